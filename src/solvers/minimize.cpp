#include "solvers/minimize.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <deque>
#include <stdexcept>
#include <limits>

#include "mesh/geometry.hpp"

namespace trbc {

double maxVertexNorm(const Eigen::VectorXd& g) {
    const Eigen::Map<const Eigen::Matrix3Xd> G(g.data(), 3, g.size() / 3);
    return G.colwise().norm().maxCoeff();
}

namespace {

struct Pair {
    Eigen::VectorXd s, y;
    double rho;
    double yHy;  ///< y.H0 y (y.y without a preconditioner)
};

// Two-loop recursion: d = -H g, H0 = (s.y / y.H0 y) P from the newest pair (P = I without a
// preconditioner).
Eigen::VectorXd lbfgsDirection(const std::deque<Pair>& mem, const Eigen::VectorXd& g, const Preconditioner* pre) {
    Eigen::VectorXd q = -g;
    std::vector<double> alpha(mem.size());
    for (int k = static_cast<int>(mem.size()) - 1; k >= 0; --k) {
        alpha[k] = mem[k].rho * mem[k].s.dot(q);
        q -= alpha[k] * mem[k].y;
    }
    if (pre) (*pre)(q);
    if (!mem.empty()) {
        const auto& last = mem.back();
        q *= 1.0 / (last.rho * last.yHy);
    }
    for (std::size_t k = 0; k < mem.size(); ++k) {
        const double beta = mem[k].rho * mem[k].y.dot(q);
        q += (alpha[k] - beta) * mem[k].s;
    }
    return q;
}

// The constraint manifold c(x) = 0 around the current point: values, Jacobian and the Cholesky
// factor of J^T J, which give the multipliers, the tangent projector and the retraction.
class Manifold {
public:
    explicit Manifold(const EqualityConstraints* con) : con_(con) {}
    bool active() const { return con_ != nullptr; }

    void at(const Eigen::VectorXd& x) {
        con_->evaluate(x, c_, J_);
        const Eigen::Index m = J_.cols();
        Eigen::MatrixXd gram(m, m);  // J^T J by dot products (a general GEMM is slow for m = 2)
        for (Eigen::Index a = 0; a < m; ++a)
            for (Eigen::Index b = 0; b <= a; ++b) gram(a, b) = gram(b, a) = J_.col(a).dot(J_.col(b));
        gram_.compute(gram);
    }
    double error() const { return (c_.array().abs() / con_->scale.array()).maxCoeff(); }
    // lambda = (J^T J)^{-1} J^T g: least-squares multipliers of the gradient g.
    Eigen::VectorXd multipliers(const Eigen::VectorXd& g) const {
        Eigen::VectorXd jg(J_.cols());
        for (Eigen::Index a = 0; a < J_.cols(); ++a) jg[a] = J_.col(a).dot(g);
        return gram_.solve(jg);
    }
    const Eigen::MatrixXd& jacobian() const { return J_; }
    const Eigen::VectorXd& values() const { return c_; }
    // v <- (I - J (J^T J)^{-1} J^T) v.
    void project(Eigen::VectorXd& v) const { v -= J_ * multipliers(v); }

