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

// The L-BFGS correction pairs (s, y), the newest `memory` of them, and the scale of H0.
class PairMemory {
public:
    PairMemory(const MinimizeOptions& opt, const Preconditioner* pre) : opt_(opt), pre_(pre) {}
    bool empty() const { return pairs_.empty(); }
    void clear() {
        pairs_.clear();
        lastScale_ = 0.0;
    }
    void remember(Pair p);
    Eigen::VectorXd direction(const Eigen::VectorXd& g) const;

private:
    const MinimizeOptions& opt_;
    const Preconditioner* pre_;
    std::deque<Pair> pairs_;
    double lastScale_ = 0.0;  // y.H0 y / s.y of the last pair that applied the preconditioner
    int pairsSinceScale_ = 0;
};

// Adds a pair if its curvature s.y is positive (keeps the L-BFGS matrix positive definite).
void PairMemory::remember(Pair p) {
    const double sy = p.s.dot(p.y);
    if (!(sy > 1e-12 * p.s.norm() * p.y.norm())) return;
    p.rho = 1.0 / sy;
    if (pre_ && !opt_.scalePreconditioner) {
        p.yHy = sy;  // unit scale: rho * yHy = 1 in the two-loop recursion
    } else if (pre_ && lastScale_ > 0 && ++pairsSinceScale_ < opt_.preconditionerScaleInterval) {
        p.yHy = sy * lastScale_;
    } else if (pre_) {
        Eigen::VectorXd hy = p.y;
        (*pre_)(hy);
        p.yHy = p.y.dot(hy);
        lastScale_ = p.yHy / sy;
        pairsSinceScale_ = 0;
    } else {
        p.yHy = p.y.squaredNorm();
    }
    pairs_.push_back(std::move(p));
    if (static_cast<int>(pairs_.size()) > opt_.memory) pairs_.pop_front();
}

