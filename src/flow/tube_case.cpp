#include "flow/tube_case.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/error.hpp"
#include "mesh/geometry.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kStageDtMax = 5.0;  // R/V

/// Wall points per ring at the default resolution: wall chord ~ 1.5 x the cell's mean edge.
int defaultWallPoints(double radiusUm, const Vertices& cellUm, const Faces& faces) {
    const double faceArea = totalArea(cellUm, faces) / static_cast<double>(faces.cols());
    const double edge = std::sqrt(4.0 * faceArea / std::sqrt(3.0));  // equilateral face of that area
    return std::max(16, static_cast<int>(std::ceil(2.0 * kPi * radiusUm / (1.5 * edge))));
}

/// V = pg / 45 cm/s (docs/FLOW_TUBE.md), time unit R / V; Poiseuille centre-line velocity
/// U_c = G R^2 / (4 eta) with G = pg x 1.33322e5 Pa/m.
TubeUnits tubeUnits(const TubeCaseOptions& o, const FlowConditions& fc) {
    TubeUnits u;
    u.minimumRadius = minimumTubeRadius(fc.A0, fc.V0);
    u.velocityScale = o.pressureGradient / 45.0 * 1e4;
    u.timeUnit = o.radius / u.velocityScale;
    u.pressureGradientPaPerM = o.pressureGradient * kPaPerMPerMmHgPerMm;
    u.centreLineVelocity = u.pressureGradientPaPerM * std::pow(o.radius * 1e-6, 2) / (4.0 * o.etaOut * 1e-3) * 1e6;
    return u;
}

/// eta_m / mu = settleRelax R / V; with mu in uN/m, R in um and V in um/s this is
/// eta_m = settleRelax mu R / V in Pa s um.
TubeSettlingViscosity settlingViscosity(const TubeCaseOptions& o, const TubeUnits& u) {
    TubeSettlingViscosity s;
    s.etamPerTimeUnit = o.cell.mu * u.timeUnit;
    s.fromRelax = !o.settleEtam.has_value();
    s.etamFromRelax = o.settleRelax * s.etamPerTimeUnit;
    s.etam = s.fromRelax ? std::min(o.cell.etam, s.etamFromRelax) : *o.settleEtam;
    return s;
}

/// What the snapshots' key adds to the integrator's own fingerprint: the tube around the cell and
/// the settling criterion.
std::string tubeCaseKey(const TubeCaseOptions& o, const TubeSetup& ts) {
    return fmt::format("tube radius {:a} pg {:a} eta_out {:a} lambda {:a} level {} settle {:a} settle-tol {:a} "
                       "wall {:a} {:a} {:a} {} repulsion {:a} {:a} {:a}",
                       o.radius, o.pressureGradient, o.etaOut, o.viscosityRatio, o.level, o.settle, o.settleTolerance,
                       ts.radius, ts.centreLineSpeed, ts.halfLength, ts.pointsPerRing, ts.repulsionRange,
                       ts.repulsionPressure, ts.vertexWeight);
}

TubeFrameSeries tubeSeries(const CellFlowResult& r, const FlowScales& s, double radiusUm) {
    const std::size_t n = r.frames.size();
    TubeFrameSeries f;
    f.centroidUm.resize(3, static_cast<Eigen::Index>(n));
    for (std::size_t k = 0; k < n; ++k) {
        const Vertices X = r.frames[k] * s.length;
        const Eigen::Vector3d c = centroid(X), e = extents(X);
        f.time.push_back(r.times[k] * s.time);
        f.timeROverV.push_back(r.times[k]);
        f.centroidUm.col(static_cast<Eigen::Index>(k)) = c;
        f.lengthUm.push_back(e.x());
        f.widthYUm.push_back(e.y());
        f.widthZUm.push_back(e.z());
        f.clearanceUm.push_back(wallClearance(X, radiusUm));
    }
    f.areaDrift = r.areaDrift;
    f.volumeDrift = r.volumeDrift;
    return f;
}