    // Gauss-Newton projection of x onto c = 0; leaves the manifold state at the new x.
    bool retract(Eigen::VectorXd& x) {
        at(x);
        for (int it = 0; it < con_->maxNewtonIterations; ++it) {
            if (!c_.allFinite()) return false;
            if (error() <= con_->tolerance) return true;
            x -= J_ * gram_.solve(c_);
            if (con_->values) {
                con_->values(x, c_);
                if (c_.allFinite() && error() <= con_->tolerance) return true;
            }
            at(x);
        }
        return c_.allFinite() && error() <= con_->tolerance;
    }

private:
    const EqualityConstraints* con_;
    Eigen::VectorXd c_;
    Eigen::MatrixXd J_;
    Eigen::LDLT<Eigen::MatrixXd> gram_;
};

}  // namespace

MinimizeResult lbfgsMinimize(const Objective& f, Eigen::VectorXd& x, const MinimizeOptions& opt,
                             const EqualityConstraints* constraints, const Preconditioner* pre) {
    MinimizeResult res;
    const Eigen::Index n = x.size();
    Manifold manifold(constraints);
    if (manifold.active() && !manifold.retract(x)) {
        res.message = "the starting point cannot be projected onto the constraints";
        return res;
    }
    Eigen::VectorXd g(n), gNew(n), xNew(n), lambda;
    double fx = f(x, g);
    ++res.evaluations;
    if (!std::isfinite(fx) || !g.allFinite()) {
        res.message = "objective is not finite at the starting point";
        res.energy = fx;
        return res;
    }
    // pg: gradient of the Lagrangian f - lambda.c, i.e. the tangent component of g.
    Eigen::VectorXd pg = g;
    Eigen::MatrixXd Jx;
    if (manifold.active()) {
        Jx = manifold.jacobian();
        lambda = manifold.multipliers(g);
        pg -= manifold.jacobian() * lambda;
    }
    std::deque<Pair> mem;
    double lastScale = 0.0;  // y.H0 y / s.y of the last pair that applied the preconditioner
    int pairsSinceScale = 0;
    // Adds a pair if its curvature s.y is positive (keeps the L-BFGS matrix positive definite).
    const auto remember = [&](Pair p) {
        const double sy = p.s.dot(p.y);
        if (!(sy > 1e-12 * p.s.norm() * p.y.norm())) return;
        p.rho = 1.0 / sy;
        if (pre && !opt.scalePreconditioner) {
            p.yHy = sy;  // unit scale: rho * yHy = 1 in the two-loop recursion
        } else if (pre && lastScale > 0 && ++pairsSinceScale < opt.preconditionerScaleInterval) {
            p.yHy = sy * lastScale;
        } else if (pre) {
            Eigen::VectorXd hy = p.y;
            (*pre)(hy);
            p.yHy = p.y.dot(hy);
            lastScale = p.yHy / sy;
            pairsSinceScale = 0;
        } else {
            p.yHy = p.y.squaredNorm();
        }
        mem.push_back(std::move(p));
        if (static_cast<int>(mem.size()) > opt.memory) mem.pop_front();
    };
    constexpr double c1 = 1e-4;
    constexpr double eps = std::numeric_limits<double>::epsilon();

    for (res.iterations = 0; res.iterations < opt.maxIterations; ++res.iterations) {
        res.gradientNorm = maxVertexNorm(pg);
        if (res.gradientNorm <= opt.gradientTolerance) {
            res.converged = true;
            break;
        }
        if (opt.interruptCheck) opt.interruptCheck();
        if (deadlinePassed(opt.deadline)) {
            res.message = fmt::format("time limit reached after {} iterations, gradient norm {:.3g} > {:.3g}",
                                      res.iterations, res.gradientNorm, opt.gradientTolerance);
            break;
        }
        Eigen::VectorXd d = lbfgsDirection(mem, pg, pre);
        if (manifold.active()) manifold.project(d);
        double slope = pg.dot(d);
        if (!(slope < 0)) {  // not a descent direction: restart from steepest descent
            mem.clear();
            lastScale = 0.0;
            d = -pg;
            slope = -pg.squaredNorm();
        }
        double t = 1.0;
        if (mem.empty() && !pre) t = std::min(1.0, 1.0 / pg.norm());  // first step or restart
        if (opt.maxVertexStep > 0) {
            const double dm = maxVertexNorm(d);
            if (t * dm > opt.maxVertexStep) t = opt.maxVertexStep / dm;
        }

        // Backtracking with Armijo; where energy differences are at round-off level the
        // directional derivative decides (the gradient stays accurate when the energy does not).
        // Constrained: the trial point is retracted onto the manifold first (the manifold state
        // then belongs to the trial point).
        bool accepted = false;
        double fNew = fx;
        const double merit = manifold.active() ? fx - lambda.dot(manifold.values()) : fx;
        for (int ls = 0; ls < 40; ++ls) {
            xNew = x + t * d;
            if (!manifold.active() || manifold.retract(xNew)) {
                fNew = f(xNew, gNew);
                ++res.evaluations;
                // Merit: the Lagrangian f - lambda.c, blind to the retraction's residual c.
                const double meritNew = manifold.active() ? fNew - lambda.dot(manifold.values()) : fNew;
                if (std::isfinite(fNew) && gNew.allFinite()) {
                    const double noise = 100.0 * eps * std::abs(fx);
                    if (meritNew <= merit + c1 * t * slope)
                        accepted = true;
                    else if (std::abs(fNew - fx) <= noise && std::abs(gNew.dot(d)) <= 0.9 * std::abs(slope))
                        accepted = true;
                }
            }
            if (accepted) break;
            t *= (ls < 2 ? 0.5 : 0.25);
        }
        if (!accepted) {
            if (manifold.active()) manifold.at(x);
            if (!mem.empty()) {  // drop the curvature history and retry along the steepest descent
                mem.clear();
                lastScale = 0.0;
                continue;
            }
            res.message = fmt::format("line search failed along the steepest-descent direction "
                                      "(gradient norm {:.3g}, energy round-off reached)", res.gradientNorm);
            break;
        }
        // y = grad L(xNew, lambdaNew) - grad L(x, lambdaNew): the Lagrangian's curvature.
        Pair p{xNew - x, gNew - g, 0.0, 0.0};
        Eigen::VectorXd pgNew = gNew;
        if (manifold.active()) {
            // The manifold state is at xNew (last retraction); Jx is J(x).
            const Eigen::VectorXd lambdaNew = manifold.multipliers(gNew);
            pgNew -= manifold.jacobian() * lambdaNew;
            p.y += (Jx - manifold.jacobian()) * lambdaNew;
            Jx = manifold.jacobian();
            lambda = lambdaNew;
        }
        remember(std::move(p));
        x.swap(xNew);
        g.swap(gNew);
        pg.swap(pgNew);
        fx = fNew;
    }
    res.energy = fx;
    res.gradientNorm = maxVertexNorm(pg);
    if (manifold.active()) {
        res.multipliers = lambda;
        res.constraintError = manifold.error();
    }
    if (res.gradientNorm <= opt.gradientTolerance) res.converged = true;
    if (res.converged)
        res.message = "converged";
    else if (res.message.empty())
        res.message = fmt::format("reached the iteration limit ({}) with gradient norm {:.3g} > {:.3g}",
                                  opt.maxIterations, res.gradientNorm, opt.gradientTolerance);
    return res;
}

EqualityConstraints areaVolumeConstraints(const Faces& faces, Eigen::Index nv, const AreaVolumeConstraint& target) {
    EqualityConstraints con;
    const bool area = target.area > 0, volume = target.volume > 0;
    const int m = int(area) + int(volume);
    con.scale.resize(m);
    if (area) con.scale[0] = target.area;
    if (volume) con.scale[m - 1] = target.volume;
    con.evaluate = [&faces, nv, target, area, volume, m](const Eigen::VectorXd& x, Eigen::VectorXd& c,
                                                         Eigen::MatrixXd& J) {
        const AreaVolume av = areaVolumeWithGradients(Eigen::Map<const Vertices>(x.data(), 3, nv), faces);
        c.resize(m);
        J.resize(3 * nv, m);
        if (area) {
            c[0] = av.area - target.area;
            J.col(0) = Eigen::Map<const Eigen::VectorXd>(av.areaGradient.data(), 3 * nv);
        }
        if (volume) {
            c[m - 1] = av.volume - target.volume;
            J.col(m - 1) = Eigen::Map<const Eigen::VectorXd>(av.volumeGradient.data(), 3 * nv);
        }
    };
    con.values = [&faces, nv, target, area, volume, m](const Eigen::VectorXd& x, Eigen::VectorXd& c) {
        const AreaVolume av = areaAndVolume(Eigen::Map<const Vertices>(x.data(), 3, nv), faces);
        c.resize(m);
        if (area) c[0] = av.area - target.area;
        if (volume) c[m - 1] = av.volume - target.volume;
    };
    return con;
}

double loadedEnergy(const MembraneModel& model, const Vertices& X, const Vertices* externalForces, Vertices& grad) {
    double u = model.evaluate(X, &grad);
    if (externalForces) {
        u -= (externalForces->array() * X.array()).sum();
        grad -= *externalForces;
    }
    return u;
}

MinimizeResult minimizeEnergy(const MembraneModel& model, Vertices& X, const MinimizeOptions& options,
                              const Vertices* externalForces, const AreaVolumeConstraint& constraint,
                              const Preconditioner* preconditioner, const std::vector<Eigen::Index>* inversionSymmetry) {
    const Eigen::Index nv = X.cols();
    if (inversionSymmetry && inversionSymmetry->size() != static_cast<size_t>(nv))
        throw std::invalid_argument(fmt::format("minimizeEnergy: {} inversion partners for {} vertices",
                                                inversionSymmetry->size(), nv));
    if (inversionSymmetry) symmetrizeUnderInversion(X, *inversionSymmetry);
    Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(X.data(), 3 * nv);
    Vertices Xv(3, nv), G(3, nv), W(3, nv);
    const Objective f = [&](const Eigen::VectorXd& xv, Eigen::VectorXd& g) {
        Xv = Eigen::Map<const Vertices>(xv.data(), 3, nv);
        const double u = loadedEnergy(model, Xv, externalForces, G);
        if (inversionSymmetry) symmetrizeUnderInversion(G, *inversionSymmetry);
        g = Eigen::Map<const Eigen::VectorXd>(G.data(), 3 * nv);
        return u;
    };
    // An H0 that is not exactly equivariant (a Gauss-Seidel smoother's ordering) must not leak
    // antisymmetric components into the directions.
    const auto symmetrized = [&](Eigen::VectorXd& v) {
        W = Eigen::Map<const Vertices>(v.data(), 3, nv);
        symmetrizeUnderInversion(W, *inversionSymmetry);
        v = Eigen::Map<const Eigen::VectorXd>(W.data(), 3 * nv);
    };
    Preconditioner symmetricH0;
    if (inversionSymmetry && preconditioner)
        symmetricH0 = [&](Eigen::VectorXd& v) {
            symmetrized(v);
            (*preconditioner)(v);
            symmetrized(v);
        };
    const Preconditioner* h0 = symmetricH0 ? &symmetricH0 : preconditioner;
    MinimizeResult r;
    if (constraint.active()) {
        const EqualityConstraints con = areaVolumeConstraints(model.faces(), nv, constraint);
        r = lbfgsMinimize(f, x, options, &con, h0);
    } else {
        r = lbfgsMinimize(f, x, options, nullptr, h0);
    }
    X = Eigen::Map<const Vertices>(x.data(), 3, nv);
    return r;
}

}  // namespace trbc
