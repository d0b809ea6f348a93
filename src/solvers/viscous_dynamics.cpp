#include "solvers/viscous_dynamics.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.hpp"
#include "solvers/bdf2.hpp"

namespace trbc {
namespace {

// Inverses of the 3x3 vertex blocks of kGamma(X) + shift I: vertex i's block is
// kGamma sum_{j in N(i)} e_ij e_ij^T + shift I (membrane viscosity; the edge dashpots resist only the edge-direction
// component of the relative velocity, so the block is stiff along the edges and soft along the
// normal, where the shift carries the elastic and inertial stiffness).
std::vector<Eigen::Matrix3d> frictionBlockInverses(const Vertices& X, const Topology& T, double kGamma, double shift) {
    const Eigen::Index nv = X.cols();
    std::vector<Eigen::Matrix3d> B(std::size_t(nv), shift * Eigen::Matrix3d::Identity());
    for (Eigen::Index e = 0; e < T.numEdges(); ++e) {
        const int a = T.edges(0, e), b = T.edges(1, e);
        const Eigen::Vector3d u = (X.col(a) - X.col(b)).normalized();
        const Eigen::Matrix3d uu = kGamma * u * u.transpose();
        B[std::size_t(a)] += uu;
        B[std::size_t(b)] += uu;
    }
    for (auto& m : B) m = m.inverse().eval();
    return B;
}

// B v for the 3x3 vertex blocks B.
Eigen::VectorXd blockProduct(const std::vector<Eigen::Matrix3d>& B, const Eigen::VectorXd& v) {
    Eigen::VectorXd out(v.size());
    for (std::size_t i = 0; i < B.size(); ++i) {
        const Eigen::Index j = 3 * Eigen::Index(i);
        out.segment<3>(j) = B[i] * v.segment<3>(j);
    }
    return out;
}

// One variational BDF step: minimise
//   U - f.X + c0/(2dt) (X-Y)^T (Gamma(Xf) + eps) (X-Y) + m c0^2/(2 dt^2) |X - Y - dt Yv / c0|^2,
// with the friction matrix taken at the extrapolated state Xf (second order; Gamma(X_n) would be
// first order). The last term (inertia, m > 0) makes the stationarity condition the BDF2 formula
// for the first-order system (X, V): c0 (X - Y)/dt = V, m c0 (V - Yv)/dt = -dU/dX - Gamma V + f.
MinimizeResult bdfStep(const MembraneModel& model, const Vertices& Xf, const Vertices& Y, const Vertices& Yv,
                       double c0, double dt, const ViscousDynamicsOptions& opt, const Vertices* fext, Vertices& X) {
    const Eigen::Index nv = X.cols();
    const double k = c0 / dt;
    const double km = opt.vertexMass * k * k;
    const Vertices inertialTarget = opt.vertexMass > 0 ? Vertices(Y + Yv / k) : Y;
    Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(X.data(), 3 * nv);
    Vertices Xv(3, nv), G(3, nv), W(3, nv);
    const Eigen::Matrix3Xd edges = unitEdgeVectors(Xf, model.topology());
    const Objective phi = [&](const Eigen::VectorXd& xv, Eigen::VectorXd& g) {
        Xv = Eigen::Map<const Vertices>(xv.data(), 3, nv);
        double u = loadedEnergy(model, Xv, fext, G);
        W = Xv - Y;
        // Gamma W = -f_visc(W); add eps W.
        const Vertices GW = -membraneViscousForceAlong(edges, W, opt.gamma, model.topology()) + opt.isotropicFriction * W;
        u += 0.5 * k * (W.array() * GW.array()).sum();
        G += k * GW;
        if (km > 0) {
            const Vertices D = Xv - inertialTarget;
            u += 0.5 * km * D.squaredNorm();
            G += km * D;
        }
        g = Eigen::Map<const Eigen::VectorXd>(G.data(), 3 * nv);
        return u;
    };
    std::vector<Eigen::Matrix3d> blocks;
    if (opt.preconditionerStiffness > 0 && (!opt.multigrid || opt.blockJacobiWeight > 0))
        blocks = frictionBlockInverses(Xf, model.topology(), k * opt.gamma,
                                       k * opt.isotropicFriction + km + opt.preconditionerStiffness);
    Preconditioner pre;
    if (opt.multigrid) {
        const StiffnessModel& e = opt.elasticStiffness;
        opt.multigrid->setStiffness({e.a0 + k * opt.isotropicFriction + km, e.a1 + opt.frictionLaplacianFactor * k * opt.gamma, e.a2});
        pre = [&opt, &blocks](Eigen::VectorXd& v) {
            const Eigen::VectorXd bv = blocks.empty() ? Eigen::VectorXd() : blockProduct(blocks, v);
            opt.multigrid->apply(v);
            if (!blocks.empty()) v += opt.blockJacobiWeight * bv;
        };
    } else if (!blocks.empty()) {
        pre = [&blocks](Eigen::VectorXd& v) { v = blockProduct(blocks, v); };
    }
    const Preconditioner* h0 = pre ? &pre : nullptr;
    MinimizeResult r;
    if (opt.constraint.active()) {
        const EqualityConstraints con = areaVolumeConstraints(model.faces(), nv, opt.constraint);
        r = lbfgsMinimize(phi, x, opt.inner, &con, h0);
    } else {
        r = lbfgsMinimize(phi, x, opt.inner, nullptr, h0);
    }
    X = Eigen::Map<const Vertices>(x.data(), 3, nv);
    return r;
}

// The step control of the options. The first step keeps its size for the first BDF2 step
// (bdf2::StepControl::firstStepGrowth): a relaxation starts in its fastest transient.
bdf2::StepControl stepControl(const ViscousDynamicsOptions& opt) {
    bdf2::StepControl c;
    c.tolerance = opt.errorTolerance;
    c.adaptive = opt.adaptive;
    c.dtInitial = opt.dtInitial;
    c.dtMin = opt.dtMin;
    c.dtMax = opt.dtMax > 0 ? opt.dtMax : opt.tEnd;
    c.firstStepGrowth = 1.0;
    return c;
}

}  // namespace

ViscousDynamicsResult integrateViscous(const MembraneModel& model, Vertices& X, const ViscousDynamicsOptions& opt,
                                       const std::vector<double>& sampleTimes, const DynamicsObserver& observer,
                                       const Vertices* fext) {
    if (!(opt.gamma > 0) && !(opt.isotropicFriction > 0) && !(opt.vertexMass > 0))
        throw InputError("viscous dynamics needs a positive friction (gamma or isotropic friction) or a vertex mass");
    if (opt.blockJacobiWeight > 0 && (!opt.multigrid || !(opt.preconditionerStiffness > 0)))
        throw InputError(fmt::format("viscous dynamics: blockJacobiWeight = {} needs the multigrid and a positive "
                                     "preconditionerStiffness (got {})", opt.blockJacobiWeight, opt.preconditionerStiffness));
    if (!(opt.tEnd > 0) || !(opt.dtInitial > 0))
        throw InputError(fmt::format("viscous dynamics needs tEnd > 0 and dtInitial > 0 (got {}, {})",
                                     opt.tEnd, opt.dtInitial));
    std::vector<double> samples(sampleTimes);
    std::sort(samples.begin(), samples.end());
    samples.erase(std::remove_if(samples.begin(), samples.end(),
                                 [&](double t) { return t <= 0 || t > opt.tEnd; }),
                  samples.end());
    samples.push_back(opt.tEnd);
    samples.erase(std::unique(samples.begin(), samples.end()), samples.end());
    std::size_t nextSample = 0;
    if (observer) observer(0.0, X);

    ViscousDynamicsResult res;
    res.dtSmallest = std::numeric_limits<double>::infinity();
    const bdf2::StepControl control = stepControl(opt);
    bdf2::History history(X);
    // Velocities (inertial case), started at rest, stepped with the same BDF2 formula.
    Vertices V = Vertices::Zero(3, X.cols()), Vprev = V;
    double t = 0.0, dt = std::min(opt.dtInitial, control.dtMax);
    // The integrator works on the history; X follows it on every return.
    const auto stop = [&](std::string message) {
        X = history.X;
        res.message = std::move(message);
        return res;
    };

    while (!bdf2::reaches(t, opt.tEnd)) {
        if (opt.inner.interruptCheck) opt.inner.interruptCheck();
        if (deadlinePassed(opt.inner.deadline)) return stop(fmt::format("time limit reached at t = {:.6g}", t));
        // Steps land on every sample, or only on tEnd when the samples are interpolated.
        const double target = opt.interpolateSamples ? opt.tEnd : samples[nextSample];
        const bdf2::Step step = control.propose(dt, history, t, target);
        const bdf2::Coefficients coef = bdf2::coefficients(history, step.h);
        const Vertices Y = coef.historyTerm(history.X, history.Xprev);
        const Vertices Yv = opt.vertexMass > 0 ? coef.historyTerm(V, Vprev) : V;
        const Vertices Xpred = bdf2::predictor(history, step.h);
        Vertices Xnew = Xpred;
        const MinimizeResult inner = bdfStep(model, Xpred, Y, Yv, coef.c0, step.h, opt, fext, Xnew);
        res.evaluations += inner.evaluations;
        if (!inner.converged) {
            ++res.rejectedSteps;
            const bdf2::Verdict v = control.afterFailedSolve(step);
            if (v.outcome == bdf2::Outcome::Fail)
                return stop(fmt::format("step size fell below {:.3g} at t = {:.6g}: {}", opt.dtMin, t, inner.message));
            dt = v.dt;
            continue;
        }
        const double err = history.accepted >= 2 ? bdf2::localError(Xnew, Xpred) : 0.0;
        const bdf2::Verdict v = control.judge(step, err, history);
        if (v.outcome != bdf2::Outcome::Accept) {
            ++res.rejectedSteps;
            if (v.outcome == bdf2::Outcome::Fail)
                return stop(fmt::format("step size fell below {:.3g} at t = {:.6g}", opt.dtMin, t));
            dt = v.dt;
            continue;
        }
        if (opt.vertexMass > 0) {
            Vprev.swap(V);
            V = (coef.c0 / step.h) * (Xnew - Y);
        }
        history.accept(Xnew, step.h);
        ++res.steps;
        const double tStart = t;
        t = step.end;
        res.dtSmallest = std::min(res.dtSmallest, step.h);
        res.dtLargest = std::max(res.dtLargest, step.h);
        if (opt.interpolateSamples) {
            for (; nextSample < samples.size() && bdf2::covers(t, samples[nextSample]); ++nextSample)
                if (observer) observer(samples[nextSample], bdf2::interpolate(history, tStart, t, samples[nextSample]));
        } else if (step.landed) {
            if (observer) observer(t, history.X);
            ++nextSample;
        }
        dt = v.dt;
    }
    X = history.X;
    res.completed = true;
    res.message = "completed";
    return res;
}

}  // namespace trbc
