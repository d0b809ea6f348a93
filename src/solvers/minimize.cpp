#include "solvers/minimize.hpp"

#include <fmt/format.h>

#include <cmath>
#include <deque>
#include <limits>

namespace trbc {

double maxVertexNorm(const Eigen::VectorXd& g) {
    const Eigen::Map<const Eigen::Matrix3Xd> G(g.data(), 3, g.size() / 3);
    return G.colwise().norm().maxCoeff();
}

namespace {

struct Pair {
    Eigen::VectorXd s, y;
    double rho;
};

// Two-loop recursion: d = -H g.
Eigen::VectorXd lbfgsDirection(const std::deque<Pair>& mem, const Eigen::VectorXd& g) {
    Eigen::VectorXd q = -g;
    std::vector<double> alpha(mem.size());
    for (int k = static_cast<int>(mem.size()) - 1; k >= 0; --k) {
        alpha[k] = mem[k].rho * mem[k].s.dot(q);
        q -= alpha[k] * mem[k].y;
    }
    if (!mem.empty()) {
        const auto& last = mem.back();
        q *= last.s.dot(last.y) / last.y.squaredNorm();
    }
    for (std::size_t k = 0; k < mem.size(); ++k) {
        const double beta = mem[k].rho * mem[k].y.dot(q);
        q += (alpha[k] - beta) * mem[k].s;
    }
    return q;
}

}  // namespace

MinimizeResult lbfgsMinimize(const Objective& f, Eigen::VectorXd& x, const MinimizeOptions& opt) {
    MinimizeResult res;
    const Eigen::Index n = x.size();
    Eigen::VectorXd g(n), gNew(n), xNew(n);
    double fx = f(x, g);
    ++res.evaluations;
    if (!std::isfinite(fx) || !g.allFinite()) {
        res.message = "objective is not finite at the starting point";
        res.energy = fx;
        return res;
    }
    std::deque<Pair> mem;
    constexpr double c1 = 1e-4;
    constexpr double eps = std::numeric_limits<double>::epsilon();
    int roundoffStalls = 0;

    for (res.iterations = 0; res.iterations < opt.maxIterations; ++res.iterations) {
        res.gradientNorm = maxVertexNorm(g);
        if (res.gradientNorm <= opt.gradientTolerance) {
            res.converged = true;
            break;
        }
        Eigen::VectorXd d = lbfgsDirection(mem, g);
        double slope = g.dot(d);
        if (!(slope < 0)) {  // not a descent direction: restart from steepest descent
            mem.clear();
            d = -g;
            slope = -g.squaredNorm();
        }
        double t = 1.0;
        if (mem.empty()) t = std::min(1.0, 1.0 / std::sqrt(g.squaredNorm()));  // first step or restart
        if (opt.maxVertexStep > 0) {
            const double dm = maxVertexNorm(d);
            if (t * dm > opt.maxVertexStep) t = opt.maxVertexStep / dm;
        }

        // Backtracking with Armijo; where energy differences are at round-off level the
        // directional derivative decides (the gradient stays accurate when the energy does not).
        bool accepted = false;
        double fNew = fx;
        for (int ls = 0; ls < 40; ++ls) {
            xNew = x + t * d;
            fNew = f(xNew, gNew);
            ++res.evaluations;
            if (std::isfinite(fNew) && gNew.allFinite()) {
                const double noise = 100.0 * eps * std::abs(fx);
                if (fNew <= fx + c1 * t * slope) {
                    accepted = true;
                } else if (std::abs(fNew - fx) <= noise && std::abs(gNew.dot(d)) <= 0.9 * std::abs(slope)) {
                    accepted = true;
                    ++roundoffStalls;
                }
            }
            if (accepted) break;
            t *= (ls < 2 ? 0.5 : 0.25);
        }
        if (!accepted) {
            if (!mem.empty()) {  // drop the curvature history and retry along -g
                mem.clear();
                continue;
            }
            res.message = fmt::format("line search failed along the steepest-descent direction "
                                      "(gradient norm {:.3g}, energy round-off reached)", res.gradientNorm);
            break;
        }
        Pair p{xNew - x, gNew - g, 0.0};
        const double sy = p.s.dot(p.y);
        if (sy > 1e-12 * p.s.norm() * p.y.norm()) {
            p.rho = 1.0 / sy;
            mem.push_back(std::move(p));
            if (static_cast<int>(mem.size()) > opt.memory) mem.pop_front();
        }
        x.swap(xNew);
        g.swap(gNew);
        fx = fNew;
    }
    res.energy = fx;
    res.gradientNorm = maxVertexNorm(g);
    if (res.gradientNorm <= opt.gradientTolerance) res.converged = true;
    if (res.converged)
        res.message = "converged";
    else if (res.message.empty())
        res.message = fmt::format("reached the iteration limit ({}) with gradient norm {:.3g} > {:.3g}",
                                  opt.maxIterations, res.gradientNorm, opt.gradientTolerance);
    return res;
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
                              const Vertices* externalForces) {
    const Eigen::Index nv = X.cols();
    Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(X.data(), 3 * nv);
    Vertices Xv(3, nv), G(3, nv);
    const Objective f = [&](const Eigen::VectorXd& xv, Eigen::VectorXd& g) {
        Xv = Eigen::Map<const Vertices>(xv.data(), 3, nv);
        const double u = loadedEnergy(model, Xv, externalForces, G);
        g = Eigen::Map<const Eigen::VectorXd>(G.data(), 3 * nv);
        return u;
    };
    MinimizeResult r = lbfgsMinimize(f, x, options);
    X = Eigen::Map<const Vertices>(x.data(), 3, nv);
    return r;
}

}  // namespace trbc
