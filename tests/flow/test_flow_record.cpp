// The flow record read back as the validation reads it: the writer's observables round-trip, a
// failed case's missing fields are NaN, and the tube's diagnostics are found where tubeRecord puts them.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>

#include "core/error.hpp"
#include "flow/flow_record.hpp"

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
    const auto refusal = [](const nlohmann::json& j) {
        try {
            readFlowRecord(j, "cases/a.json");
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
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

    // Missing sections of a failed case, and nulls, are missing values, not damage.
    const FlowRecordView failed = readFlowRecord({{"status", "failed"}, {"observables", nullptr}, {"diagnostics", nullptr}}, "cases/a.json");
    EXPECT_FALSE(failed.ok());
    EXPECT_TRUE(std::isnan(failed.inclinationDeg));
    const FlowRecordView empty = readFlowRecord({{"status", "ok"}, {"observables", nlohmann::json::object()}}, "cases/a.json");
    EXPECT_TRUE(empty.ok());
    EXPECT_TRUE(std::isnan(empty.lengthUm));
    EXPECT_EQ(empty.settled, "none");
}

}  // namespace
}  // namespace trbc