/// analyzeTubeFrames over the frames from index `first` on (times in s, shapes in um); none for
/// fewer than 16 frames.
std::optional<TubeObservables> observablesFrom(const CellFlowResult& r, std::size_t first, const FlowScales& s) {
    if (r.frames.size() < first + 16) return std::nullopt;
    std::vector<double> t;
    std::vector<Vertices> framesUm;
    for (std::size_t k = first; k < r.frames.size(); ++k) {
        t.push_back(r.times[k] * s.time);
        framesUm.push_back(r.frames[k] * s.length);
    }
    return analyzeTubeFrames(t, framesUm);
}

/// The fitted cell's tube in internal units; InputError for a wall too short or too large.
TubeSetup tubeSetup(const TubeCaseOptions& o, const TubeCaseResult& res, double vertexWeight) {
    const OptionNamer& n = o.step.optionName;
    const double L = res.scales.length;
    const double reachUm = res.fit.initialUm.row(0).cwiseAbs().maxCoeff();
    TubeSetup ts;
    ts.radius = o.radius / L;
    ts.centreLineSpeed = res.units.centreLineVelocity * res.units.timeUnit / L;
    ts.halfLength = (o.tubeLength > 0.0 ? 0.5 * o.tubeLength : 1.15 * reachUm + 2.0 * o.radius) / L;
    ts.pointsPerRing = o.wallPoints > 0 ? o.wallPoints : defaultWallPoints(o.radius, res.prepared.initial, res.prepared.faces);
    ts.repulsionRange = o.repulsionRange / L;
    ts.repulsionPressure = o.repulsionPressure;  // the internal stress unit is eta_out / (R / V)
    ts.vertexWeight = vertexWeight;
    if (ts.halfLength - ts.endMargin * ts.radius <= reachUm / L)
        throw InputError(fmt::format("parameter {} = {} um: must exceed the fitted cell's length {:.3f} um plus 2 R = {:.3f} "
                                     "um (valid range ({:.3f}, inf) um, or 0 for the default)",
                                     optionName(n, "tube_length_um"), o.tubeLength, 2.0 * reachUm, 2.0 * o.radius,
                                     2.0 * reachUm + 2.0 * o.radius));
    const Eigen::Index wallVertices = static_cast<Eigen::Index>(tubeMesh(ts.radius, ts.halfLength, ts.pointsPerRing).numVertices());
    if (3 * wallVertices > 12000)
        throw InputError(fmt::format("parameters {} = {} um / {} = {}: the wall would have {} vertices (dense S_WW of {} "
                                     "unknowns; at most 4000 vertices): use a smaller radius, fewer {} or a shorter {}",
                                     optionName(n, "radius_um"), o.radius, optionName(n, "wall_points"), ts.pointsPerRing,
                                     wallVertices, 3 * wallVertices, optionName(n, "wall_points"),
                                     optionName(n, "tube_length_um")));
    return ts;
}

/// Fits the cell into the tube; false (with the reason in res.message) when it cannot be.
bool fitCell(const TubeCaseOptions& o, TubeCaseResult& res) {
    try {
        res.fit.initialUm = fitIntoTube(res.prepared.initial, res.prepared.faces, o.radius, 0.1 * o.radius,
                                        res.conditions.A0, res.conditions.V0);
    } catch (const NumericalError& e) {
        res.message = fmt::format("the cell cannot be fitted into a tube of {} {} um: {}",
                                  optionName(o.step.optionName, "radius_um"), o.radius, e.what());
        return false;
    }
    res.fit.equilibriumExtentsUm = extents(res.prepared.initial);
    res.fit.fittedExtentsUm = extents(res.fit.initialUm);
    res.fit.clearanceUm = wallClearance(res.fit.initialUm, o.radius);
    return true;
}

TubeGroups tubeGroups(const TubeCaseOptions& o, const TubeCaseResult& res, const FlowGroups& g) {
    const double L = res.scales.length, Vum = res.units.velocityScale;
    TubeGroups t;
    t.capillary = res.conditions.etaOut * 1e-3 * (Vum / o.radius) * L / o.cell.mu;
    t.viscosityRatio = o.viscosityRatio;
    t.membraneViscosity = g.membraneViscosity;
    t.FvK = g.FvK;
    t.confinement = o.radius / L;
    t.centreLineOverV = res.units.centreLineVelocity / Vum;
    return t;
}

