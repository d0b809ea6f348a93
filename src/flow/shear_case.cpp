#include "flow/shear_case.hpp"

#include <fmt/format.h>

#include <Eigen/Geometry>
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
    return fmt::format("shear eta_out {:a} eta_in {:a} rate {:a} level {} rotations {:a} random start {} kick {:a} seed {}",
                       o.etaOut, o.etaIn, o.shearRate, o.level, o.rotations, o.randomStart, o.kickTemperatureK, o.seed);
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

}  // namespace

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
    if (o.randomStart)
        res.prepared.initial = randomThermalStart(res.prepared.initial, res.scales.length,
                                                  model.membrane().parameters().bending.kb * res.scales.force() * res.scales.length,
                                                  o.kickTemperatureK, o.seed);
    res.integrator = stageOptions(o.step, o.rotations * 4.0 * kPi, 0.0);
    if (o.temperatureK > 0.0) {
        res.integrator.thermal.kT = thermalEnergy(o.temperatureK) / (res.scales.force() * res.scales.length);
        res.integrator.thermal.seed = o.seed;
        res.integrator.thermal.step = o.thermalStep;
    }
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

}  // namespace trbc
