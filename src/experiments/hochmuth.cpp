#include "experiments/hochmuth.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <cmath>

#include "core/error.hpp"

namespace trbc {

namespace {

// The law in the form (z - zInf)/(z + zInf) = q e^{-t/tc}, q = (z0 - zInf)/(z0 + zInf) = 1/Lambda:
//   z = zInf (1 + u)/(1 - u),  u = q e^{-t/tc}.
// It equals the Lambda form wherever that is defined and stays regular at zInf = z0 (q = 0).
double ratio(double z0, double zInf) { return (z0 - zInf) / (z0 + zInf); }

// Least squares in p = (s, zInf) with s = log tc. For tc > 0 this is a reparametrisation: the
// minimisers are those of the problem in (tc, zInf), only the path changes. It makes LM steps
// multiplicative in tc, so a start at 0.015 s reaches 2 s in a few steps instead of crawling
// (or jumping to tc < 0, where the law blows up instead of relaxing).
struct Problem {
    const std::vector<double>& tau;  // elapsed times t_k - t_0
    const std::vector<double>& z;
    double z0;

    /// Residuals m(t_k) - z_k and, when J is given, dm/ds and dm/dzInf.
    void evaluate(const Eigen::Vector2d& p, Eigen::VectorXd& r, Eigen::MatrixXd* J) const {
        const double tc = std::exp(p[0]), zInf = p[1];
        const double q = ratio(z0, zInf);
        const double dq = -2.0 * z0 / ((z0 + zInf) * (z0 + zInf));  // dq/dzInf
        const auto n = static_cast<Eigen::Index>(z.size());
        r.resize(n);
        if (J) J->resize(n, 2);
        for (Eigen::Index k = 0; k < n; ++k) {
            const double tk = tau[static_cast<std::size_t>(k)];
            const double e = std::exp(-tk / tc), u = q * e, w = 1.0 / (1.0 - u);
            r[k] = zInf * (1.0 + u) * w - z[static_cast<std::size_t>(k)];
            if (J) {
                const double dmdu = 2.0 * zInf * w * w;
                (*J)(k, 0) = dmdu * u * tk / tc;                  // du/ds = u t / tc
                (*J)(k, 1) = (1.0 + u) * w + dmdu * e * dq;     // du/dzInf = e dq/dzInf
            }
        }
    }
};

}  // namespace

double hochmuthLaw(double t, double z0, double zInf, double tc) {
    const double u = ratio(z0, zInf) * std::exp(-t / tc);
    return zInf * (1.0 + u) / (1.0 - u);
}

// Levenberg-Marquardt written out for the two unknowns rather than Eigen's unsupported MINPACK
// port: the log(tc) parametrisation, rejection of trial points with non-finite residuals and the
// converged/message reporting are then explicit, and the whole solver is a 2x2 solve per trial.
HochmuthFit fitHochmuth(const std::vector<double>& t, const std::vector<double>& z, double tcGuess,
                        double zInfGuess) {
    if (t.size() != z.size())
        throw InputError(fmt::format("fitHochmuth: {} times but {} deformation indices", t.size(), z.size()));
    if (t.size() < 3) throw InputError(fmt::format("fitHochmuth: {} samples, need at least 3", t.size()));
    for (std::size_t k = 0; k < t.size(); ++k) {
        if (!std::isfinite(t[k]) || !std::isfinite(z[k]))
            throw InputError(fmt::format("fitHochmuth: sample {} is not finite (t = {}, z = {})", k, t[k], z[k]));
        if (k > 0 && !(t[k] > t[k - 1]))
            throw InputError(fmt::format("fitHochmuth: times not strictly increasing at sample {} (t = {} after {})",
                                         k, t[k], t[k - 1]));
    }
    if (!(tcGuess > 0.0) || !std::isfinite(tcGuess))
        throw InputError(fmt::format("fitHochmuth: initial tc = {} must be positive and finite", tcGuess));
    if (!std::isfinite(zInfGuess) || zInfGuess == z[0] || zInfGuess == -z[0])
        throw InputError(fmt::format("fitHochmuth: initial zInf = {} must be finite and differ from +-z0 = +-{} "
                                     "(Lambda = (z0 + zInf)/(z0 - zInf) undefined or tc without effect)",
                                     zInfGuess, z[0]));

    std::vector<double> tau(t.size());
    for (std::size_t k = 0; k < t.size(); ++k) tau[k] = t[k] - t[0];
    const Problem problem{tau, z, z[0]};
    const auto n = static_cast<double>(z.size());

    HochmuthFit fit;
    fit.z0 = z[0];
    fit.t0 = t[0];
    Eigen::Vector2d p(std::log(tcGuess), zInfGuess);
    Eigen::VectorXd r, rTrial;
    Eigen::MatrixXd J;
    problem.evaluate(p, r, &J);
    if (!r.allFinite()) throw InputError("fitHochmuth: the law is not finite at the initial guess");
    double cost = 0.5 * r.squaredNorm();
    double lambda = 1e-3;
    const int maxIterations = 500;
    const double stepTol = 1e-12, gradTol = 1e-14;
    const double zScale = Eigen::Map<const Eigen::VectorXd>(z.data(), r.size()).cwiseAbs().maxCoeff();
    auto finish = [&](bool converged, std::string message) {
        // A stationary point where z(t_k) does not depend on tc (tc far below the first sample
        // interval, or zInf = z0) leaves tc undetermined: report it instead of an arbitrary value.
        if (converged && J.col(0).norm() <= 1e-8 * std::sqrt(n) * zScale) {
            converged = false;
            message = "tc is not determined by the data: the fitted law does not depend on it (" + message + ")";
        }
        fit.tc = std::exp(p[0]);
        fit.zInf = p[1];
        if (!std::isfinite(fit.tc)) {
            converged = false;
            message = "tc diverged to infinity: the data show no relaxation (" + message + ")";
        }
        fit.rms = std::sqrt(2.0 * cost / n);
        fit.converged = converged;
        fit.message = std::move(message);
        return fit;
    };

    for (fit.iterations = 1; fit.iterations <= maxIterations; ++fit.iterations) {
        const Eigen::Matrix2d H = J.transpose() * J;
        const Eigen::Vector2d g = J.transpose() * r;
        // Scale-free stationarity: cosine between r and each Jacobian column (MINPACK's gtol).
        const double rNorm = r.norm();
        if (rNorm == 0.0 ||
            (std::abs(g[0]) <= gradTol * rNorm * std::sqrt(H(0, 0)) &&
             std::abs(g[1]) <= gradTol * rNorm * std::sqrt(H(1, 1))))
            return finish(true, "gradient orthogonal to the residual");
        const Eigen::Vector2d d = H.diagonal().cwiseMax(1e-12 * H.trace());  // Marquardt scaling
        bool accepted = false;
        Eigen::Vector2d step;
        while (lambda < 1e16) {
            Eigen::Matrix2d A = H;
            A.diagonal() += lambda * d;
            step = -A.ldlt().solve(g);
            const Eigen::Vector2d trial = p + step;
            if (step.allFinite() && trial.allFinite()) {
                problem.evaluate(trial, rTrial, nullptr);
                const double trialCost = 0.5 * rTrial.squaredNorm();
                if (rTrial.allFinite() && trialCost < cost) {
                    p = trial;
                    cost = trialCost;
                    accepted = true;
                    lambda = std::max(lambda / 3.0, 1e-12);
                    break;
                }
            }
            lambda *= 10.0;
        }
        if (!accepted) {
            // No damped step decreases the cost: either the fit is exact up to round-off, or the
            // Gauss-Newton model promises less than the cost's own round-off (a minimum), or a stall.
            if (std::sqrt(2.0 * cost / n) <= 1e-12 * zScale) return finish(true, "exact fit (round-off level)");
            const double predicted = 0.5 * g.dot(H.ldlt().solve(g));  // Gauss-Newton decrease
            if (predicted <= 1e-10 * cost) return finish(true, "no further decrease (round-off level)");
            return finish(false, fmt::format("Levenberg-Marquardt stalled: no damped step decreases the residual "
                                             "(Gauss-Newton predicts a decrease of {:.3g} of {:.3g})",
                                             predicted, cost));
        }
        problem.evaluate(p, r, &J);
        if (std::abs(ratio(z[0], p[1])) < 1e-12)
            return finish(false, "zInf reached z0: the data do not relax and tc is undetermined");
        if (std::abs(step[0]) <= stepTol && std::abs(step[1]) <= stepTol * (1.0 + std::abs(p[1])))
            return finish(true, "step below tolerance");
    }
    fit.iterations = maxIterations;
    return finish(false, fmt::format("no convergence in {} Levenberg-Marquardt iterations", maxIterations));
}

}  // namespace trbc
