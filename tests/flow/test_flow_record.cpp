// The flow record read back as the validation reads it: the writer's observables round-trip, a
// failed case's missing fields are NaN, and the tube's diagnostics are found where tubeRecord puts them.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>

#include "core/error.hpp"
#include "flow/flow_record.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

TEST(FlowRecord, ShearObservablesRoundTripThroughTheWriter) {
    ShearObservables obs;
    obs.regime = ShearRegime::TankTreading;
    obs.inclinationDeg = 12.5;
    obs.swingAmplitudeDeg = 1.25;
    obs.ttf.defined = true;
    obs.ttf4piFOverRate = 0.375;
    nlohmann::json j = {{"status", "ok"}, {"diagnostics", {{"area_drift_max", 1e-4}, {"volume_drift_max", 2e-4}}}};
    addShearObservables(j, obs);
    const FlowRecordView r = readFlowRecord(nlohmann::json::parse(j.dump()));
    EXPECT_TRUE(r.ok());
    EXPECT_EQ(r.regime, "tank-treading");
    EXPECT_DOUBLE_EQ(r.inclinationDeg, 12.5);
    EXPECT_DOUBLE_EQ(r.observable("inclination_deg"), 12.5);
    EXPECT_DOUBLE_EQ(r.swingDeg, 1.25);
    EXPECT_DOUBLE_EQ(r.observable("ttf_4pi_f_over_shear_rate"), 0.375);
    EXPECT_DOUBLE_EQ(r.areaDriftMax, 1e-4);
    EXPECT_DOUBLE_EQ(r.volumeDriftMax, 2e-4);
    EXPECT_TRUE(std::isnan(r.velocityCmPerS));
    EXPECT_THROW(r.observable("angle"), std::invalid_argument);

    obs.regime = ShearRegime::Tumbling;  // the writer nulls the tank-treading observables
    addShearObservables(j, obs);
    const FlowRecordView t = readFlowRecord(nlohmann::json::parse(j.dump()));
    EXPECT_EQ(t.regime, "tumbling");
    EXPECT_TRUE(std::isnan(t.inclinationDeg));
    EXPECT_TRUE(std::isnan(t.ttf));
}

TEST(FlowRecord, AFailedCaseLacksItsObservables) {
    const FlowRecordView r = readFlowRecord({{"status", "failed"}, {"reason", "diverged at t = 0.03"}});
    EXPECT_FALSE(r.ok());
    EXPECT_EQ(r.reason, "diverged at t = 0.03");
    EXPECT_EQ(r.regime, "");
    EXPECT_TRUE(std::isnan(r.inclinationDeg));
    EXPECT_EQ(r.settled, "none");
    EXPECT_FALSE(readFlowRecord(nlohmann::json()).ok());          // not an object
    EXPECT_FALSE(readFlowRecord({{"status", 3}}).ok());           // a status that is not a string
}

TEST(FlowRecord, TubeObservablesAndDiagnostics) {
    const nlohmann::json j = {
        {"status", "ok"},
        {"observables", {{"velocity_cm_per_s", 0.21}, {"length_um", 9.5}, {"width_um", 5.0}}},
        {"diagnostics",
         {{"plateau", {{"reached", true}}},
          {"settling", {{"settled", false}, {"length_change_main_vs_settled", 0.004}}},
          {"cell_frame_motion", {{"ratio", 0.02}}},
          {"area_drift_max", nullptr}}}};
    const FlowRecordView r = readFlowRecord(j);
    EXPECT_DOUBLE_EQ(r.observable("velocity_cm_per_s"), 0.21);
    EXPECT_DOUBLE_EQ(r.observable("length_um"), 9.5);
    EXPECT_DOUBLE_EQ(r.widthUm, 5.0);
    EXPECT_TRUE(r.plateauReached);
    EXPECT_EQ(r.settled, "false");
    EXPECT_DOUBLE_EQ(r.lengthChangeMainVsSettled, 0.004);
    EXPECT_DOUBLE_EQ(r.cellFrameMotionRatio, 0.02);
    EXPECT_TRUE(std::isnan(r.areaDriftMax));  // null
}

