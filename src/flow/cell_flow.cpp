#include "flow/cell_flow.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <utility>

#include "core/error.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "flow/cell_flow_checkpoint.hpp"
#include "flow/coupled_system.hpp"
#include "mesh/geometry.hpp"
#include "mesh/validate.hpp"
#include "solvers/bdf2.hpp"

namespace trbc {
namespace {

using Eigen::Index;
using Eigen::VectorXd;
using Clock = std::chrono::steady_clock;

constexpr double kPi = std::numbers::pi;

void requirePositive(const char* name, double value, const char* unit) {
    if (!(value > 0.0) || !std::isfinite(value))
        throw InputError(fmt::format("parameter {} = {} {}: must be finite and > 0 (valid range (0, inf) {})", name,
                                     value, unit, unit));
}

FlowScales makeScales(const FlowConditions& f) {
    FlowScales s;
    s.length = std::sqrt(f.A0 / (4.0 * kPi));
    s.time = f.timeScale > 0.0 ? f.timeScale : 1.0 / f.shearRate;
    s.viscosity = f.etaOut * 1e-3;  // mPa s -> Pa s = pN s / um^2
    return s;
}

/// Bending and in-plane moduli (Lim or a capsule law) in internal units. No penalties: area and volume are exact
/// constraints (multiplier rows in the coupled system, projection after each step).
MembraneParameters internalMembrane(const CellParameters& p, const FlowScales& s) {
    MembraneParameters m = experimentMembrane(p);  // kb (pN um), Kalpha = mu (pN/um), Lim constants
    const double F = s.force(), L = s.length;
    m.bending.kb /= F * L;
    m.lim.Kalpha /= F / L;
    m.lim.mu /= F / L;
    m.capsule.Gs /= F / L;
    return m;
}

Vertices checkedReference(const Faces& faces, const Vertices& ref, double length) {
    if (ref.cols() == 0 || faces.cols() == 0) throw InputError("cell flow: empty reference mesh");
    if (!ref.allFinite()) throw InputError("cell flow: reference positions must be finite");
    validateClosedManifold(Mesh{ref, faces});
    return ref / length;
}

using cellflow::CoupledSystem;
using cellflow::PreconditionerFactor;
using cellflow::thermalNoise;
using cellflow::ThermalNoise;

void checkOptions(const CellFlowOptions& o) {
    requirePositive("tEnd", o.tEnd, "(internal time)");
    requirePositive("frameInterval", o.frameInterval, "(internal time)");
    // Every saved frame is kept in memory (3 Nv doubles each): their count is bounded before the run.
    if (o.tEnd / o.frameInterval > double(kMaxFlowFrames))
        throw InputError(fmt::format("frames = duration / frame interval = {:.3g} is more than the limit of {} saved frames; raise "
                                     "--frame-interval to at least {:.3g} (internal time) or shorten the run",
                                     o.tEnd / o.frameInterval, kMaxFlowFrames, o.tEnd / double(kMaxFlowFrames)));
    requirePositive("errorTolerance", o.errorTolerance, "R_A");
    requirePositive("dtInitial", o.dtInitial, "(internal time)");
    requirePositive("dtMin", o.dtMin, "(internal time)");
    requirePositive("dtMax", o.dtMax, "(internal time)");
    if (!(o.checkpoint.intervalSeconds >= 0.0))
        throw InputError(fmt::format("checkpoint interval = {} s: must be >= 0", o.checkpoint.intervalSeconds));
    if (!(o.gmresTolerance >= 0.0 && o.gmresTolerance < 1.0))
        throw InputError(fmt::format("GMRES tolerance = {}: must be in [0, 1) (0: automatic)", o.gmresTolerance));
    if (o.gmresRestart < 1 || o.gmresMaxIterations < 1 || o.maxSteps < 1)
        throw InputError("cell flow: gmresRestart, gmresMaxIterations and maxSteps must be >= 1");
    requirePositive("maxDrift", o.maxDrift, "");
    for (const auto& [name, value] : {std::pair{"bendingPreconditionerRatio", o.bendingPreconditionerRatio},
                                      std::pair{"bendingOverShearRatio", o.bendingOverShearRatio}})
        if (!(value >= 0.0))
            throw InputError(fmt::format("cell flow: {} = {}: must be in [0, inf] (inf: no bending correction)", name, value));
    const ThermalOptions& th = o.thermal;
    if (!(th.kT >= 0.0) || !std::isfinite(th.kT))
        throw InputError(fmt::format("thermal energy kT = {} (internal units): must be finite and >= 0", th.kT));
    if (th.kT > 0.0) {
        requirePositive("thermal step", th.step, "(internal time)");
        requirePositive("thermal sqrtTolerance", th.sqrtTolerance, "");
        requirePositive("thermal mobilityTolerance", th.mobilityTolerance, "");
        if (th.sqrtMaxIterations < 1) throw InputError("cell flow: thermal sqrtMaxIterations must be >= 1");
    }
}

/// The step control of the options (docs/FLOW.md, step control).
bdf2::StepControl stepControl(const CellFlowOptions& o) {
    bdf2::StepControl c;
    c.tolerance = o.errorTolerance;
    c.adaptive = o.adaptive;
    c.dtInitial = o.dtInitial;
    c.dtMin = o.dtMin;
    c.dtMax = o.dtMax;
    c.firstStepGrowth = bdf2::kMaxGrowth;
    return c;
}

/// Newton projection onto V = V0 along dV/dx (a few iterations), for a membrane without the area
/// constraint.
void projectVolume(Vertices& X, const Faces& F, double V0) {
    for (int it = 0; it < 5; ++it) {
        const AreaVolume av = areaVolumeWithGradients(X, F);
        const double c = av.volume - V0;
        if (std::abs(c) <= 1e-13 * V0) return;
        X -= (c / av.volumeGradient.squaredNorm()) * av.volumeGradient;
    }
}

/// Gauss-Newton projection onto A = A0, V = V0 (moves along dA/dx and dV/dx; a few iterations).
void projectAreaVolume(Vertices& X, const Faces& F, double A0, double V0) {
    for (int it = 0; it < 5; ++it) {
        const AreaVolume av = areaVolumeWithGradients(X, F);
        const Eigen::Vector2d c(av.area - A0, av.volume - V0);
        if (std::abs(c[0]) <= 1e-13 * A0 && std::abs(c[1]) <= 1e-13 * V0) return;
        const Eigen::Map<const VectorXd> ga(av.areaGradient.data(), X.size()), gv(av.volumeGradient.data(), X.size());
        Eigen::Matrix2d JtJ;
        JtJ << ga.dot(ga), ga.dot(gv), ga.dot(gv), gv.dot(gv);
        const Eigen::Vector2d l = JtJ.ldlt().solve(c);
        X -= l[0] * av.areaGradient + l[1] * av.volumeGradient;
    }
}

/// What a snapshot must match (CellFlowCheckpoint): the caller's key, the version, the model's
/// parameters and connectivity, the initial shape's bits and every option that changes a step.
std::uint64_t cellFlowFingerprint(const CellFlowModel& model, const Vertices& initial, const CellFlowOptions& o,
                                  const FlowEnvironment* env) {
    const CellParameters& c = model.cell();
    const FlowConditions& f = model.conditions();
    const QuadratureOptions& q = o.quadrature;
    std::string d = fmt::format("{}|{}|{}|", o.checkpoint.key, kVersion, env ? "environment" : "unbounded");
    for (double v : {c.v, c.mu, c.FvK, c.b2, c.etam, f.etaOut, f.etaIn, f.shearRate, f.timeScale, f.A0, f.V0, o.tEnd,
                     o.frameInterval, o.errorTolerance, o.dtInitial, o.dtMin, o.dtMax, o.gmresTolerance, o.maxDrift,
                     o.preconditionerScale, o.bendingPreconditionerRatio, o.bendingOverShearRatio, q.nearFactor})
        d += fmt::format("{:a},", v);
    for (long v : {long(o.keepFrames), long(o.adaptive), long(o.maxSteps), long(o.gmresRestart),
                   long(o.gmresMaxIterations), long(o.operators), long(o.denseLimit), long(o.preconditioner),
                   long(o.eliminateMultipliers),
                   long(q.farRule), long(q.farPoints), long(q.nearSubdivisions), long(q.singularPoints),
                   long(q.singlePrecisionFar),
                   long(initial.cols()), long(model.faces().cols())})
        d += fmt::format("{},", v);
    if (model.hasMembraneSpec()) {
        const MembraneParameters& m = model.membrane().parameters();
        d += fmt::format("spec|{}|", model.areaConstraint());
        for (double v : {m.bending.kb, m.bending.C0, m.lim.Kalpha, m.lim.a3, m.lim.a4, m.lim.mu, m.lim.b1, m.lim.b2,
                         m.capsule.Gs, m.capsule.C, model.edgeFriction(), model.viscosityRatio()})
            d += fmt::format("{:a},", v);
        d += fmt::format("{},", static_cast<int>(m.law));
    }
    if (o.thermal.kT > 0.0)
        d += fmt::format("thermal|{:a}|{}|{:a}|{:a}|{}|{:a}|", o.thermal.kT, o.thermal.seed, o.thermal.step,
                         o.thermal.sqrtTolerance, o.thermal.sqrtMaxIterations, o.thermal.mobilityTolerance);
    std::uint64_t h = fnv1a(d);
    h = fnv1a(std::string_view(reinterpret_cast<const char*>(model.faces().data()),
                               static_cast<std::size_t>(model.faces().size()) * sizeof(model.faces()(0, 0))),
              h);
    return fnv1a(std::string_view(reinterpret_cast<const char*>(initial.data()),
                                  static_cast<std::size_t>(initial.size()) * sizeof(double)),
                 h);
}

/// A snapshot whose fingerprint and checksum match holds a state of this run; this guards the
/// restore against a colliding or hand-made file all the same.
bool snapshotFits(const CellFlowSnapshot& s, Index nv, const FlowEnvironment* env) {
    const CellFlowState& st = s.state;
    for (const Vertices* M : {&st.steps.X, &st.steps.Xprev, &st.steps.Xprev2})
        if (M->cols() != nv) return false;
    if (s.result.final.cols() != 0 && s.result.final.cols() != nv) return false;  // set only when finished
    for (const Vertices& f : s.result.frames)
        if (f.cols() != nv) return false;
    const std::size_t frames = s.result.times.size();
    return st.steps.accepted >= 0 && st.nextFrame >= 1 && st.nextFrame <= frames + 1 && st.framesChecked <= frames &&
           s.result.areaDrift.size() == frames && s.result.volumeDrift.size() == frames &&
           s.environmentRecords.size() == (env ? env->records().size() : 0);
}

/// Every saved frame is kept in memory (3 Nv doubles each): their bytes are bounded before the run.
void checkFrameMemory(const CellFlowOptions& opt, Index nv) {
    const double frameBytes = opt.tEnd / opt.frameInterval * 24.0 * static_cast<double>(nv);
    if (opt.keepFrames && frameBytes > kMaxFlowFrameBytes)
        throw InputError(fmt::format("frames = duration / frame interval = {:.3g} of {} vertices would take {:.3g} GiB, more "
                                     "than the limit of {:.3g} GiB; raise --frame-interval to at least {:.3g} (internal "
                                     "time) or shorten the run",
                                     opt.tEnd / opt.frameInterval, nv, frameBytes / 1073741824.0,
                                     kMaxFlowFrameBytes / 1073741824.0, opt.frameInterval * frameBytes / kMaxFlowFrameBytes));
}

/// The linear solve of one step: the state the operators are frozen at, and the solution's
/// multipliers, or why the solve failed.
struct StepSolve {
    Vertices Xpred;
    double tension = 0.0, flux = 0.0;
    int iterations = 0;
    bool solved = false;
    std::string failure;
};

/// The linearly implicit integrator of integrateCellFlow: adaptive BDF2 steps (bdf2::StepControl),
/// or the fixed steps of the trapezoidal rule in thermal runs (ThermalOptions); frames by the dense
/// output; the area and volume projected after each accepted step; snapshots of CellFlowState.
class CellFlowIntegrator {
public:
    CellFlowIntegrator(const CellFlowModel& model, const Vertices& initial, const CellFlowOptions& opt,
                       const CellFlowObserver& observer, const FlowEnvironment* env)
        : model_(model), opt_(opt), observer_(observer), env_(env), F_(model.faces()), A0_(model.targetArea()),
          V0_(model.targetVolume()), nv_(model.membrane().numVertices()) {
        checkOptions(opt);
        if (initial.cols() != nv_ || !initial.allFinite())
            throw InputError(fmt::format("cell flow: initial shape has {} vertices (model {}) or non-finite positions",
                                         initial.cols(), nv_));
        checkFrameMemory(opt, nv_);
        if (thermal_ && env) throw InputError("cell flow: thermal fluctuations are for a cell in unbounded fluid, not in a tube");
        t0_ = Clock::now();
        res_.dtSmallest = std::numeric_limits<double>::infinity();
        state_ = CellFlowState{.steps = bdf2::History(initial),
                               .dt = std::min(opt.dtInitial, opt.dtMax), .nextFrame = 1, .framesChecked = 1};
        Xnew_.resize(3, nv_);
        fingerprint_ = opt.checkpoint.file.empty() ? 0 : cellFlowFingerprint(model, initial, opt, env);
        snapshots_ = !opt.checkpoint.file.empty();
        lastSnapshot_ = Clock::now();
    }

