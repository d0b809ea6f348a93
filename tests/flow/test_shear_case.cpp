// The flow protocols as library calls (flow/shear_case.hpp, flow/tube_case.hpp) at level 1 and
// short durations: a tank-treading and a tumbling cell in shear, a cell moving along a tube, the
// stages, failures and the checks of the options. `trbc flow` writes its outputs from these
// results (tests/flow/test_cell_flow.cpp and tests/flow/test_tube.cpp run the commands).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "flow/shear_case.hpp"
#include "flow/steady_rule_study.hpp"
#include "flow/tube_case.hpp"
#include "mesh/geometry.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;

ShearCaseOptions cheapShear(double etaOut, double rate) {
    ShearCaseOptions o;
    o.etaOut = etaOut;
    o.shearRate = rate;
    o.level = 1;
    o.rotations = 3.0;
    return o;
}

TubeCaseOptions cheapTube() {
    TubeCaseOptions o;
    o.radius = 3.3;
    o.pressureGradient = 30.0;
    o.level = 1;
    o.wallPoints = 12;
    o.settle = 0.0;
    o.duration = 8.0;
    o.step.frameInterval = 0.5;  // 17 frames: enough for the observables
    return o;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(ShearCase, TankTreadingCellHasAFiniteInclinationAndMembraneFrequency) {
    ShearCaseOptions o = cheapShear(28.9, 50.0);  // Ca ~ 1: tank-treading (docs/FLOW.md, shear)
    std::vector<double> reported;
    o.step.progress = [&](const FlowCaseProgress& p) {
        EXPECT_EQ(p.stage, "main");
        EXPECT_EQ(p.shapeUm.cols(), 42);
        reported.push_back(p.t);
    };
    const ShearCaseResult r = runShearCase(o);
    ASSERT_TRUE(r.completed) << r.message;
    ASSERT_TRUE(r.observables.has_value());
    const ShearObservables& obs = *r.observables;
    EXPECT_EQ(obs.regime, ShearRegime::TankTreading);
    // Inclined into the extensional quadrant of the flow, by less than 45 degrees.
    EXPECT_TRUE(std::isfinite(obs.inclinationDeg));
    EXPECT_GT(obs.inclinationDeg, 0.0);
    EXPECT_LT(obs.inclinationDeg, 45.0);
    EXPECT_TRUE(std::isfinite(obs.swingAmplitudeDeg));
    EXPECT_GE(obs.swingAmplitudeDeg, 0.0);
    // The membrane turns, slower than a rigid sphere (4 pi f / rate = 1).
    ASSERT_TRUE(obs.ttf.defined);
    EXPECT_GT(obs.ttf4piFOverRate, 0.0);
    EXPECT_LT(obs.ttf4piFOverRate, 1.0);

    // Units: time 1/rate, frames every 0.1 / rate up to 3 x 4 pi / rate; the series in s and um.
    EXPECT_DOUBLE_EQ(r.scales.time, 1.0 / 50.0);
    EXPECT_DOUBLE_EQ(r.tEndSeconds, 3.0 * 4.0 * kPi / 50.0);
    const ShearFrameSeries& s = r.series;
    ASSERT_EQ(s.time.size(), r.flow.frames.size());
    EXPECT_EQ(s.centroidUm.cols(), static_cast<Eigen::Index>(s.time.size()));
    EXPECT_NEAR(s.time.back(), r.tEndSeconds, 0.1 / 50.0);
    for (std::size_t k = 0; k < s.time.size(); ++k) {
        EXPECT_NEAR(s.shearStrain[k], 50.0 * s.time[k], 1e-9);
        EXPECT_LT(std::abs(s.areaDrift[k]), 1e-3);
        EXPECT_LT(s.centroidUm.col(static_cast<Eigen::Index>(k)).norm(), 0.05);  // stays at the origin (um)
    }
    EXPECT_NEAR(totalArea(r.flow.final * r.scales.length, r.prepared.faces), 135.0, 0.135);
    // Progress at t = 0 and at every frame.
    ASSERT_EQ(reported.size(), s.time.size());
    EXPECT_EQ(reported.front(), 0.0);
    EXPECT_NEAR(reported.back(), 3.0 * 4.0 * kPi, 0.1);
}

TEST(ShearCase, TumblingCellHasNoInclinationButAnAdvancingOrientation) {
    // Viscosity ratio 10 at a low shear stress: the cell flips as a whole.
    const ShearCaseResult r = runShearCase(cheapShear(1.0, 10.0));
    ASSERT_TRUE(r.completed) << r.message;
    const ShearObservables& obs = *r.observables;
    EXPECT_EQ(obs.regime, ShearRegime::Tumbling);
    // Clockwise (the vorticity is -rate/2 e_z): more than half a turn over the analysed window.
    EXPECT_TRUE(std::isfinite(obs.orientationAdvance));
    EXPECT_LT(obs.orientationAdvance, -kPi);
    EXPECT_LT(r.series.orientationDeg.back(), r.series.orientationDeg.front() - 180.0);
}

// Every membrane modulus is proportional to mu at fixed FvK and b2, so the cell at (s mu, s rate)
// runs the same flow at the same strains: the observables depend on Ca = eta_out rate R_A / mu, not on
// mu and the rate apart. The flow networks take the dimensionless groups on this ground
// (surrogate/flow_surrogate.hpp).
TEST(ShearCase, TheSameFlowWhenTheModuliAndTheRateScaleTogether) {
    // Not a power of two, so that the scaled arithmetic rounds differently and only the physics can
    // make the two runs agree.
    ShearCaseOptions a = cheapShear(28.9, 50.0), b = a;
    b.cell.mu *= 1.7, b.shearRate *= 1.7;
    const ShearCaseResult ra = runShearCase(a), rb = runShearCase(b);
    ASSERT_TRUE(ra.completed && rb.completed) << ra.message << rb.message;
    const ShearObservables &oa = *ra.observables, &ob = *rb.observables;
    EXPECT_EQ(oa.regime, ob.regime);
    EXPECT_NEAR(oa.inclinationDeg, ob.inclinationDeg, 1e-6);
    EXPECT_NEAR(oa.swingAmplitudeDeg, ob.swingAmplitudeDeg, 1e-6);
    EXPECT_NEAR(oa.ttf4piFOverRate, ob.ttf4piFOverRate, 1e-8);
    ASSERT_EQ(ra.flow.frames.size(), rb.flow.frames.size());
    EXPECT_LT((ra.flow.final * ra.scales.length - rb.flow.final * rb.scales.length).cwiseAbs().maxCoeff(), 1e-6);  // um
    EXPECT_NEAR(ra.tEndSeconds, 1.7 * rb.tEndSeconds, 1e-12);

    // A stiffer cell at the same rate is another flow (a lower Ca): the check above can fail.
    ShearCaseOptions c = a;
    c.cell.mu *= 2.0;
    const ShearCaseResult rc = runShearCase(c);
    ASSERT_TRUE(rc.completed) << rc.message;
    EXPECT_GT(std::abs(rc.observables->inclinationDeg - oa.inclinationDeg), 0.1);  // 0.41 deg at level 1
}

TEST(ShearCase, AFailedRunIsAResultNotAnException) {
    ShearCaseOptions o = cheapShear(28.9, 50.0);
    o.step.maxSteps = 3;
    const ShearCaseResult r = runShearCase(o);
    EXPECT_FALSE(r.completed);
    EXPECT_TRUE(contains(r.message, "step limit")) << r.message;
    EXPECT_FALSE(r.observables.has_value());
    EXPECT_EQ(r.series.time.size(), r.flow.frames.size());
}

// The thermal step is the requested one, at most the membrane's viscous time eta_m / mu: the
// reference set-up's cell (eta_m 0.42 Pa s um, mu 4.99 uN/m: 84.2 ms) at 100 mPa s.
TEST(ShearCase, TheThermalStepIsAtMostTheMembranesViscousTime) {
    CellParameters cell;
    cell.mu = 4.99;
    cell.etam = 0.42;
    EXPECT_NEAR(thermalStepTimesRate(cell, 0.3, 0.2), 0.3 * 0.42 / 4.99, 1e-15);  // 84 ms = 0.0253 / rate: capped
    EXPECT_NEAR(thermalStepTimesRate(cell, 0.936, 0.2), 0.936 * 0.42 / 4.99, 1e-15);
    EXPECT_EQ(thermalStepTimesRate(cell, 20.0, 0.2), 0.2);  // 10 ms of 84 ms: as requested
    EXPECT_EQ(thermalStepTimesRate(cell, 0.3, 0.01), 0.01);
    // A run takes it: the reference set-up's cell at 100 mPa s, 0.3 1/s.
    ShearCaseOptions o = cheapShear(100.0, 0.3);
    o.cell = cell;
    o.temperatureK = 293.15;
    o.rotations = 0.1;
    const ShearCaseResult r = runShearCase(o);
    EXPECT_NEAR(r.integrator.thermal.step, 0.3 * 0.42 / 4.99, 1e-15);
    EXPECT_DOUBLE_EQ(thermalStepOnFrames(r.integrator), 0.025);  // four steps per frame interval of 0.1
    // Each stage of a ramp caps its own step: 0.0253 and 0.0505 of 1/rate, taken as 0.025 and 0.05.
    ShearRampOptions ramp{o, {0.3, 0.6}};
    const ShearRampResult rr = runShearRamp(ramp);
    ASSERT_EQ(rr.stages.size(), 3u);
    EXPECT_DOUBLE_EQ(rr.stages[0].thermalStep, 0.025);
    EXPECT_DOUBLE_EQ(rr.stages[1].thermalStep, 0.05);
    EXPECT_DOUBLE_EQ(rr.stages[2].thermalStep, 0.025);
}

TEST(ShearCase, BadOptionsThrowInputErrorNamingTheOption) {
    struct Case {
        std::function<void(ShearCaseOptions&)> change;
        std::string name;
    };
    const std::vector<Case> cases = {
        {[](ShearCaseOptions& o) { o.etaOut = std::nan(""); }, "parameter eta_out_mPa_s = nan mPa s"},
        {[](ShearCaseOptions& o) { o.shearRate = -1.0; }, "shear_rate_per_s = -1 1/s: out of range (valid: (0, 1e+06] 1/s)"},
        {[](ShearCaseOptions& o) { o.etaIn = 0.0; }, "eta_in_mPa_s"},
        {[](ShearCaseOptions& o) { o.cell.v = 0.5; }, "parameter v = 0.5"},
        {[](ShearCaseOptions& o) { o.level = 6; }, "level = 6: out of range (valid: [1, 5])"},
        {[](ShearCaseOptions& o) { o.rotations = 0.0; }, "rotations"},
        {[](ShearCaseOptions& o) { o.step.frameInterval = -0.1; }, "frame_interval = -0.1 1/rate"},
        {[](ShearCaseOptions& o) { o.step.stepTolerance = 2.0; }, "step_tol = 2 R_A"},
        {[](ShearCaseOptions& o) { o.step.gmresTolerance = 1.0; }, "gmres_tol = 1: out of range (valid: [0, 1), 0: automatic)"},
        {[](ShearCaseOptions& o) { o.step.dt = 200.0; }, "dt = 200 1/rate: out of range (valid: (0, 100] 1/rate)"},
        {[](ShearCaseOptions& o) { o.step.maxSteps = 0; }, "max_steps"},
        {[](ShearCaseOptions& o) { o.step.resume = true; }, "resume"},
    };
    for (const Case& c : cases) {
        ShearCaseOptions o = cheapShear(28.9, 50.0);
        c.change(o);
        const std::string what = test::inputError([&] { runShearCase(o); });
        EXPECT_TRUE(contains(what, c.name)) << c.name << ": " << what;
    }
    // A caller's names for the options (the CLI's).
    ShearCaseOptions o = cheapShear(28.9, 0.0);
    o.step.optionName = [](const std::string& name) { return name == "shear_rate_per_s" ? "--shear-rate" : name; };
    EXPECT_TRUE(contains(test::inputError([&] { validateShearCaseOptions(o); }), "parameter --shear-rate = 0 1/s"));
    // Too few frames for the analysis: the options that give more.
    o = cheapShear(28.9, 50.0);
    o.rotations = 0.1;
    o.step.frameInterval = 0.5;
    const std::string few = test::inputError([&] { runShearCase(o); });
    EXPECT_TRUE(contains(few, "give more rotations (now 0.1) or a smaller frame_interval (now 0.5)")) << few;
}

TEST(TubeCase, CellMovesDownstreamSlowerThanTheCentreLine) {
    TubeCaseOptions o = cheapTube();
    int progressCalls = 0;
    o.step.progress = [&](const FlowCaseProgress& p) {
        EXPECT_EQ(p.stage, "main");
        ++progressCalls;
    };
    const TubeCaseResult r = runTubeCase(o);
    ASSERT_TRUE(r.completed) << r.message;
    EXPECT_EQ(r.stage, TubeCaseStage::Main);
    EXPECT_FALSE(r.settling.ran);
    ASSERT_TRUE(r.main.observables.has_value());
    // Units: V = 30 / 45 cm/s, R / V, U_c = G R^2 / (4 eta) with G = 30 x 1.33322e5 Pa/m.
    const TubeUnits& u = r.units;
    EXPECT_NEAR(u.velocityScale, 30.0 / 45.0 * 1e4, 1e-9);
    EXPECT_NEAR(u.timeUnit, 3.3 / u.velocityScale, 1e-15);
    EXPECT_NEAR(u.centreLineVelocity, 30.0 * 1.33322e5 * 3.3e-6 * 3.3e-6 / (4.0 * 1.003e-3) * 1e6, 1e-6);
    EXPECT_NEAR(r.scales.time, u.timeUnit, 1e-15);
    // The equilibrium disc (7.8 um) is squeezed into the tube, keeping at least 0.1 R from the wall.
    EXPECT_GT(r.fit.equilibriumExtentsUm.z(), 2.0 * 3.3);
    EXPECT_GE(r.fit.clearanceUm, 0.1 * 3.3 - 1e-9);
    EXPECT_LE(r.fit.fittedExtentsUm.z(), 2.0 * (3.3 - 0.1 * 3.3) + 1e-9);
    const TubeObservables& ob = *r.main.observables;
    EXPECT_TRUE(std::isfinite(ob.velocity));
    EXPECT_GT(ob.velocity, 0.0);                       // downstream (+x)
    EXPECT_LT(ob.velocity, u.centreLineVelocity);      // slower than the centre line
    EXPECT_GT(ob.velocity, 0.3 * u.centreLineVelocity);
    EXPECT_GT(ob.length, ob.widthY);                   // stretched along the axis
    EXPECT_LT(ob.widthY, 2.0 * 3.3);
    EXPECT_LT(ob.widthZ, 2.0 * 3.3);
    // Series: 17 frames, the centroid moving along the axis, the cell clear of the wall.
    const TubeFrameSeries& s = r.main.series;
    ASSERT_EQ(s.time.size(), 17u);
    EXPECT_EQ(progressCalls, 17);
    for (std::size_t k = 1; k < s.time.size(); ++k) {
        EXPECT_GT(s.centroidUm(0, Eigen::Index(k)), s.centroidUm(0, Eigen::Index(k - 1)));
        EXPECT_NEAR(s.time[k], s.timeROverV[k] * u.timeUnit, 1e-15);
        EXPECT_GT(s.clearanceUm[k], 0.0);
    }
    EXPECT_GT(r.main.minClearanceUm, 0.0);
    EXPECT_LT(r.main.maxOffAxisUm, 1e-3);
}

TEST(TubeCase, SettlingStageStartsTheMainStageFromItsShape) {
    TubeCaseOptions o = cheapTube();
    o.settle = 10.0;
    o.duration = 2.0;  // 5 frames: no observables
    std::vector<std::string> stages;
    o.step.progress = [&](const FlowCaseProgress& p) {
        if (stages.empty() || stages.back() != p.stage) stages.emplace_back(p.stage);
    };
    const TubeCaseResult r = runTubeCase(o);
    ASSERT_TRUE(r.completed) << r.message;
    EXPECT_EQ(stages, (std::vector<std::string>{"settling", "main"}));
    ASSERT_TRUE(r.settling.ran);
    ASSERT_TRUE(r.main.ran);
    // The settling stage's membrane viscosity: 1.5 mu R / V (below the cell's own).
    EXPECT_TRUE(r.settlingViscosity.fromRelax);
    EXPECT_NEAR(r.settling.cell.etam, 1.5 * o.cell.mu * 3.3 / (30.0 / 45.0 * 1e4), 1e-12);
    EXPECT_EQ(r.main.cell.etam, o.cell.etam);
    EXPECT_GT(r.settling.flow.tReached, 0.0);
    EXPECT_LE(r.settling.flow.tReached, 10.0 + 1e-9);
    EXPECT_TRUE(r.settling.series.time.size() >= 2u);
    EXPECT_TRUE(r.settling.startUm.isApprox(r.fit.initialUm));
    EXPECT_TRUE(r.main.startUm.isApprox(r.settling.flow.final * r.scales.length));
    EXPECT_FALSE(r.main.observables.has_value());
}

TEST(TubeCase, FailuresAreResultsNamingTheStage) {
    TubeCaseOptions o = cheapTube();
    o.settle = 10.0;
    o.step.maxSteps = 2;
    TubeCaseResult r = runTubeCase(o);
    EXPECT_FALSE(r.completed);
    EXPECT_EQ(r.stage, TubeCaseStage::Settling);
    EXPECT_TRUE(contains(r.message, "settling stage: ")) << r.message;
    EXPECT_FALSE(r.main.ran);
    o.settle = 0.0;
    r = runTubeCase(o);
    EXPECT_EQ(r.stage, TubeCaseStage::Main);
    EXPECT_TRUE(contains(r.message, "main stage: ")) << r.message;
    // The tube of the smallest radius holds the cell's area and volume only as a capsule, which the
    // affine fit of the disc does not reach.
    o = cheapTube();
    o.radius = 1.5;
    r = runTubeCase(o);
    EXPECT_FALSE(r.completed);
    EXPECT_EQ(r.stage, TubeCaseStage::Fit);
    EXPECT_TRUE(contains(r.message, "cannot be fitted into a tube of radius_um 1.5 um")) << r.message;
}

TEST(TubeCase, BadOptionsThrowInputErrorNamingTheOption) {
    struct Case {
        std::function<void(TubeCaseOptions&)> change;
        std::string name;
    };
    const std::vector<Case> cases = {
        {[](TubeCaseOptions& o) { o.radius = 1.2; }, "radius_um = 1.2 um: out of range (valid: [1.4967, 100] um)"},
        {[](TubeCaseOptions& o) { o.pressureGradient = std::nan(""); }, "pressure_gradient_mmHg_per_mm"},
        {[](TubeCaseOptions& o) { o.etaOut = -1.0; }, "eta_out_mPa_s"},
        {[](TubeCaseOptions& o) { o.viscosityRatio = 2.0; }, "viscosity_ratio = 2: out of range (valid: [1, 1])"},
        {[](TubeCaseOptions& o) { o.cell.mu = 20.0; }, "mu_uN_per_m = 20"},
        {[](TubeCaseOptions& o) { o.level = 5; }, "level"},
        {[](TubeCaseOptions& o) { o.duration = 0.0; }, "duration_R_over_V"},
        {[](TubeCaseOptions& o) { o.settle = 5.0; }, "settle_R_over_V = 5 R/V: the settling criterion spans 10 R/V"},
        {[](TubeCaseOptions& o) { o.settleRelax = 0.0; }, "settle_relax_R_over_V"},
        {[](TubeCaseOptions& o) { o.settleEtam = 0.0; }, "settle_etam_Pa_s_um"},
        {[](TubeCaseOptions& o) { o.settleTolerance = 0.0; }, "settle_tol"},
        {[](TubeCaseOptions& o) { o.wallPoints = 500; }, "wall_points"},
        {[](TubeCaseOptions& o) { o.repulsionRange = 0.0; }, "repulsion_range_um"},
        {[](TubeCaseOptions& o) { o.repulsionPressure = -1.0; }, "repulsion_pressure"},
        {[](TubeCaseOptions& o) { o.step.frameInterval = 0.0; }, "frame_interval = 0 R/V"},
        // Checked once the cell is fitted: the wall must hold it.
        {[](TubeCaseOptions& o) { o.tubeLength = 5.0; }, "tube_length_um = 5 um: must exceed the fitted cell's length"},
        {[](TubeCaseOptions& o) { o.radius = 60.0; o.wallPoints = 400; }, "fewer wall_points or a shorter tube_length_um"},
    };
    for (const Case& c : cases) {
        TubeCaseOptions o = cheapTube();
        c.change(o);
        const std::string what = test::inputError([&] { runTubeCase(o); });
        EXPECT_TRUE(contains(what, c.name)) << c.name << ": " << what;
    }
    TubeCaseOptions o = cheapTube();
    o.settle = 5.0;
    o.step.optionName = [](const std::string& name) { return name == "settle_R_over_V" ? "--settle" : name; };
    EXPECT_TRUE(contains(test::inputError([&] { validateTubeCaseOptions(o); }), "parameter --settle = 5 R/V"));
}

// The ramp protocol: the first stage is the shear case at its rate, step for step; the later
// stages start from the shape where the last ended; the brackets name the rates where the regime
// changes on each leg; bad rates are refused with the option's name.
// With the steady-state stop each stage ends at its steady state; the regimes are those of the
// full-length stages.
TEST(ShearRamp, StagesStopAtTheSteadyStateWhenAsked) {
    ShearRampOptions full;
    full.base = cheapShear(30.0, 2.0);
    full.base.rotations = 8.0;
    full.rates = {2.0, 20.0};
    ShearRampOptions steady = full;
    steady.base.stopWhenSteady = true;
    const ShearRampResult a = runShearRamp(full), b = runShearRamp(steady);
    ASSERT_TRUE(a.completed && b.completed);
    ASSERT_EQ(a.stages.size(), 3u);
    ASSERT_EQ(b.stages.size(), 3u);
    int early = 0;
    for (std::size_t k = 0; k < 3; ++k) {
        EXPECT_EQ(a.stages[k].observables->regime, b.stages[k].observables->regime) << "stage " << k;
        EXPECT_FALSE(a.stages[k].stoppedWhenSteady);
        EXPECT_NEAR(a.stages[k].turns, 8.0, 0.02);
        if (b.stages[k].stoppedWhenSteady) {
            ++early;
            EXPECT_LT(b.stages[k].turns, 7.9) << "stage " << k;
            EXPECT_GE(b.stages[k].turns, 4.0) << "stage " << k;
        }
    }
    EXPECT_GT(early, 0);
}

TEST(ShearRamp, StagesContinueFromTheLastShapeAndBracketTheRegimeChange) {
    ShearRampOptions r;
    r.base = cheapShear(30.0, 2.0);
    r.rates = {2.0, 20.0};
    const ShearRampResult ramp = runShearRamp(r);
    ASSERT_TRUE(ramp.completed);
    ASSERT_EQ(ramp.stages.size(), 3u);
    const ShearCaseResult single = runShearCase(cheapShear(30.0, 2.0));
    ASSERT_TRUE(single.completed && ramp.stages[0].observables);
    EXPECT_EQ(ramp.stages[0].observables->regime, single.observables->regime);
    EXPECT_EQ(ramp.stages[0].observables->orientationAdvance, single.observables->orientationAdvance);
    EXPECT_TRUE(ramp.stages[0].up && ramp.stages[1].up && !ramp.stages[2].up);
    EXPECT_EQ(ramp.stages[2].shearRate, 2.0);
    // At 30 mPa s: tumbling at 2 1/s, tank-treading at 20 1/s, tumbling again on the way down.
    EXPECT_EQ(ramp.stages[0].observables->regime, ShearRegime::Tumbling);
    EXPECT_EQ(ramp.stages[1].observables->regime, ShearRegime::TankTreading);
    EXPECT_EQ(ramp.stages[2].observables->regime, ShearRegime::Tumbling);
    ASSERT_TRUE(ramp.upBracket && ramp.downBracket);
    EXPECT_EQ(*ramp.upBracket, std::make_pair(2.0, 20.0));
    EXPECT_EQ(*ramp.downBracket, std::make_pair(2.0, 20.0));
    // The down stage starts where the tank-treading stage ended, not from the disc at rest.
    EXPECT_NE(ramp.stages[2].observables->orientationAdvance, single.observables->orientationAdvance);

    ShearRampOptions bad = r;
    bad.rates = {2.0};
    EXPECT_TRUE(contains(test::inputError([&] { runShearRamp(bad); }), "rates"));
    bad.rates = {2.0, 2.0};
    EXPECT_TRUE(contains(test::inputError([&] { runShearRamp(bad); }), "increase"));
    bad.rates = {2.0, -1.0};
    EXPECT_TRUE(contains(test::inputError([&] { runShearRamp(bad); }), "shear_rate_per_s"));
}

}  // namespace
}  // namespace trbc

