#include "flow/shear_case.hpp"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <numbers>

#include "core/error.hpp"
#include "core/random.hpp"
#include "experiments/thermal_undulations.hpp"
#include "mesh/geometry.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr std::uint64_t kRandomStartStream = 0x7374617274;  // "start"

FlowConditions shearConditions(const ShearCaseOptions& o) {
    FlowConditions fc;
    fc.etaOut = o.etaOut;
    fc.etaIn = o.etaIn;
    fc.shearRate = o.shearRate;
    return fc;
}

/// What the snapshots' key adds to the integrator's own fingerprint (which holds the cell, the
/// fluid, the mesh, the initial shape and the stepping options).
std::string shearCaseKey(const ShearCaseOptions& o) {
    return fmt::format("shear eta_out {:a} eta_in {:a} rate {:a} level {} rotations {:a} random start {} kick {:a} seed {} "
                       "steady stop {} {:a} {:a} {:a}",
                       o.etaOut, o.etaIn, o.shearRate, o.level, o.rotations, o.randomStart, o.kickTemperatureK, o.seed,
                       o.stopWhenSteady, o.steadyRule.minRotations, o.steadyRule.angleToleranceDeg, o.steadyRule.ttfTolerance);
}

ShearFrameSeries shearSeries(const CellFlowResult& r, const FlowScales& s, double rate) {
    const std::vector<double> phi = unwrappedOrientation(r.frames);
    const std::size_t n = r.frames.size();
    ShearFrameSeries f;
    f.time.resize(n);
    f.shearStrain.resize(n);
    f.inclinationDeg.resize(n);
    f.orientationDeg.resize(n);
    f.centroidUm.resize(3, static_cast<Eigen::Index>(n));
    for (std::size_t k = 0; k < n; ++k) {
        f.time[k] = r.times[k] * s.time;
        f.shearStrain[k] = r.times[k] * s.time * rate;
        f.inclinationDeg[k] = inclinationAngle(r.frames[k]) * 180.0 / kPi;
        f.orientationDeg[k] = phi[k] * 180.0 / kPi;
        f.centroidUm.col(static_cast<Eigen::Index>(k)) = centroid(r.frames[k]) * s.length;
    }
    f.areaDrift = r.areaDrift;
    f.volumeDrift = r.volumeDrift;
    return f;
}

/// The observables of docs/FLOW.md, shear (times in 1/rate); too few frames name the options that
/// give more.
ShearObservables shearObservables(const CellFlowResult& r, const ShearCaseOptions& o) {
    try {
        return analyzeShearFrames(r.times, r.frames, 1.0);
    } catch (const InputError& e) {
        throw InputError(fmt::format("{}: too few frames for the analysis; give more {} (now {:g}) or a smaller {} (now {:g})",
                                     e.what(), optionName(o.step.optionName, "rotations"), o.rotations,
                                     optionName(o.step.optionName, "frame_interval"), o.step.frameInterval));
    }
}

/// The ensemble protocol's start (ShearCaseOptions::randomStart) of the shape X (um).
Vertices randomStartOf(const Vertices& X, const CellFlowModel& model, const ShearCaseOptions& o) {
    const FlowScales& s = model.scales();
    return randomThermalStart(X, s.length, model.membrane().parameters().bending.kb * s.force() * s.length, o.kickTemperatureK, o.seed);
}

/// The thermal noise of a stage at o.temperatureK (none at 0 K) from the noise stream `seed`, and
/// the steady-state stop when o.stopWhenSteady.
void configureStage(CellFlowOptions& opt, const CellFlowModel& model, const ShearCaseOptions& o, std::uint64_t seed) {
    if (o.temperatureK > 0.0) {
        opt.thermal.kT = thermalEnergy(o.temperatureK) / (model.scales().force() * model.scales().length);
        opt.thermal.seed = seed;
        opt.thermal.step = thermalStepTimesRate(o.cell, model.conditions().shearRate, o.thermalStep);
    }
    if (o.stopWhenSteady)
        opt.stopWhen = [rule = o.steadyRule](const CellFlowResult& sofar) {
            const double since = sofar.stepLog.empty() ? 0.0 : sofar.stepLog.back().t - sofar.stepLog.back().dt;
            return shearSteadyStateReached(sofar.times, sofar.frames, rule, since);
        };
}

}  // namespace