    CellFlowResult run() {
        if (resume()) {
            if (res_.completed) return res_;  // the snapshot of a finished run
        } else {
            recordFrame(0.0, state_.steps.X);
        }
        while (!bdf2::reaches(state_.t, opt_.tEnd)) {
            if (res_.steps + res_.rejectedSteps + res_.failedSolves >= opt_.maxSteps)
                return finish(false, fmt::format("step limit {} reached at t = {:.6g}", opt_.maxSteps, state_.t));
            const bdf2::Step step =
                thermal_ ? thermalProposal() : control_.propose(state_.dt, state_.steps, state_.t, opt_.tEnd);
            const StepSolve s = solveStep(step);
            res_.gmresIterations += s.iterations;
            res_.maxGmresIterations = std::max(res_.maxGmresIterations, s.iterations);
            if (!s.solved) {
                ++res_.failedSolves;
                if (thermal_)
                    return finish(false, fmt::format("solver diverged at t = {:.6g} (thermal step {:.3g}): {}", state_.t,
                                                     step.h, s.failure));
                const bdf2::Verdict v = control_.afterFailedSolve(step);
                if (v.outcome == bdf2::Outcome::Fail)
                    return finish(false, fmt::format("solver diverged at t = {:.6g} (step {:.3g} < dtMin {:.3g}): {}",
                                                     state_.t, v.dt, opt_.dtMin, s.failure));
                state_.dt = v.dt;
                continue;
            }
            // Also logged with fixed steps; a thermal step has no error estimate and is always accepted.
            const double err = !thermal_ && state_.steps.accepted >= 2 ? bdf2::localError(Xnew_, s.Xpred) : 0.0;
            const bdf2::Verdict verdict = thermal_ ? bdf2::Verdict{bdf2::Outcome::Accept, thermalStep_}
                                                   : control_.judge(step, err, state_.steps);
            if (verdict.outcome != bdf2::Outcome::Accept) {
                ++res_.rejectedSteps;
                if (verdict.outcome == bdf2::Outcome::Fail)
                    return finish(false, fmt::format("step size fell below dtMin = {:.3g} at t = {:.6g} (error {:.3g})",
                                                     opt_.dtMin, state_.t, err));
                state_.dt = verdict.dt;
                continue;
            }
            if (std::optional<CellFlowResult> end = accept(step, s, err)) return std::move(*end);
            state_.dt = verdict.dt;
            if (snapshots_ &&
                std::chrono::duration<double>(Clock::now() - lastSnapshot_).count() >= opt_.checkpoint.intervalSeconds) {
                snapshot();
                lastSnapshot_ = Clock::now();
            }
        }
        return finish(true, "completed");
    }

private:
    double wallSoFar() const { return wallBefore_ + std::chrono::duration<double>(Clock::now() - t0_).count(); }
    double frameTime(std::uint64_t k) const { return static_cast<double>(k) * opt_.frameInterval; }