/// One stage from startUm; records the tube's clearance and off-axis extremes and starts them afresh.
void runStage(TubeStageResult& stage, const CellFlowModel& model, CellFlowOptions opt, const TubeEnvironment& env,
              const TubeCaseOptions& o, std::string_view name, std::chrono::steady_clock::time_point start) {
    const double L = model.scales().length;
    stage.ran = true;
    stage.cell = model.cell();
    stage.integrator = std::move(opt);
    stage.flow = integrateCellFlow(model, model.toInternal(stage.startUm), stage.integrator,
                                   stageObserver(o.step, name, stage.integrator.tEnd, L, start), &env);
    stage.series = tubeSeries(stage.flow, model.scales(), o.radius);
    stage.minClearanceUm = env.minClearance() * L;
    stage.maxOffAxisUm = env.maxOffAxis() * L;
    env.resetRecords();
}

/// The settling stage (file comment): ends when the shape has settled, or at o.settle R/V.
void settle(TubeCaseResult& res, const TubeCaseOptions& o, const TubeEnvironment& env, const std::string& key,
            std::chrono::steady_clock::time_point start) {
    CellParameters ps = o.cell;
    ps.etam = res.settlingViscosity.etam;
    const CellFlowModel model(ps, res.conditions, res.prepared.faces, res.prepared.reference);
    CellFlowOptions so = stageOptions(o.step, o.settle, kStageDtMax);
    so.checkpoint = stageCheckpoint(o.step, "settling", key);
    so.stopWhen = [tol = o.settleTolerance](const CellFlowResult& sofar) {
        return tubeShapeSettled(sofar.times, sofar.frames, kTubeSettleSpan, tol);
    };
    res.settling.startUm = res.fit.initialUm;
    runStage(res.settling, model, std::move(so), env, o, "settling", start);
    // Is the membrane at rest in the co-moving frame at the end of this stage too? The motion is
    // measured over the second half of the frames given, here the last kTubeSettleSpan R/V.
    const CellFlowResult& rs = res.settling.flow;
    std::size_t first = 0;
    while (first < rs.times.size() && rs.times[first] < rs.tReached - 2.0 * kTubeSettleSpan - 1e-9) ++first;
    res.settling.observables = observablesFrom(rs, first, res.scales);
}

}  // namespace

FlowCaseStepping TubeCaseOptions::tubeStepping() {
    FlowCaseStepping s;
    s.frameInterval = 1.0;
    s.stepTolerance = kTubeStepTolerance;
    return s;
}