namespace trbc {
namespace {

// The steady-state stop: a tank-treading cell stops at a whole turn from the 4th on with the
// observables of the full run within the rule's tolerances (the full run's window is longer, so a
// little more); a tumbling cell stops at the 4th turn; the rule is asked only at the first frame
// of a turn.
TEST(ShearSteadyStop, StopsAtAWholeTurnWithTheFullRunsObservables) {
    ShearCaseOptions o = cheapShear(28.9, 50.0);
    o.rotations = 10.0;
    const ShearCaseResult full = runShearCase(o);
    o.stopWhenSteady = true;
    const ShearCaseResult early = runShearCase(o);
    ASSERT_TRUE(full.completed && early.completed);
    ASSERT_TRUE(early.flow.stoppedEarly);
    const double turns = early.flow.tReached / (4.0 * kPi);
    EXPECT_GE(turns, 4.0 - 1e-9);
    EXPECT_LT(turns, 10.0);
    // The step that reached the turn ends it (steps at most 1 / rate).
    EXPECT_NEAR(turns, std::floor(turns), 1.0 / (4.0 * kPi) + 1e-9);
    ASSERT_EQ(early.observables->regime, ShearRegime::TankTreading);
    EXPECT_NEAR(early.observables->inclinationDeg, full.observables->inclinationDeg, 0.3);
    EXPECT_NEAR(early.observables->ttf4piFOverRate, full.observables->ttf4piFOverRate, 0.02 * full.observables->ttf4piFOverRate);
    // The rule looks at a turn once: not again after a step that ends later in the same turn.
    const std::vector<double>& t = full.flow.times;
    const std::vector<Vertices>& f = full.flow.frames;
    const std::size_t mid = static_cast<std::size_t>(std::floor(turns) * 4.0 * kPi / 0.1) + 5;  // 5 frames past the turn
    const std::vector<double> tm(t.begin(), t.begin() + mid);
    const std::vector<Vertices> fm(f.begin(), f.begin() + mid);
    EXPECT_TRUE(shearSteadyStateReached(tm, fm, {}, tm[mid - 7]));
    EXPECT_FALSE(shearSteadyStateReached(tm, fm, {}, tm[mid - 3]));
    // The full run's turn-by-turn record, judged by the same rule, stops where the run stopped, with
    // the stopped run's cost and observables (the same trajectory up to there).
    const std::vector<FullLengthCase> record = {{0, turnRecords(full.flow)}};
    ASSERT_EQ(record[0].turns.back().turn, 10);  // the run ends at turn 10, its last frame before it
    EXPECT_EQ(record[0].turns.back().stop.inclinationDeg, full.observables->inclinationDeg);
    EXPECT_EQ(record[0].turns.back().steps, full.flow.steps);
    const SteadyRuleEffect e = steadyRuleEffect(record, {});
    EXPECT_EQ(e.stopped, 1);
    EXPECT_EQ(e.meanTurns, std::floor(turns));
    EXPECT_EQ(e.regimeChanged, 0);
    const TurnRecord& atStop = record[0].turns[std::size_t(std::floor(turns)) - std::size_t(record[0].turns.front().turn)];
    EXPECT_EQ(atStop.steps, early.flow.steps);
    EXPECT_NEAR(atStop.stop.inclinationDeg, early.observables->inclinationDeg, 1e-9);
    EXPECT_NEAR(atStop.stop.ttf4piFOverRate, early.observables->ttf4piFOverRate, 1e-9);
    EXPECT_NEAR(e.angleMaxDeg, std::abs(early.observables->inclinationDeg - full.observables->inclinationDeg), 1e-9);
    EXPECT_GT(e.costFraction, 0.2);
    EXPECT_LT(e.costFraction, 1.0);

    ShearCaseOptions tumble = cheapShear(23.9, 2.0);
    tumble.rotations = 10.0;
    tumble.stopWhenSteady = true;
    const ShearCaseResult tr = runShearCase(tumble);
    ASSERT_TRUE(tr.completed);
    EXPECT_EQ(tr.observables->regime, ShearRegime::Tumbling);
    EXPECT_TRUE(tr.flow.stoppedEarly);
    EXPECT_LT(tr.flow.tReached / (4.0 * kPi), 6.0);
}

}  // namespace
}  // namespace trbc