    void recordFrame(double t, const Vertices& X) {
        res_.times.push_back(t);
        res_.areaDrift.push_back(totalArea(X, F_) / A0_ - 1.0);
        res_.volumeDrift.push_back(enclosedVolume(X, F_) / V0_ - 1.0);
        if (opt_.keepFrames) res_.frames.push_back(X);
        if (observer_) observer_(t, X);
    }

    /// Writes the state the next step reads and the result so far (CellFlowCheckpoint). A snapshot
    /// that cannot be written (disk full, ...) is reported and the run goes on without.
    void snapshot() {
        if (!snapshots_) return;
        CellFlowSnapshot s{state_, env_ ? env_->records() : std::vector<double>{}, res_};
        if (!res_.completed) s.result.wallSeconds = wallSoFar();  // a finished run's is set by finish()
        try {
            writeCellFlowSnapshot(opt_.checkpoint.file, s, fingerprint_);
        } catch (const std::exception& e) {
            snapshots_ = false;
            if (opt_.checkpoint.log)
                opt_.checkpoint.log(fmt::format("cannot write the snapshot ({}); the run goes on without snapshots", e.what()));
        }
    }

    /// Restores the run from its snapshot when asked to and one of this run is intact.
    bool resume() {
        const CellFlowCheckpoint& cp = opt_.checkpoint;
        if (cp.file.empty() || !cp.resume) return false;
        std::string why;
        std::optional<CellFlowSnapshot> resumed = readCellFlowSnapshot(cp.file, fingerprint_, why);
        if (resumed && !snapshotFits(*resumed, nv_, env_)) {
            resumed.reset();
            why = "damaged snapshot (its state does not fit the run)";
        }
        if (cp.log)
            cp.log(resumed ? fmt::format("resuming {} at t = {:.6g} ({} steps done)", cp.file.string(), resumed->state.t,
                                         resumed->result.steps)
                           : fmt::format("not resuming {}: {}; starting afresh", cp.file.string(), why));
        if (!resumed) return false;
        state_ = std::move(resumed->state);
        if (env_) env_->restoreRecords(resumed->environmentRecords);
        res_ = std::move(resumed->result);
        wallBefore_ = res_.wallSeconds;
        if (!res_.completed) {
            ++res_.resumes;
            res_.resumedAt = state_.t;
        }
        return true;
    }