// A damaged record is not a failed case: a field of another type than the schema's, or a finished
// case without observables, is an InputError naming the record's file and the field. Text that is
// not JSON, or JSON that is not an object, reads as failed with the reason.
TEST(FlowRecord, DamagedRecordsAreRefusedByFileAndField) {
    const auto refusal = [](const nlohmann::json& j) { return test::inputError([&] { readFlowRecord(j, "cases/a.json"); }); };
    const nlohmann::json notJson = nlohmann::json::parse("{\"status\": \"ok\", \"observables\": {", nullptr, false);
    ASSERT_TRUE(notJson.is_discarded());
    const FlowRecordView r = readFlowRecord(notJson, "cases/a.json");
    EXPECT_FALSE(r.ok());
    EXPECT_EQ(r.reason, "cases/a.json: not a JSON object but discarded");
    EXPECT_EQ(readFlowRecord(nlohmann::json::array({1, 2}), "cases/a.json").reason, "cases/a.json: not a JSON object but array");

    EXPECT_EQ(refusal({{"status", "ok"}, {"diagnostics", nlohmann::json::object()}}),
              "cases/a.json: a finished case (status \"ok\") without its 'observables' object");
    EXPECT_EQ(refusal({{"status", "ok"}, {"observables", {1.0, 2.0}}}),
              "cases/a.json: a finished case (status \"ok\") without its 'observables' object");
    EXPECT_EQ(refusal({{"status", "ok"}, {"observables", {{"regime", "tumbling"}, {"inclination_deg", "12.5"}}}}),
              "cases/a.json: 'observables.inclination_deg' is \"12.5\" (string), not a number or null");
    EXPECT_EQ(refusal({{"status", "ok"}, {"observables", {{"regime", 1}}}}),
              "cases/a.json: 'observables.regime' is 1 (number), not a string or null");
    EXPECT_EQ(refusal({{"status", "failed"}, {"diagnostics", "none"}}),
              "cases/a.json: 'diagnostics' is \"none\" (string), not an object or null");
    EXPECT_EQ(refusal({{"status", "ok"}, {"observables", nlohmann::json::object()}, {"diagnostics", {{"plateau", {{"reached", "yes"}}}}}}),
              "cases/a.json: 'diagnostics.plateau.reached' is \"yes\" (string), not true, false or null");
    const std::string longValue = refusal({{"status", "ok"}, {"observables", {{"length_um", std::string(100, 'x')}}}});
    EXPECT_NE(longValue.find("'observables.length_um' is \"xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx... (string)"), std::string::npos) << longValue;
    EXPECT_EQ(refusal({{"status", "failed"}, {"observables", {{"width_um", true}}}}),  // damage of a failed case too
              "cases/a.json: 'observables.width_um' is true (boolean), not a number or null");
    EXPECT_EQ(refusal({{"status", "failed"}, {"reason", {{"message", "diverged"}}}}),
              "cases/a.json: 'reason' is {\"message\":\"diverged\"} (object), not a string or null");
    EXPECT_EQ(refusal({{"status", 3}, {"reason", 7}}), "cases/a.json: 'reason' is 7 (number), not a string or null");

    // Missing sections of a failed case, and nulls, are missing values, not damage; so is a status
    // of another type, which marks a failed case.
    const FlowRecordView failed = readFlowRecord({{"status", "failed"}, {"observables", nullptr}, {"diagnostics", nullptr}}, "cases/a.json");
    EXPECT_FALSE(failed.ok());
    EXPECT_EQ(failed.reason, "");
    EXPECT_TRUE(std::isnan(failed.inclinationDeg));
    EXPECT_EQ(readFlowRecord({{"status", "failed"}, {"reason", nullptr}}, "cases/a.json").reason, "");
    const FlowRecordView typedStatus = readFlowRecord({{"status", true}, {"reason", "stopped"}}, "cases/a.json");
    EXPECT_FALSE(typedStatus.ok());
    EXPECT_EQ(typedStatus.reason, "stopped");
    const FlowRecordView empty = readFlowRecord({{"status", "ok"}, {"observables", nlohmann::json::object()}}, "cases/a.json");
    EXPECT_TRUE(empty.ok());
    EXPECT_TRUE(std::isnan(empty.lengthUm));
    EXPECT_EQ(empty.settled, "none");
}