double thermalStepTimesRate(const CellParameters& cell, double shearRate, double requested) {
    return std::min(requested, shearRate * cell.etam / cell.mu);  // Pa s um / (uN / m) = s
}

void validateShearCaseOptions(const ShearCaseOptions& o) {
    const OptionNamer& n = o.step.optionName;
    requireOptionRange(n, "eta_out_mPa_s", o.etaOut, {0.0, 1e6, true, "mPa s"});
    requireOptionRange(n, "shear_rate_per_s", o.shearRate, {0.0, 1e6, true, "1/s"});
    requireOptionRange(n, "eta_in_mPa_s", o.etaIn, {0.0, 1e6, true, "mPa s"});
    validateCellParameters(o.cell, o.allowOutsidePrior);
    requireOptionRange(n, "level", o.level, {1.0, 5.0, false, ""});
    requireOptionRange(n, "rotations", o.rotations, {0.0, 1000.0, true, ""});
    requireOptionRange(n, "tilt_deg", o.tiltDeg, {0.0, 90.0, false, "deg"});
    requireOptionRange(n, "temperature_K", o.temperatureK, {0.0, 400.0, false, "K"});
    requireOptionRange(n, "kick_temperature_K", o.kickTemperatureK, {0.0, 400.0, false, "K"});
    requireOptionRange(n, "thermal_step", o.thermalStep, {0.0, 1.0, true, "1/rate"});
    validateStepping(o.step, "1/rate");
}

Vertices randomThermalStart(const Vertices& X, double radiusUm, double kbPnUm, double temperatureK, std::uint64_t seed) {
    Rng rng(seed, kRandomStartStream);
    Eigen::Quaterniond q(rng.normal(), rng.normal(), rng.normal(), rng.normal());
    q.normalize();
    const Eigen::Vector3d c = centroid(X);
    Vertices Y = (q.toRotationMatrix() * (X.colwise() - c)).colwise() + c;
    if (temperatureK > 0.0) Y += thermalUndulation(Y, radiusUm, thermalEnergy(temperatureK), kbPnUm, rng);
    return Y;
}