    CellFlowResult finish(bool ok, std::string msg) {
        res_.completed = ok;
        res_.message = std::move(msg);
        res_.final = state_.steps.X;
        res_.tReached = state_.t;
        res_.wallSeconds = wallSoFar();
        if (res_.steps == 0) res_.dtSmallest = res_.dtLargest = 0.0;
        if (ok) snapshot();
        return res_;
    }

    /// A thermal step: fixed, ending on t = (steps + 1) h (thermalStepOnFrames).
    bdf2::Step thermalProposal() const {
        bdf2::Step s;
        s.wanted = thermalStep_;
        s.end = std::min(opt_.tEnd, static_cast<double>(res_.steps + 1) * thermalStep_);
        s.h = s.end - state_.t;
        s.landed = bdf2::reaches(s.end, opt_.tEnd);
        return s;
    }

    /// Solves the step's coupled system (CoupledSystem) at the predicted state; X^{n+1} in Xnew_.
    StepSolve solveStep(const bdf2::Step& step) {
        const bdf2::History& history = state_.steps;
        const double h = step.h;
        const bdf2::Coefficients coef = thermal_ ? bdf2::Coefficients{} : bdf2::coefficients(history, h);
        const Vertices Y = thermal_ ? history.X : coef.historyTerm(history.X, history.Xprev);
        StepSolve r;
        // The thermal step freezes the operators at the extrapolated midpoint X^n + (h/2)(X^n - X^{n-1}) / hPrev,
        // which makes its deterministic drift second order (at X^n it is first order: 0.66 deg off in the angle
        // of a level-3 case at h = 0.1 / rate). X^{n-1} holds the noise of earlier steps only, so the step's
        // own noise still meets a mobility it does not depend on (Ito).
        r.Xpred = !thermal_ ? bdf2::predictor(history, h)
                  : history.accepted == 0
                      ? history.X
                      : Vertices(history.X + (0.5 * h / history.hPrev) * (history.X - history.Xprev));
        // BDF2: X^{n+1} = Y + alpha u with the Hessian weight alpha = h / c0; the trapezoidal rule:
        // X^{n+1} = X^n + h u with the weight h / 2.
        const double alpha = thermal_ ? h : h / coef.c0;
        const double hessianWeight = thermal_ ? 0.5 * h : alpha;
        try {
            const CoupledSystem sys(model_, r.Xpred, hessianWeight, opt_, factor_, env_);
            Vertices g(3, nv_);
            sys.gradient(r.Xpred, g);
            // F(X*) - H (Y - X*): the explicit part of the linearised elastic force.
            Vertices Fexp = -g - sys.hessianTimes(Y - r.Xpred);
            std::optional<ThermalNoise> noise;
            if (thermal_) {
                noise = thermalNoise(sys, model_, r.Xpred, h, opt_.thermal, res_.steps, res_);
                Fexp += noise->force;
            }
            // Linearised area constraint A(X*) + g_A . (Y + alpha u - X*) = A0.
            const double areaRate =
                (A0_ - sys.area() - (sys.areaGradient().array() * (Y - r.Xpred).array()).sum()) / alpha;
            const double volumeRate =
                (V0_ - sys.volume() - (sys.volumeGradient().array() * (Y - r.Xpred).array()).sum()) / alpha;
            // GMRES starts from zero: the BDF2-predicted velocity (Xpred - Y) / alpha and the last
            // step's velocity leave residuals in the grid-scale modes that cost more iterations
            // than they save (level 3: 14.4 iterations per step from zero, 15.5 from the predicted
            // velocity, plus its operator application; docs/FLOW_SOLVER.md, "Preconditioner").
            const CoupledSystem::Solution s = sys.solve(Fexp, areaRate, volumeRate, noise ? &noise->velocity : nullptr);
            r.iterations = s.gmres.iterations;
            if (s.gmres.converged && s.u.allFinite() && std::isfinite(s.tension)) {
                Xnew_ = Y + alpha * s.u;
                r.tension = s.tension;
                r.flux = s.fluxCorrection;
                r.solved = Xnew_.allFinite();
                if (!r.solved) r.failure = "non-finite state";
            } else {
                r.failure = fmt::format("GMRES did not converge (relative residual {:.3e} after {} iterations)",
                                        s.gmres.residual, s.gmres.iterations);
            }
        } catch (const InputError& e) {  // degenerate geometry (non-finite positions, ...)
            r.failure = e.what();
        } catch (const NumericalError& e) {
            r.failure = e.what();
        }
        return r;
    }

