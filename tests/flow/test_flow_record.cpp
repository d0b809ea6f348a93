// The flow record read back as the validation reads it: the writer's observables round-trip, a
// failed case's missing fields are NaN, and the tube's diagnostics are found where tubeRecord puts them.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>

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

}  // namespace
}  // namespace trbc