void validateTubeCaseOptions(const TubeCaseOptions& o) {
    const OptionNamer& n = o.step.optionName;
    const FlowConditions cellSize;
    const double rMin = std::ceil(minimumTubeRadius(cellSize.A0, cellSize.V0) * 1e4) / 1e4;
    requireOptionRange(n, "radius_um", o.radius, {rMin, 100.0, false, "um"});
    requireOptionRange(n, "pressure_gradient_mmHg_per_mm", o.pressureGradient, {0.0, 1e4, true, "mmHg/mm"});
    requireOptionRange(n, "eta_out_mPa_s", o.etaOut, {0.0, 1e6, true, "mPa s"});
    requireOptionRange(n, "viscosity_ratio", o.viscosityRatio, {1.0, 1.0, false, ""});
    validateCellParameters(o.cell, o.allowOutsidePrior);
    requireOptionRange(n, "level", o.level, {1.0, 4.0, false, ""});
    requireOptionRange(n, "duration_R_over_V", o.duration, {0.0, 1e4, true, "R/V"});
    requireOptionRange(n, "settle_R_over_V", o.settle, {0.0, 1e4, false, "R/V"});
    if (o.settle > 0.0 && o.settle < kTubeSettleSpan)
        throw InputError(fmt::format("parameter {} = {} R/V: the settling criterion spans {:g} R/V (valid: 0 for no "
                                     "settling stage, or [{:g}, inf) R/V)",
                                     optionName(n, "settle_R_over_V"), o.settle, kTubeSettleSpan, kTubeSettleSpan));
    requireOptionRange(n, "settle_relax_R_over_V", o.settleRelax, {0.0, 1e9, true, "R/V"});
    if (o.settleEtam) requireOptionRange(n, "settle_etam_Pa_s_um", *o.settleEtam, {0.0, 1e3, true, "Pa s um"});
    requireOptionRange(n, "settle_tol", o.settleTolerance, {0.0, 1.0, true, ""});
    requireOptionRange(n, "wall_points", o.wallPoints, {0.0, 400.0, false, ""});
    requireOptionRange(n, "tube_length_um", o.tubeLength, {0.0, 1e3, false, "um"});
    requireOptionRange(n, "repulsion_range_um", o.repulsionRange, {0.0, 10.0, true, "um"});
    requireOptionRange(n, "repulsion_pressure", o.repulsionPressure, {0.0, 1e6, false, "eta_out V / R"});
    validateStepping(o.step, "R/V");
}

TubeCaseResult runTubeCase(const TubeCaseOptions& o) {
    const auto tStart = std::chrono::steady_clock::now();
    validateTubeCaseOptions(o);
    TubeCaseResult res;
    res.cell = o.cell;
    res.units = tubeUnits(o, res.conditions);
    res.settlingViscosity = settlingViscosity(o, res.units);
    res.conditions.etaOut = o.etaOut;
    res.conditions.etaIn = o.etaOut * o.viscosityRatio;
    res.conditions.shearRate = 0.0;
    res.conditions.timeScale = res.units.timeUnit;
    validateFlowConditions(res.conditions);

    // The cell: SFS, equilibrium shape with the disc plane containing the axis (x-z), fitted into the tube.
    res.prepared = prepareShearCell(o.cell, o.level, o.cacheDir);
    const CellFlowModel model(o.cell, res.conditions, res.prepared.faces, res.prepared.reference);
    res.scales = model.scales();
    if (!fitCell(o, res)) return res;
    res.setup = tubeSetup(o, res, model.targetArea() / static_cast<double>(res.prepared.faces.maxCoeff() + 1));
    const auto tWall = std::chrono::steady_clock::now();
    const TubeEnvironment env(res.setup);
    res.wallSetupSeconds = secondsSince(tWall);
    res.wallVertices = env.wall().numVertices();
    res.contactClearanceUm = env.wall().sagitta() * res.scales.length;
    res.repulsionPressurePa = o.repulsionPressure * res.conditions.etaOut * 1e-3 * res.units.velocityScale / o.radius;
    res.groups = tubeGroups(o, res, model.groups());
    res.setupWallSeconds = secondsSince(tStart);
    const std::string key = tubeCaseKey(o, res.setup);

    res.stage = TubeCaseStage::Settling;
    res.main.startUm = res.fit.initialUm;
    if (o.settle > 0.0) {
        settle(res, o, env, key, tStart);
        if (!res.settling.flow.completed) {
            res.message = "settling stage: " + res.settling.flow.message;
            res.wallSeconds = secondsSince(tStart);
            return res;
        }
        res.main.startUm = model.toMicrons(res.settling.flow.final);
    }

    res.stage = TubeCaseStage::Main;
    CellFlowOptions opt = stageOptions(o.step, o.duration, kStageDtMax);
    opt.checkpoint = stageCheckpoint(o.step, "main", key);
    runStage(res.main, model, std::move(opt), env, o, "main", tStart);
    res.completed = res.main.flow.completed;
    if (res.completed)
        res.main.observables = observablesFrom(res.main.flow, 0, res.scales);
    else
        res.message = "main stage: " + res.main.flow.message;
    res.wallSeconds = secondsSince(tStart);
    return res;
}

}  // namespace trbc