    /// Takes the accepted step: removes the second-order area and volume drift of the linearised
    /// step, logs it, records the frames it passes; the run's result when the step ends the run.
    std::optional<CellFlowResult> accept(const bdf2::Step& step, const StepSolve& s, double err) {
        const double areaCorrection = totalArea(Xnew_, F_) / A0_ - 1.0;
        const double volumeCorrection = enclosedVolume(Xnew_, F_) / V0_ - 1.0;
        if (model_.areaConstraint())
            projectAreaVolume(Xnew_, F_, A0_, V0_);
        else
            projectVolume(Xnew_, F_, V0_);
        state_.tension = s.tension;
        state_.steps.accept(Xnew_, step.h);
        ++res_.steps;
        const double tOld = state_.t;
        state_.t = step.end;
        const CellFlowStepRecord rec = logStep(step.h, err, s, areaCorrection, volumeCorrection);
        // Frames in (tOld, t]: BDF2's dense output.
        for (; bdf2::covers(state_.t, frameTime(state_.nextFrame)); ++state_.nextFrame)
            recordFrame(frameTime(state_.nextFrame),
                        bdf2::interpolate(state_.steps, tOld, state_.t, frameTime(state_.nextFrame)));
        // A capsule's area follows its in-plane law: only a constrained area counts as drift.
        const double limit = opt_.maxDrift;
        const bool areaDrifts = model_.areaConstraint() &&
                                (!(std::abs(areaCorrection) <= limit) || !(std::abs(rec.areaDrift) <= limit));
        if (areaDrifts || !(std::abs(volumeCorrection) <= limit) || !(std::abs(rec.volumeDrift) <= limit))
            return finish(false, fmt::format("diverged at t = {:.6g}: area change {:.3g}, volume change {:.3g} in one "
                                             "step (limit {:.3g})",
                                             state_.t, areaCorrection, volumeCorrection, limit));
        if (env_) {
            const std::string why = env_->inadmissible(state_.steps.X);
            if (!why.empty()) return finish(false, fmt::format("stopped at t = {:.6g}: {}", state_.t, why));
        }
        if (opt_.stopWhen && res_.times.size() > state_.framesChecked) {
            state_.framesChecked = res_.times.size();
            if (opt_.stopWhen(res_)) {
                res_.stoppedEarly = true;
                return finish(true, fmt::format("stop criterion met at t = {:.6g}", state_.t));
            }
        }
        return std::nullopt;
    }