// ramp.json of a hand-made ramp: up 20, 40 and down at 20, where the down stage failed.
TEST(FlowRecord, RampRecordOfASyntheticRamp) {
    ShearRampOptions r;
    r.base.etaOut = 30.0;
    r.base.etaIn = 10.0;
    r.base.cell = paperTable1Cell();
    r.base.level = 2;
    r.base.rotations = 3.0;
    r.base.tiltDeg = 5.0;
    r.base.randomStart = true;
    r.base.temperatureK = 300.0;
    r.base.thermalStep = 0.2;
    r.base.seed = 9;
    r.base.stopWhenSteady = true;
    r.rates = {20.0, 40.0};

    ShearObservables tumbling, treading;
    tumbling.regime = ShearRegime::Tumbling;
    treading.regime = ShearRegime::TankTreading;
    treading.inclinationDeg = 14.0;
    treading.swingAmplitudeDeg = 2.5;
    treading.ttf.defined = true;
    treading.ttf4piFOverRate = 0.25;
    ShearRampResult res;
    res.stages.resize(3);
    res.stages[0] = {20.0, true, true, "", tumbling, 3.0, false, 0.2, 1.5};
    res.stages[1] = {40.0, true, true, "", treading, 2.0, true, 0.1, 2.5};
    res.stages[2] = {20.0, false, false, "diverged at t = 1", std::nullopt, 0.5, false, 0.05, 0.75};
    res.upBracket = std::make_pair(20.0, 40.0);
    res.wallSeconds = 5.0;

    const nlohmann::json j = rampRecord(res, r, "the test's cell", {{"method", "by hand"}});
    EXPECT_EQ(j.size(), 4u);
    EXPECT_EQ(j.at("provenance"), nlohmann::json({{"method", "by hand"}}));
    const nlohmann::json& p = j.at("parameters");
    EXPECT_EQ(p.size(), 13u);
    EXPECT_EQ(p.at("eta_out_mPa_s"), 30.0);
    EXPECT_EQ(p.at("eta_in_mPa_s"), 10.0);
    EXPECT_EQ(p.at("rates_per_s"), nlohmann::json({20.0, 40.0}));
    EXPECT_EQ(p.at("cell"), flowCellJson(paperTable1Cell()));
    EXPECT_EQ(p.at("cell_source"), "the test's cell");
    EXPECT_EQ(p.at("level"), 2);
    EXPECT_EQ(p.at("rotations_per_stage"), 3.0);
    EXPECT_EQ(p.at("tilt_deg"), 5.0);
    EXPECT_EQ(p.at("start"), "random");
    EXPECT_EQ(p.at("temperature_K"), 300.0);
    EXPECT_EQ(p.at("seed"), 9);
    EXPECT_EQ(p.at("stop_when_steady"), true);
    EXPECT_EQ(p.at("thermal_step_times_rate"), 0.2);

    const nlohmann::json& s = j.at("stages");
    ASSERT_EQ(s.size(), 3u);
    EXPECT_EQ(s[0].at("shear_rate_per_s"), 20.0);
    EXPECT_DOUBLE_EQ(s[1].at("shear_stress_Pa").get<double>(), 1.2);  // eta_out rate = 30 mPa s x 40 / s
    EXPECT_EQ(s[1].at("direction"), "up");
    EXPECT_EQ(s[2].at("direction"), "down");
    EXPECT_EQ(s[1].at("status"), "ok");
    EXPECT_EQ(s[1].at("turns"), 2.0);
    EXPECT_EQ(s[1].at("stopped_when_steady"), true);
    EXPECT_EQ(s[1].at("thermal_step_times_rate"), 0.1);
    EXPECT_EQ(s[1].at("wall_s"), 2.5);
    EXPECT_EQ(s[1].at("observables").at("regime"), "tank-treading");
    EXPECT_EQ(s[1].at("observables").at("inclination_deg"), 14.0);
    EXPECT_EQ(s[1].at("observables").at("ttf_4pi_f_over_shear_rate"), 0.25);
    EXPECT_TRUE(s[0].at("observables").at("inclination_deg").is_null());  // tumbling
    EXPECT_FALSE(s[1].contains("analysis") || s[1].contains("reason"));
    EXPECT_EQ(s[2].at("status"), "failed");
    EXPECT_EQ(s[2].at("reason"), "diverged at t = 1");
    EXPECT_FALSE(s[2].contains("observables"));
    EXPECT_EQ(s[2].size(), 9u);

    const nlohmann::json& sum = j.at("summary");
    EXPECT_EQ(sum.at("completed"), false);
    EXPECT_EQ(sum.at("up_onset_bracket_per_s"), nlohmann::json({20.0, 40.0}));
    EXPECT_TRUE(sum.at("down_end_bracket_per_s").is_null());
    EXPECT_EQ(sum.at("hysteresis"), false);  // one bracket only
    EXPECT_EQ(sum.at("wall_s"), 5.0);

    // Without fluctuations no step is recorded; two brackets that differ are a hysteresis.
    r.base.temperatureK = 0.0;
    r.base.randomStart = false;
    res.completed = true;
    res.downBracket = std::make_pair(20.0, 40.0);
    res.upBracket = std::make_pair(40.0, 80.0);
    const nlohmann::json cold = rampRecord(res, r, "the test's cell", nullptr);
    EXPECT_TRUE(cold.at("parameters").at("thermal_step_times_rate").is_null());
    EXPECT_EQ(cold.at("parameters").at("start"), "in-plane");
    for (const nlohmann::json& st : cold.at("stages")) EXPECT_FALSE(st.contains("thermal_step_times_rate"));
    EXPECT_EQ(cold.at("summary").at("hysteresis"), true);
    EXPECT_EQ(cold.at("summary").at("completed"), true);
}

}  // namespace
}  // namespace trbc