// Two-loop recursion: d = -H g, H0 = (s.y / y.H0 y) P from the newest pair (P = I without a
// preconditioner).
Eigen::VectorXd PairMemory::direction(const Eigen::VectorXd& g) const {
    Eigen::VectorXd q = -g;
    std::vector<double> alpha(pairs_.size());
    for (int k = static_cast<int>(pairs_.size()) - 1; k >= 0; --k) {
        alpha[k] = pairs_[k].rho * pairs_[k].s.dot(q);
        q -= alpha[k] * pairs_[k].y;
    }
    if (pre_) (*pre_)(q);
    if (!pairs_.empty()) {
        const auto& last = pairs_.back();
        q *= 1.0 / (last.rho * last.yHy);
    }
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const double beta = pairs_[k].rho * pairs_[k].y.dot(q);
        q += (alpha[k] - beta) * pairs_[k].s;
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

// The starting point: projected onto the constraints, f and its gradient g evaluated there.
// Sets the message of `res` and returns false when the point is unusable.
bool startingPoint(const Objective& f, Manifold& manifold, Eigen::VectorXd& x, Eigen::VectorXd& g, double& fx,
                   MinimizeResult& res) {
    if (manifold.active() && !manifold.retract(x)) {
        res.message = "the starting point cannot be projected onto the constraints";
        return false;
    }
    fx = f(x, g);
    ++res.evaluations;
    if (!std::isfinite(fx) || !g.allFinite()) {
        res.message = "objective is not finite at the starting point";
        res.energy = fx;
        return false;
    }
    return true;
}

// The L-BFGS direction projected onto the tangent space, or -pg where that is not a descent
// direction (the curvature history is then dropped); writes the slope pg.d.
Eigen::VectorXd descentDirection(PairMemory& mem, const Manifold& manifold, const Eigen::VectorXd& pg,
                                 double& slope) {
    Eigen::VectorXd d = mem.direction(pg);
    if (manifold.active()) manifold.project(d);
    slope = pg.dot(d);
    if (!(slope < 0)) {  // not a descent direction: restart from steepest descent
        mem.clear();
        d = -pg;
        slope = -pg.squaredNorm();
    }
    return d;
}

// t = 1, or min(1, 1 / |pg|) on the first step or after a restart without a preconditioner, cut to
// t |d_i| <= maxVertexStep for every vertex i.
double firstTrialStep(bool unscaled, const Eigen::VectorXd& pg, const Eigen::VectorXd& d, double maxVertexStep) {
    double t = 1.0;
    if (unscaled) t = std::min(1.0, 1.0 / pg.norm());
    if (maxVertexStep > 0) {
        const double dm = maxVertexNorm(d);
        if (t * dm > maxVertexStep) t = maxVertexStep / dm;
    }
    return t;
}

struct LineSearchResult {
    bool accepted = false;
    double energy = 0.0;  ///< f at the last evaluated trial point (f(x) if none was evaluated)
};

// Backtracking with Armijo; where energy differences are at round-off level the
// directional derivative decides (the gradient stays accurate when the energy does not).
// Constrained: the trial point is retracted onto the manifold first (the manifold state
// then belongs to the trial point). xNew and gNew hold the last trial point and its gradient.
LineSearchResult armijoLineSearch(const Objective& f, Manifold& manifold, const Eigen::VectorXd& lambda,
                                  const Eigen::VectorXd& x, double fx, const Eigen::VectorXd& d, double slope,
                                  double t, Eigen::VectorXd& xNew, Eigen::VectorXd& gNew, int& evaluations) {
    constexpr double c1 = 1e-4;
    constexpr double eps = std::numeric_limits<double>::epsilon();
    bool accepted = false;
    double fNew = fx;
    const double merit = manifold.active() ? fx - lambda.dot(manifold.values()) : fx;
    for (int ls = 0; ls < 40; ++ls) {
        xNew = x + t * d;
        if (!manifold.active() || manifold.retract(xNew)) {
            fNew = f(xNew, gNew);
            ++evaluations;
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
    return {accepted, fNew};
}

// The pair (s, y) of an accepted step x -> xNew, with y = grad L(xNew, lambdaNew) - grad L(x, lambdaNew):
// the Lagrangian's curvature. Writes pgNew, the tangent component of gNew; Jx and lambda move on to xNew.
Pair curvaturePair(const Manifold& manifold, const Eigen::VectorXd& x, const Eigen::VectorXd& xNew,
                   const Eigen::VectorXd& g, const Eigen::VectorXd& gNew, Eigen::MatrixXd& Jx,
                   Eigen::VectorXd& lambda, Eigen::VectorXd& pgNew) {
    Pair p{xNew - x, gNew - g, 0.0, 0.0};
    pgNew = gNew;
    if (manifold.active()) {
        // The manifold state is at xNew (last retraction); Jx is J(x).
        const Eigen::VectorXd lambdaNew = manifold.multipliers(gNew);
        pgNew -= manifold.jacobian() * lambdaNew;
        p.y += (Jx - manifold.jacobian()) * lambdaNew;
        Jx = manifold.jacobian();
        lambda = lambdaNew;
    }
    return p;
}

// Energy, gradient norm, multipliers, constraint error and message at the returned point.
void finishResult(MinimizeResult& res, double fx, const Eigen::VectorXd& pg, const Manifold& manifold,
                  const Eigen::VectorXd& lambda, const MinimizeOptions& opt) {
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
}

}  // namespace

MinimizeResult lbfgsMinimize(const Objective& f, Eigen::VectorXd& x, const MinimizeOptions& opt,
                             const EqualityConstraints* constraints, const Preconditioner* pre) {
    MinimizeResult res;
    const Eigen::Index n = x.size();
    Manifold manifold(constraints);
    Eigen::VectorXd g(n), gNew(n), xNew(n), lambda;
    double fx = 0.0;
    if (!startingPoint(f, manifold, x, g, fx, res)) return res;
    // pg: gradient of the Lagrangian f - lambda.c, i.e. the tangent component of g.
    Eigen::VectorXd pg = g;
    Eigen::MatrixXd Jx;
    if (manifold.active()) {
        Jx = manifold.jacobian();
        lambda = manifold.multipliers(g);
        pg -= manifold.jacobian() * lambda;
    }
    PairMemory mem(opt, pre);
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
        double slope = 0.0;
        const Eigen::VectorXd d = descentDirection(mem, manifold, pg, slope);
        const double t = firstTrialStep(mem.empty() && !pre, pg, d, opt.maxVertexStep);
        const LineSearchResult step =
            armijoLineSearch(f, manifold, lambda, x, fx, d, slope, t, xNew, gNew, res.evaluations);
        if (!step.accepted) {
            if (manifold.active()) manifold.at(x);
            if (!mem.empty()) {  // drop the curvature history and retry along the steepest descent
                mem.clear();
                continue;
            }
            res.message = fmt::format("line search failed along the steepest-descent direction "
                                      "(gradient norm {:.3g}, energy round-off reached)", res.gradientNorm);
            break;
        }
        Eigen::VectorXd pgNew;
        mem.remember(curvaturePair(manifold, x, xNew, g, gNew, Jx, lambda, pgNew));
        x.swap(xNew);
        g.swap(gNew);
        pg.swap(pgNew);
        fx = step.energy;
    }
    finishResult(res, fx, pg, manifold, lambda, opt);
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
