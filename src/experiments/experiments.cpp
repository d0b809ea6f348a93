#include "experiments/experiments.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include "core/clock.hpp"
#include "core/error.hpp"
#include "core/random.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "solvers/minimize.hpp"
#include "solvers/multigrid.hpp"
#include "solvers/viscous_dynamics.hpp"

namespace trbc {
namespace {

const AreaVolumeConstraint kCellConstraint{cell::area, cell::volume};
constexpr double kReferenceSymmetryTolerance = 1e-3;

SolverDiagnostics staticDiagnostics(const MinimizeResult& r, SteadyClock::time_point t0) {
    SolverDiagnostics d;
    d.converged = r.converged;
    d.iterations = r.iterations;
    d.evaluations = r.evaluations;
    d.gradientNorm = r.gradientNorm;
    d.energy = r.energy;
    if (r.multipliers.size() == 2) {
        d.tension = r.multipliers[0];
        d.pressure = r.multipliers[1];
    }
    d.wallSeconds = secondsSince(t0);
    d.message = r.message;
    return d;
}

MinimizeOptions staticOptions(const CellParameters& p, const MembraneModel& model, const Vertices& X,
                              const ExperimentOptions& opt) {
    MinimizeOptions mo;
    mo.gradientTolerance = opt.staticTolerance * p.mu * meanEdgeLength(X, model.topology());
    mo.maxIterations = opt.maxIterations;
    mo.deadline = opt.deadline;
    mo.interruptCheck = opt.interruptCheck;
    // With the multigrid, its scale refreshed at every second pair (one V-cycle per iteration instead of two). Level 4,
    // equilibrium + stretching at 100 pN + a 5-force curve, summed over the reference point, the stiff corner,
    // (0.8, 2, 600, 1) and (0.9, 8, 400, 0.5): 3657 -> 3735 evaluations (every fourth pair: 4227; never,
    // i.e. the multigrid at its own scale: 7700); a 20-force curve at the reference point 1756 -> 1573
    // evaluations and 0.84x the wall time, D0 and D1 within 1.4e-5 um.
    if (opt.multigrid) mo.preconditionerScaleInterval = 2;
    return mo;
}

// The scale R_c of membraneStiffness (solvers/multigrid.hpp): the rim's radius of curvature.
// Force evaluations of an equilibrium plus a 20-force stretching curve at level 4
// (docs/FORWARD_MODEL.md "Multigrid H0"): reference point 1910 / 1730 / 2370 for R_c = 0.35 / 0.5 /
// 0.7 um; stiff corner 2560 / 1950 / 1920; soft corner 45700 / 21600 / 15600 (without the
// multigrid: 10380, 9380 and 19810).
constexpr double kStiffnessCurvatureRadius = 0.5;  // um

StiffnessModel cellStiffness(const CellParameters& p, const Vertices& X, const Topology& topo) {
    return membraneStiffness(p.mu, p.mu, p.kbPnUm(), cell::area / static_cast<double>(X.cols()), meanEdgeLength(X, topo),
                             kStiffnessCurvatureRadius);
}

// Multigrid H0 (ExperimentOptions::multigrid); empty when switched off or the mesh is not an icosphere.
std::optional<IcosphereMultigrid> cellMultigrid(const CellParameters& p, const MembraneModel& model, const Vertices& X,
                                                const ExperimentOptions& opt) {
    if (!opt.multigrid) return std::nullopt;
    return IcosphereMultigrid::build(model.faces(), cellStiffness(p, X, model.topology()));
}

void requireConverged(const SolverDiagnostics& d, const std::string& what) {
    if (!d.converged) throw NumericalError(fmt::format("{} did not converge: {}", what, d.message));
}

// The in-plane axes of a resting (axisymmetric) cell are degenerate, so alignment leaves x to round-off;
// but the bead bands of stretching and the half-line of equilibrium see the mesh's discrete in-plane structure
// (D1 varies by about 1 % with the angle at level 3). Fix the angle geometrically: rotate about z
// so that the vertex farthest from the axis lies on +x (labels and rigid motions of the input
// then no longer matter).
Vertices canonicalInPlaneOrientation(const Vertices& aligned) {
    Eigen::Index far = 0;
    aligned.topRows<2>().colwise().squaredNorm().maxCoeff(&far);
    const double phi = std::atan2(aligned(1, far), aligned(0, far));
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    R.topLeftCorner<2, 2>() << std::cos(phi), std::sin(phi), -std::sin(phi), std::cos(phi);
    return R * aligned;
}

// alignment literally: x = the in-plane axis of largest variance (alignPrincipalAxes), its sign fixed so
// that the vertex with the largest |x| lies on +x (a rotation by pi about z otherwise).
Vertices largestVarianceOrientation(const Vertices& aligned) {
    Eigen::Index far = 0;
    aligned.row(0).cwiseAbs().maxCoeff(&far);
    if (aligned(0, far) >= 0) return aligned;
    Vertices flipped = aligned;
    flipped.topRows<2>() *= -1.0;
    return flipped;
}

// EquilibriumSymmetry::Inversion (and the symmetric start of Lowest) restricts the minimisation to
// centrally symmetric shapes, which is exact only for an energy invariant under the inversion, i.e. a
// symmetric Lim reference.
const std::vector<Eigen::Index>& equilibriumSymmetry(const CellMeshes& m) {
    if (m.inversionPartners.size() != static_cast<size_t>(m.reference.cols()))
        throw NumericalError("symmetric equilibrium: the mesh is not centrally symmetric (no inversion partners)");
    const double asym = inversionAsymmetry(m.reference, m.inversionPartners);
    if (asym > 1e-12)
        throw NumericalError(fmt::format("symmetric equilibrium: the Lim reference is not centrally symmetric "
                                         "(|x_i + x_j| up to {:.3g} of its size)", asym));
    return m.inversionPartners;
}

// The equilibrium's minimisations share the model, the stopping rule (from the biconcave start's
// edge length) and the H0.
struct EquilibriumProblem {
    const CellMeshes& meshes;
    const MembraneModel& model;
    const MinimizeOptions& options;
    const Preconditioner* h0;
};

EquilibriumCandidate minimizeCandidate(const EquilibriumProblem& e, Vertices& X, const std::vector<Eigen::Index>* symmetry,
                                       MinimizeResult& r) {
    const auto t0 = SteadyClock::now();
    r = minimizeEnergy(e.model, X, e.options, nullptr, kCellConstraint, e.h0, symmetry);
    EquilibriumCandidate c;
    c.converged = r.converged;
    c.energy = r.energy;
    c.evaluations = r.evaluations;
    c.hmin = equilibriumObservables(alignPrincipalAxes(X), e.meshes.faces).hmin;
    if (e.meshes.inversionPartners.size() == static_cast<size_t>(X.cols()))
        c.asymmetry = inversionAsymmetry(X, e.meshes.inversionPartners);
    c.wallSeconds = secondsSince(t0);
    return c;
}

struct EquilibriumState {
    Vertices X;
    MinimizeResult result;
};

constexpr int kMinKickIterations = 1000, kKickIterationFactor = 20;

// Kick k of a round is min(k, 3) times the thermal field: near the switch to the cup the
// field itself (1 sigma) returns to the disc where 2 and 3 sigma reach the cup (level 4, v 0.99, FvK 122:
// 0 / 3 / 4 of 6 seeds), while 4 sigma of a soft membrane (FvK 1000, 0.6 um rms) crumples the shape
// (40,737 evaluations without converging at level 3, v 0.96).
double kickScale(int kick) { return std::min(kick, 3); }

// EquilibriumSymmetry::Lowest after the symmetric minimum `best`: rounds of thermal kicks
// (EquilibriumKicks). Only a state lower by more than kT counts as lower: states closer than kT are
// equally populated, and the margin keeps a kick that returns to `best` within the solver's tolerance
// from replacing it.
EquilibriumState lowestAfterKicks(const CellParameters& p, const EquilibriumProblem& e, EquilibriumState best,
                                  const ExperimentOptions& opt, EquilibriumResult& res) {
    const double kT = thermalEnergy(opt.kicks.temperatureK);
    const double radius = std::sqrt(cell::radiusSquared);
    res.kickRms = undulationRms(radius, kT, p.kbPnUm());
    // A kick gets kKickIterationFactor times the symmetric minimisation's iterations (at least
    // kMinKickIterations): the large kicks of a soft membrane can crumple the shape into a state that
    // takes tens of thousands of iterations to unfold; such a kick is dropped instead.
    MinimizeOptions kickOptions = e.options;
    kickOptions.maxIterations =
        std::min(e.options.maxIterations, std::max(kMinKickIterations, kKickIterationFactor * best.result.iterations));
    const EquilibriumProblem kicked{e.meshes, e.model, kickOptions, e.h0};
    for (int round = 1; round <= opt.kicks.maxRounds; ++round) {
        std::optional<EquilibriumState> lower;
        for (int kick = 1; kick <= opt.kicks.perRound; ++kick) {
            Rng rng(opt.kicks.seed, static_cast<std::uint64_t>(round), static_cast<std::uint64_t>(kick));
            EquilibriumState s{best.X + kickScale(kick) * thermalUndulation(best.X, radius, kT, p.kbPnUm(), rng), {}};
            EquilibriumCandidate c = minimizeCandidate(kicked, s.X, nullptr, s.result);
            c.start = "kick";
            c.round = round;
            c.kick = kick;
            res.candidates.push_back(c);
            if (!s.result.converged) {
                // A kick that exhausts the iterations is no candidate; one stopped by the deadline stops the sample.
                if (deadlinePassed(opt.deadline)) requireConverged(staticDiagnostics(s.result, SteadyClock::now()), "equilibrium shape");
                continue;
            }
            const double bar = lower ? lower->result.energy : best.result.energy - kT;
            if (s.result.energy < bar) lower = std::move(s);
        }
        if (!lower) break;
        best = std::move(*lower);
        res.branch = "kicked";
    }
    return best;
}

}  // namespace

const char* equilibriumSymmetryName(EquilibriumSymmetry s) {
    switch (s) {
        case EquilibriumSymmetry::Inversion: return "inversion";
        case EquilibriumSymmetry::None: return "none";
        case EquilibriumSymmetry::Lowest: break;
    }
    return "lowest";
}

EquilibriumSymmetry equilibriumSymmetryFromName(const std::string& name, const std::string& option) {
    for (EquilibriumSymmetry s : {EquilibriumSymmetry::Lowest, EquilibriumSymmetry::Inversion, EquilibriumSymmetry::None})
        if (name == equilibriumSymmetryName(s)) return s;
    throw InputError(fmt::format("{}: '{}' is not one of lowest, inversion, none", option, name));
}

const char* inPlaneAxisName(InPlaneAxis a) {
    return a == InPlaneAxis::LargestVariance ? "largest-variance" : "farthest-vertex";
}

CellMeshes cellMeshes(const StressFreeState& sfs, bool symmetricReference) {
    CellMeshes m;
    m.faces = sfs.mesh.F;
    m.reference = scaleToArea(sfs.mesh.X, sfs.mesh.F, cell::area);
    // equilibrium variant: Evans-Fung map of the same icosphere, whose symmetry axis z is the SFS
    // material axis (the SFS was seeded along z), so the material and shape axes coincide.
    const Mesh ico = icosphere(sfs.level);
    m.initial = scaleToArea(evansFungMap(ico.X), ico.F, cell::area);
    // The SFS is seeded as the (centrally symmetric) icosphere and its minimiser keeps the symmetry
    // to its tolerance (|x_i + x_j| up to 1.8e-5 of the size at v 0.9999, level 4): the reference is
    // its symmetric part, so that the energy is exactly invariant under the inversion (the equilibrium's
    // symmetric equilibrium). A mesh of another kind keeps its own reference.
    m.inversionPartners = inversionPartners(ico.X);
    if (symmetricReference && !m.inversionPartners.empty() &&
        inversionAsymmetry(m.reference, m.inversionPartners) <= kReferenceSymmetryTolerance)
        symmetrizeUnderInversion(m.reference, m.inversionPartners);
    return m;
}

EquilibriumResult runEquilibrium(const CellParameters& p, const CellMeshes& meshes, const ExperimentOptions& opt) {
    const auto t0 = SteadyClock::now();
    const MembraneModel model(meshes.faces, meshes.reference.cols(), experimentMembrane(p), &meshes.reference);
    EquilibriumResult res;
    const auto mg = cellMultigrid(p, model, meshes.initial, opt);
    const Preconditioner pre = asPreconditioner(mg);
    const MinimizeOptions mo = staticOptions(p, model, meshes.initial, opt);
    const EquilibriumProblem problem{meshes, model, mo, pre ? &pre : nullptr};
    const bool symmetric = opt.equilibriumSymmetry != EquilibriumSymmetry::None;
    EquilibriumState state{meshes.initial, {}};
    EquilibriumCandidate first = minimizeCandidate(problem, state.X, symmetric ? &equilibriumSymmetry(meshes) : nullptr, state.result);
    first.start = "biconcave";
    res.candidates.push_back(first);
    requireConverged(staticDiagnostics(state.result, t0), "equilibrium shape");
    res.branch = symmetric ? "symmetric" : "unrestricted";
    const double symmetricEnergy = state.result.energy;
    if (opt.equilibriumSymmetry == EquilibriumSymmetry::Lowest) {
        state = lowestAfterKicks(p, problem, std::move(state), opt, res);
        res.energyGap = symmetricEnergy - state.result.energy;
    }
    res.diagnostics = staticDiagnostics(state.result, t0);
    res.diagnostics.evaluations = 0;
    for (const EquilibriumCandidate& c : res.candidates) res.diagnostics.evaluations += c.evaluations;
    const Vertices aligned = alignPrincipalAxes(state.X);
    res.shape = opt.inPlaneAxis == InPlaneAxis::LargestVariance ? largestVarianceOrientation(aligned)
                                                                : canonicalInPlaneOrientation(aligned);
    res.observables = equilibriumObservables(res.shape, meshes.faces, &res.profile);
    res.diagnostics.wallSeconds = secondsSince(t0);
    return res;
}

Vertices beadForces(const Vertices& X, const Faces& faces, double fext) {
    const Topology topo = buildTopology(faces, X.cols());
    const double h = meanEdgeLength(X, topo);
    const double xbar = X.row(0).mean();
    const double R0 = 0.5 * (X.row(0).maxCoeff() - X.row(0).minCoeff());
    const double rc = 0.5 * cell::beadContactDiameter;
    if (!(R0 > rc)) throw NumericalError(fmt::format("cell radius {:.4g} um is smaller than the bead contact radius", R0));
    const double xc = std::sqrt(R0 * R0 - rc * rc);
    std::vector<Eigen::Index> right, left;
    for (Eigen::Index i = 0; i < X.cols(); ++i) {
        const double dx = X(0, i) - xbar;
        if (std::abs(dx - xc) <= 0.25 * h) right.push_back(i);
        if (std::abs(dx + xc) <= 0.25 * h) left.push_back(i);
    }
    if (right.empty() || left.empty())
        throw NumericalError(fmt::format("bead contact set is empty (right {}, left {} vertices)", right.size(), left.size()));
    Vertices f = Vertices::Zero(3, X.cols());
    for (auto i : right) f(0, i) += fext / static_cast<double>(right.size());
    for (auto i : left) f(0, i) -= fext / static_cast<double>(left.size());
    return f;
}

std::vector<StretchPoint> runStretching(const CellParameters& p, const CellMeshes& meshes, const Vertices& equilibrium,
                                        std::vector<double> forces, const ExperimentOptions& opt,
                                        std::vector<Vertices>* shapes) {
    std::sort(forces.begin(), forces.end());
    const MembraneModel model(meshes.faces, meshes.reference.cols(), experimentMembrane(p), &meshes.reference);
    const Vertices unit = beadForces(equilibrium, meshes.faces, 1.0);
    const MinimizeOptions mo = staticOptions(p, model, equilibrium, opt);
    const auto mg = cellMultigrid(p, model, equilibrium, opt);
    const Preconditioner pre = asPreconditioner(mg);
    const Preconditioner* h0 = pre ? &pre : nullptr;
    std::vector<StretchPoint> out;
    Vertices X = equilibrium, Xprev;
    double fPrev = 0.0, fPrevPrev = 0.0;
    int lastIterations = 0;
    for (double f : forces) {
        const auto t0 = SteadyClock::now();
        // Secant predictor along the force path, X(f) ~ X_k + (f - f_k) / (f_k - f_{k-1}) (X_k - X_{k-1}),
        // its step capped at the last one; the minimiser's retraction restores A and V. Falls back
        // to the plain continuation (start from X_k) when the predicted shape fails.
        const Vertices Xk = X;
        // The predicted start gets a budget of 10x the last level's iterations (at least 1000): a
        // prediction that lands in a poor basin is abandoned early instead of crawling to maxIterations.
        const bool predict = Xprev.size() && fPrev > fPrevPrev && f > fPrev;
        if (predict) X += std::min(1.0, (f - fPrev) / (fPrev - fPrevPrev)) * (Xk - Xprev);
        const Vertices fext = f * unit;
        MinimizeOptions first = mo;
        if (predict) first.maxIterations = std::min(mo.maxIterations, std::max(1000, 10 * lastIterations));
        MinimizeResult r = minimizeEnergy(model, X, first, &fext, kCellConstraint, h0);
        if (predict && !r.converged) {
            X = Xk;
            const int evaluations = r.evaluations;
            r = minimizeEnergy(model, X, mo, &fext, kCellConstraint, h0);
            r.evaluations += evaluations;
        }
        lastIterations = r.iterations;
        Xprev = Xk;
        fPrevPrev = fPrev;
        fPrev = f;
        StretchPoint pt;
        pt.fext = f;
        pt.diagnostics = staticDiagnostics(r, t0);
        requireConverged(pt.diagnostics, fmt::format("stretching at {} pN", f));
        pt.observables = stretchObservables(X);
        out.push_back(pt);
        if (shapes) shapes->push_back(X);
    }
    return out;
}

RelaxationResult runRelaxation(const CellParameters& p, const CellMeshes& meshes, const Vertices& equilibrium,
                               const ExperimentOptions& opt) {
    RelaxationResult res;
    res.preStretchForce = cell::preStretchForcePerMu * p.mu;
    std::vector<Vertices> stretched;
    const std::vector<StretchPoint> pre =
        runStretching(p, meshes, equilibrium, {res.preStretchForce}, opt, &stretched);
    res.preStretch = pre.front().diagnostics;
    res.released = alignPrincipalAxes(stretched.front());

    const auto t0 = SteadyClock::now();
    const MembraneModel model(meshes.faces, meshes.reference.cols(), experimentMembrane(p), &meshes.reference);
    ViscousDynamicsOptions vo;
    vo.gamma = 4.0 * p.etam / std::sqrt(3.0);
    if (opt.overdamped)
        vo.isotropicFriction = opt.isotropicFriction * vo.gamma;
    else
        vo.vertexMass = opt.vertexMassKg * 1e6;  // kg -> pN s^2 / um
    vo.tEnd = opt.relaxDuration;
    const double tc0 = p.etam / p.mu;  // Kelvin-Voigt time, sets the first step
    vo.dtInitial = 1e-3 * tc0;
    vo.errorTolerance = opt.relaxErrorTolerance;
    vo.inner.gradientTolerance = opt.relaxInnerTolerance * p.mu * meanEdgeLength(equilibrium, model.topology());
    vo.inner.maxIterations = 5000;
    vo.inner.deadline = opt.deadline;
    vo.inner.interruptCheck = opt.interruptCheck;
    vo.interpolateSamples = true;
    vo.constraint = kCellConstraint;
    // Block-Jacobi H0 of the inner L-BFGS: friction and inertia blocks plus an elastic stiffness
    // per vertex of 12 (mu + kb / l0^2) (in-plane and bending scales). Relaxation force
    // evaluations summed over the reference point, both prior corners and (v, mu, FvK, b2, etam) =
    // (0.8, 2, 600, 1, 0.2): factor 6 / 8 / 12 / 16 gave 7391 / 7670 / 7246 / 7332 at level 3 and
    // 14985 / 15110 / 14381 / 14409 at level 4; none: 19036 at level 4 (the single points scatter
    // by +-10 % between factors: the inner tolerance decides where each step stops).
    const double l0 = meanEdgeLength(equilibrium, model.topology());
    vo.preconditionerStiffness = 12.0 * (p.mu + p.kbPnUm() / (l0 * l0));
    // From level 4 up (Nv >= 2562), the multigrid replaces the blocks: H0 of
    // (a0 + k eps + m k^2) I + (mu + k gamma / 2) L + kb/l0^2 L^2 at its physical scale (the edge
    // dashpots as half a scalar Laplacian, their in-plane average). Relaxation wall time at level 4
    // (force evaluations): reference point 1.51 -> 1.23 s (2273 -> 1299), stiff corner 3.22 -> 1.71 s,
    // soft corner 2.09 -> 0.74 s, (0.8, 2, 600, 1, 0.2) 1.65 -> 1.60 s; at level 3 the blocks are
    // as fast (1.29 s against 1.39 s summed over the same four points).
    constexpr Eigen::Index kMultigridRelaxationVertices = 2562;
    auto mg = equilibrium.cols() >= kMultigridRelaxationVertices ? cellMultigrid(p, model, equilibrium, opt)
                                                                   : std::nullopt;
    if (mg) {
        vo.multigrid = &*mg;
        vo.elasticStiffness = cellStiffness(p, equilibrium, model.topology());
        vo.frictionLaplacianFactor = 0.5;
        // Plus half the blocks: relaxation force evaluations at level 4 summed over the four points
        // above 5696 -> 4987 (weight 0.25 / 0.35 / 0.5 / 0.7 / 1: 5070 / 5079 / 4987 / 5237 / 5923),
        // over (v, mu, FvK, b2, etam) = (0.7, 6, 100, 2.5, 0.5), (0.9, 8, 400, 0.5, 0.3),
        // (0.85, 3, 50, 3, 0.9), (0.97, 5, 800, 1, 0.15) 4762 -> 4230; tc within 0.6 %.
        vo.blockJacobiWeight = 0.5;
        vo.inner.scalePreconditioner = false;
    }
    std::vector<double> times;
    for (int k = 1; k <= opt.relaxSamples; ++k) times.push_back(opt.relaxDuration * k / opt.relaxSamples);
    Vertices X = res.released;
    const DynamicsObserver observe = [&](double t, const Vertices& Y) {
        const Eigen::Vector3d e = sortedExtents(Y);  // relaxation: L = largest extent, W = second largest
        res.t.push_back(t);
        res.L.push_back(e[0]);
        res.W.push_back(e[1]);
        res.z.push_back(e[0] / e[1]);
    };
    const ViscousDynamicsResult r = integrateViscous(model, X, vo, times, observe);
    res.dynamics.converged = r.completed;
    res.dynamics.iterations = r.steps;
    res.dynamics.evaluations = r.evaluations;
    res.dynamics.message = r.message;
    res.dynamics.wallSeconds = secondsSince(t0);
    res.rejectedSteps = r.rejectedSteps;
    requireConverged(res.dynamics, "relaxation");
    res.final = X;
    // relaxation: the fit starts at the first sample after release, z0 fixed to it.
    const std::vector<double> tf(res.t.begin() + 1, res.t.end()), zf(res.z.begin() + 1, res.z.end());
    res.fit = fitHochmuth(tf, zf);
    if (!res.fit.converged) throw NumericalError("Hochmuth fit of the relaxation did not converge: " + res.fit.message);
    return res;
}

SampleResult runSample(const CellParameters& p, double fext, const ExperimentSet& which, const ExperimentOptions& opt,
                       const std::vector<double>& curveForces, bool keepShapes) {
    const auto stage = [&opt](const std::string& what) {
        if (opt.progress) opt.progress(what);
    };
    SampleResult s;
    s.parameters = p;
    s.fext = fext;
    stage(fmt::format("stress-free state (v = {:g}, level {})", p.v, opt.level));
    s.sfs = stressFreeState(p.v, opt.level, opt.cacheDir, opt.sfs);
    if (!which.equilibrium && !which.stretching && !which.relaxation) return s;
    const CellMeshes meshes = cellMeshes(s.sfs, usesSymmetricReference(opt.equilibriumSymmetry));
    stage("equilibrium shape");
    s.equilibrium = runEquilibrium(p, meshes, opt);
    if (which.stretching) {
        std::vector<double> forces{fext};
        stage(fmt::format("stretching at {:g} pN", fext));
        s.stretching = runStretching(p, meshes, s.equilibrium.shape, forces, opt, keepShapes ? &s.stretchShapes : nullptr);
        if (!curveForces.empty()) {
            stage(fmt::format("stretching curve ({} forces)", curveForces.size()));
            const auto curve = runStretching(p, meshes, s.equilibrium.shape, curveForces, opt,
                                             keepShapes ? &s.stretchShapes : nullptr);
            s.stretching.insert(s.stretching.end(), curve.begin(), curve.end());
        }
    }
    if (which.relaxation) {
        stage("relaxation");
        s.relaxation = runRelaxation(p, meshes, s.equilibrium.shape, opt);
    }
    return s;
}

}  // namespace trbc
