#include "solvers/viscous_dynamics.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.hpp"

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

double maxNorm(const Vertices& D) { return D.colwise().norm().maxCoeff(); }

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
    const double dtMax = opt.dtMax > 0 ? opt.dtMax : opt.tEnd;
    // History: X_n (current), X_{n-1}, X_{n-2} with step sizes.
    Vertices Xprev = X, Xprev2 = X;
    Vertices V = Vertices::Zero(3, X.cols()), Vprev = V;  // velocities (inertial case), start at rest
    double dtPrev = 0.0, dtPrev2 = 0.0;
    int history = 0;  // number of completed steps
    double t = 0.0, dt = std::min(opt.dtInitial, dtMax);
    Vertices Xnew(3, X.cols());

    while (t < opt.tEnd * (1 - 1e-14)) {
        if (opt.inner.interruptCheck) opt.inner.interruptCheck();
        if (deadlinePassed(opt.inner.deadline)) {
            res.message = fmt::format("time limit reached at t = {:.6g}", t);
            return res;
        }
        const double target = samples[nextSample];
        bool hitsSample = false;
        double h = dt;
        if (history >= 1) h = std::min(h, 2.4 * dtPrev);  // variable-step BDF2 is zero-stable for w < 1 + sqrt 2
        if (!opt.interpolateSamples && t + h >= target * (1 - 1e-12)) {
            h = target - t;
            hitsSample = true;
        }
        if (t + h >= opt.tEnd * (1 - 1e-12)) {
            h = opt.tEnd - t;
            hitsSample = !opt.interpolateSamples;
        }
        double c0 = 1.0;
        Vertices Y = X, Yv = V;
        Vertices Xpred = X;
        if (history >= 1) {
            const double w = h / dtPrev;
            c0 = (1 + 2 * w) / (1 + w);
            Y = ((1 + w) * X - (w * w / (1 + w)) * Xprev) / c0;
            if (opt.vertexMass > 0) Yv = ((1 + w) * V - (w * w / (1 + w)) * Vprev) / c0;
            Xpred = X + w * (X - Xprev);
            if (history >= 2) {
                // Quadratic extrapolation through (t-dtPrev-dtPrev2, t-dtPrev, t).
                const double t0 = -dtPrev - dtPrev2, t1 = -dtPrev, t2 = 0.0, tp = h;
                const double l0 = (tp - t1) * (tp - t2) / ((t0 - t1) * (t0 - t2));
                const double l1 = (tp - t0) * (tp - t2) / ((t1 - t0) * (t1 - t2));
                const double l2 = (tp - t0) * (tp - t1) / ((t2 - t0) * (t2 - t1));
                Xpred = l0 * Xprev2 + l1 * Xprev + l2 * X;
            }
        }
        Xnew = Xpred;
        const MinimizeResult inner = bdfStep(model, Xpred, Y, Yv, c0, h, opt, fext, Xnew);
        res.evaluations += inner.evaluations;
        if (!inner.converged) {
            ++res.rejectedSteps;
            dt = 0.25 * h;
            if (dt < opt.dtMin) {
                res.message = fmt::format("step size fell below {:.3g} at t = {:.6g}: {}", opt.dtMin, t,
                                          inner.message);
                return res;
            }
            continue;
        }
        double factor = 2.0;
        if (opt.adaptive && history >= 2) {
            const double err = (2.0 / 11.0) * maxNorm(Xnew - Xpred);  // BDF2 vs quadratic predictor
            if (err > opt.errorTolerance) {
                ++res.rejectedSteps;
                dt = std::max(opt.dtMin, h * std::max(0.2, 0.9 * std::cbrt(opt.errorTolerance / err)));
                if (h <= opt.dtMin) {
                    res.message = fmt::format("step size fell below {:.3g} at t = {:.6g}", opt.dtMin, t);
                    return res;
                }
                continue;
            }
            factor = std::clamp(0.9 * std::cbrt(opt.errorTolerance / std::max(err, 1e-300)), 0.2, 2.0);
        }
        // Accept.
        if (opt.vertexMass > 0) {
            Vprev.swap(V);
            V = (c0 / h) * (Xnew - Y);
        }
        Xprev2.swap(Xprev);
        Xprev.swap(X);
        X.swap(Xnew);
        dtPrev2 = dtPrev;
        dtPrev = h;
        ++history;
        ++res.steps;
        t += h;
        res.dtSmallest = std::min(res.dtSmallest, h);
        res.dtLargest = std::max(res.dtLargest, h);
        if (hitsSample) {
            t = target;
            if (observer) observer(t, X);
            ++nextSample;
        } else if (opt.interpolateSamples) {
            // Dense output: quadratic through (t - h - dtPrev2, t - h, t), the BDF2 interpolant.
            const double tNew = t;
            while (nextSample < samples.size() && samples[nextSample] <= tNew * (1 + 1e-12)) {
                const double ts = samples[nextSample++];
                if (history < 2) {
                    const double a = (ts - (tNew - h)) / h;
                    if (observer) observer(ts, Vertices((1 - a) * Xprev + a * X));
                    continue;
                }
                const double t0 = tNew - h - dtPrev2, t1 = tNew - h, t2 = tNew;
                const double l0 = (ts - t1) * (ts - t2) / ((t0 - t1) * (t0 - t2));
                const double l1 = (ts - t0) * (ts - t2) / ((t1 - t0) * (t1 - t2));
                const double l2 = (ts - t0) * (ts - t1) / ((t2 - t0) * (t2 - t1));
                if (observer) observer(ts, Vertices(l0 * Xprev2 + l1 * Xprev + l2 * X));
            }
            if (tNew >= opt.tEnd * (1 - 1e-12)) t = opt.tEnd;
        }
        if (opt.adaptive) {
            // After a step shortened to hit a sample, keep the step that the error control wanted.
            dt = std::min(dtMax, std::max(hitsSample ? dt : h, h) * (history >= 2 ? factor : 1.0));
        } else {
            dt = opt.dtInitial;
        }
    }
    res.completed = true;
    res.message = "completed";
    return res;
}

}  // namespace trbc