    /// The accepted step's record in the step log, and the run's extremes and sums.
    const CellFlowStepRecord& logStep(double h, double err, const StepSolve& s, double areaCorrection,
                                      double volumeCorrection) {
        res_.dtSmallest = std::min(res_.dtSmallest, h);
        res_.dtLargest = std::max(res_.dtLargest, h);
        CellFlowStepRecord rec;
        rec.t = state_.t;
        rec.dt = h;
        rec.error = err;
        rec.gmresIterations = s.iterations;
        rec.tension = state_.tension;
        rec.fluxCorrection = s.flux;
        res_.maxFluxCorrection = std::max(res_.maxFluxCorrection, std::abs(s.flux));
        rec.areaDrift = totalArea(state_.steps.X, F_) / A0_ - 1.0;
        rec.volumeDrift = enclosedVolume(state_.steps.X, F_) / V0_ - 1.0;
        rec.areaCorrection = areaCorrection;
        rec.volumeCorrection = volumeCorrection;
        res_.stepLog.push_back(rec);
        res_.maxAreaDrift = std::max(res_.maxAreaDrift, std::abs(rec.areaDrift));
        res_.maxVolumeDrift = std::max(res_.maxVolumeDrift, std::abs(rec.volumeDrift));
        res_.maxAreaCorrection = std::max(res_.maxAreaCorrection, std::abs(areaCorrection));
        res_.maxVolumeCorrection = std::max(res_.maxVolumeCorrection, std::abs(volumeCorrection));
        res_.sumAreaCorrection += std::abs(areaCorrection);
        res_.sumVolumeCorrection += std::abs(volumeCorrection);
        return res_.stepLog.back();
    }