Vertices tiltAboutFlowAxis(const Vertices& X, double tiltDeg) {
    const Eigen::Vector3d c = centroid(X);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(tiltDeg * kPi / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
    return (R * (X.colwise() - c)).colwise() + c;
}

ShearCaseResult runShearCase(const ShearCaseOptions& o) {
    const auto tStart = std::chrono::steady_clock::now();
    validateShearCaseOptions(o);
    ShearCaseResult res;
    res.cell = o.cell;
    res.conditions = shearConditions(o);
    res.tEndSeconds = o.rotations * 4.0 * kPi / o.shearRate;
    res.prepared = prepareShearCell(o.cell, o.level, o.cacheDir);
    if (o.tiltDeg != 0.0) res.prepared.initial = tiltAboutFlowAxis(res.prepared.initial, o.tiltDeg);
    const CellFlowModel model(o.cell, res.conditions, res.prepared.faces, res.prepared.reference);
    res.scales = model.scales();
    res.groups = model.groups();
    if (o.randomStart) res.prepared.initial = randomStartOf(res.prepared.initial, model, o);
    res.integrator = stageOptions(o.step, o.rotations * 4.0 * kPi, 0.0);
    configureStage(res.integrator, model, o, o.seed);
    res.integrator.checkpoint = stageCheckpoint(o.step, "main", shearCaseKey(o));
    res.setupWallSeconds = secondsSince(tStart);
    res.flow = integrateCellFlow(model, model.toInternal(res.prepared.initial), res.integrator,
                                 stageObserver(o.step, "main", res.integrator.tEnd, res.scales.length, tStart));
    res.completed = res.flow.completed;
    res.message = res.flow.message;
    res.series = shearSeries(res.flow, res.scales, o.shearRate);
    if (res.completed) res.observables = shearObservables(res.flow, o);
    res.wallSeconds = secondsSince(tStart);
    return res;
}

ShearRampResult runShearRamp(const ShearRampOptions& o) {
    const auto tStart = std::chrono::steady_clock::now();
    const OptionNamer& n = o.base.step.optionName;
    if (o.rates.size() < 2 || o.rates.size() > 50)
        throw InputError(fmt::format("{}: {} rates given; a ramp needs 2 to 50 increasing shear rates",
                                     optionName(n, "rates"), o.rates.size()));
    for (std::size_t k = 0; k < o.rates.size(); ++k) {
        ShearCaseOptions c = o.base;
        c.shearRate = o.rates[k];
        validateShearCaseOptions(c);
        if (k > 0 && !(o.rates[k] > o.rates[k - 1]))
            throw InputError(fmt::format("{}: the rates must increase strictly ({:g} after {:g} 1/s)", optionName(n, "rates"),
                                         o.rates[k], o.rates[k - 1]));
    }
    std::vector<std::pair<double, bool>> plan;
    for (double r : o.rates) plan.emplace_back(r, true);
    for (std::size_t k = o.rates.size() - 1; k-- > 0;) plan.emplace_back(o.rates[k], false);

    ShearRampResult res;
    res.prepared = prepareShearCell(o.base.cell, o.base.level, o.base.cacheDir);
    Vertices Xum = res.prepared.initial;
    if (o.base.tiltDeg != 0.0) Xum = tiltAboutFlowAxis(Xum, o.base.tiltDeg);
    std::string key = shearCaseKey(o.base) + " ramp";
    for (double r : o.rates) key += fmt::format(" {:a}", r);
    for (std::size_t k = 0; k < plan.size(); ++k) {
        const auto stageStart = std::chrono::steady_clock::now();
        ShearCaseOptions c = o.base;
        c.shearRate = plan[k].first;
        const CellFlowModel model(c.cell, shearConditions(c), res.prepared.faces, res.prepared.reference);
        if (k == 0 && c.randomStart) Xum = randomStartOf(Xum, model, c);
        if (k == 0) res.prepared.initial = Xum;
        CellFlowOptions opt = stageOptions(c.step, c.rotations * 4.0 * kPi, 0.0);
        const std::string stage = fmt::format("{}_{}", plan[k].second ? "up" : "down", k);
        opt.checkpoint = stageCheckpoint(c.step, stage, key);
        configureStage(opt, model, c, c.seed + 1000003ULL * k);  // a noise stream of its own per stage
        const CellFlowResult flow = integrateCellFlow(model, model.toInternal(Xum), opt,
                                                      stageObserver(c.step, stage, opt.tEnd, model.scales().length, tStart));
        ShearRampStage st;
        st.shearRate = c.shearRate;
        st.up = plan[k].second;
        st.completed = flow.completed;
        st.message = flow.message;
        if (flow.completed) st.observables = shearObservables(flow, c);
        st.turns = flow.times.empty() ? 0.0 : flow.times.back() / (4.0 * kPi);
        st.stoppedWhenSteady = flow.stoppedEarly;
        if (opt.thermal.kT > 0.0) st.thermalStep = thermalStepOnFrames(opt);
        st.wallSeconds = secondsSince(stageStart);
        res.stages.push_back(st);
        if (!flow.completed) break;
        Xum = model.toMicrons(flow.final);
    }
    res.completed = res.stages.size() == plan.size() && std::all_of(res.stages.begin(), res.stages.end(),
                                                                    [](const ShearRampStage& s) { return s.completed; });
    const auto treads = [](const ShearRampStage& s) {
        return s.observables && s.observables->regime == ShearRegime::TankTreading;
    };
    for (std::size_t k = 1; k < res.stages.size(); ++k) {
        const ShearRampStage &a = res.stages[k - 1], &b = res.stages[k];
        if (a.up && b.up && !res.upBracket && !treads(a) && treads(b)) res.upBracket = {{a.shearRate, b.shearRate}};
        if (!b.up && !res.downBracket && treads(a) && !treads(b)) res.downBracket = {{b.shearRate, a.shearRate}};
    }
    res.wallSeconds = secondsSince(tStart);
    return res;
}

}  // namespace trbc