    const CellFlowModel& model_;
    const CellFlowOptions& opt_;
    const CellFlowObserver& observer_;
    const FlowEnvironment* env_;
    const Faces& F_;
    const double A0_, V0_;
    const Index nv_;
    const bool thermal_ = opt_.thermal.kT > 0.0;
    // A whole number of steps per frame interval, or of frame intervals per step (frames between
    // the steps by the dense output).
    const double thermalStep_ = thermalStepOnFrames(opt_);
    const bdf2::StepControl control_ = stepControl(opt_);
    CellFlowResult res_;
    CellFlowState state_;
    PreconditionerFactor factor_;
    Vertices Xnew_;
    Clock::time_point t0_, lastSnapshot_;
    double wallBefore_ = 0.0;  ///< of the parts before the snapshot resumed
    std::uint64_t fingerprint_ = 0;
    bool snapshots_ = false;
};

}  // namespace

/// A tenth of the step tolerance: the linear solve then adds far less to a step's error
/// than the step control allows: at the shear's 1e-3 R_A (tolerance 1e-4 instead of 1e-6) the
/// observables of 4 level-3 rotations move by 4e-5 deg and 3.6e-5 of the TTF, hundreds of times
/// less than the level 3 -> 4 change, with 37 % fewer iterations (docs/FLOW_SOLVER.md, "GMRES tolerance").
double effectiveGmresTolerance(const CellFlowOptions& o) {
    if (o.gmresTolerance > 0.0) return o.gmresTolerance;
    return o.adaptive ? std::min(1e-4, 0.1 * o.errorTolerance) : 1e-6;
}

void validateFlowConditions(const FlowConditions& f) {
    requirePositive("eta_out", f.etaOut, "mPa s");
    requirePositive("eta_in", f.etaIn, "mPa s");
    if (!(f.shearRate >= 0.0) || !std::isfinite(f.shearRate))
        throw InputError(fmt::format("parameter shear_rate = {} 1/s: must be finite and >= 0", f.shearRate));
    if (f.shearRate == 0.0 && !(f.timeScale > 0.0))
        throw InputError("parameter time_scale: a positive time scale (s) is required in a quiescent fluid");
    if (f.timeScale != 0.0) requirePositive("time_scale", f.timeScale, "s");
    requirePositive("A0", f.A0, "um^2");
    requirePositive("V0", f.V0, "um^3");
}

CellFlowModel::CellFlowModel(const CellParameters& cell, const FlowConditions& flow, const Faces& faces,
                             const Vertices& referenceUm)
    : cell_(cell),
      flow_((validateFlowConditions(flow), flow)),
      scales_(makeScales(flow)),
      internalReference_(checkedReference(faces, referenceUm, scales_.length)),
      membrane_(faces, referenceUm.cols(), internalMembrane(cell, scales_), &internalReference_) {
    for (double v : {cell.mu, cell.FvK, cell.etam})
        if (!(v > 0.0) || !std::isfinite(v))
            throw InputError(fmt::format("cell parameters: mu = {}, FvK = {}, etam = {} must be finite and > 0",
                                         cell.mu, cell.FvK, cell.etam));
    gamma_ = (4.0 * cell.etam / std::sqrt(3.0)) / (scales_.viscosity * scales_.length);
    lambda_ = flow.etaIn / flow.etaOut;
    area0_ = flow.A0 / (scales_.length * scales_.length);
    volume0_ = flow.V0 / (scales_.length * scales_.length * scales_.length);
    background_ = LinearFlow::simpleShear(flow.shearRate * scales_.time);
}

CellFlowModel::CellFlowModel(const MembraneFlowSpec& spec, const Faces& faces, const Vertices& reference)
    : flow_{.etaOut = 1.0, .etaIn = spec.viscosityRatio, .shearRate = 1.0},
      internalReference_(checkedReference(faces, reference, 1.0)),
      membrane_(faces, reference.cols(), spec.membrane, &internalReference_),
      spec_(std::make_shared<const MembraneFlowSpec>(spec)) {
    if (!(spec.edgeFriction >= 0.0) || !std::isfinite(spec.edgeFriction))
        throw InputError(fmt::format("membrane flow: edge friction = {}: must be finite and >= 0", spec.edgeFriction));
    requirePositive("viscosity ratio", spec.viscosityRatio, "");
    gamma_ = spec.edgeFriction;
    lambda_ = spec.viscosityRatio;
    area0_ = totalArea(internalReference_, faces);
    volume0_ = enclosedVolume(internalReference_, faces);
    flow_.A0 = area0_;
    flow_.V0 = volume0_;
    areaConstraint_ = spec.areaConstraint;
    if (!(spec.shearRate >= 0.0) || !std::isfinite(spec.shearRate))
        throw InputError(fmt::format("membrane flow: shear rate = {}: must be finite and >= 0", spec.shearRate));
    background_ = LinearFlow::simpleShear(spec.shearRate);
    flow_.shearRate = spec.shearRate;
}

FlowGroups CellFlowModel::groups() const {
    const double etaOutMPaS = scales_.viscosity * 1e3;
    return flowGroups(cell_, etaOutMPaS, lambda_ * etaOutMPaS, flow_.shearRate, scales_.length);
}

VelocityEvaluation membraneVelocity(const CellFlowModel& model, const Vertices& X, const CellFlowOptions& opt,
                                    const FlowEnvironment* env) {
    checkOptions(opt);
    PreconditionerFactor factor;
    const CoupledSystem sys(model, X, 0.0, opt, factor, env);
    Vertices g(3, X.cols());
    sys.gradient(X, g);
    const CoupledSystem::Solution s = sys.solve(-g, 0.0, 0.0);
    if (!s.gmres.converged)
        throw NumericalError(fmt::format("cell flow: GMRES did not converge (relative residual {:.3e} after {} iterations)",
                                         s.gmres.residual, s.gmres.iterations));
    return {s.u, s.tension, s.gmres.iterations, s.gmres.residual};
}

double thermalStepOnFrames(const CellFlowOptions& opt) {
    const double fi = opt.frameInterval, ts = opt.thermal.step;
    return ts <= fi ? fi / std::ceil(fi / ts * (1.0 - 1e-12)) : fi * std::floor(ts / fi * (1.0 + 1e-12));
}

CellFlowResult integrateCellFlow(const CellFlowModel& model, const Vertices& initial, const CellFlowOptions& opt,
                                 const CellFlowObserver& observer, const FlowEnvironment* env) {
    return CellFlowIntegrator(model, initial, opt, observer, env).run();
}

ShearCell prepareShearCell(const CellParameters& p, int level, const std::filesystem::path& cacheDir) {
    ShearCell c;
    c.sfs = stressFreeState(p.v, level, cacheDir);
    const CellMeshes meshes = cellMeshes(c.sfs);
    ExperimentOptions eo;
    eo.level = level;
    eo.cacheDir = cacheDir;
    // The symmetric disc, as in the flow validations (docs/VALIDATION_RESULTS.md): on the 42-vertex
    // mesh of level 1 (the flow tests) the kicks of the lowest-energy equilibrium find an asymmetric
    // state of the coarse mesh (thickness 3.63 um against the disc's 2.92 um at the Table-1 cell), while at
    // levels 2 and 3 that cell's lowest state is the disc itself, vertex for vertex.
    eo.equilibriumSymmetry = EquilibriumSymmetry::Inversion;
    const EquilibriumResult eq = runEquilibrium(p, meshes, eo);
    c.faces = meshes.faces;
    c.reference = meshes.reference;
    c.equilibrium = eq.diagnostics;
    // Aligned equilibrium: symmetry axis z. Rotate z -> y: (x, y, z) -> (x, z, -y).
    Eigen::Matrix3d R;
    R << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    c.initial = R * eq.shape;
    c.initial = c.initial.colwise() - centroid(c.initial);
    return c;
}

Vertices rotateAboutVorticity(const Vertices& X, double angle) {
    const Eigen::Vector3d c = centroid(X);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    return (R * (X.colwise() - c)).colwise() + c;
}

}  // namespace trbc
