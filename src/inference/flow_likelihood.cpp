#include "inference/flow_likelihood.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <numbers>

#include "core/error.hpp"
#include "inference/rbc_problem.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
const double kLog2Pi = std::log(2.0 * std::numbers::pi);

bool onLogScale(FlowObservable o) { return o != FlowObservable::Inclination; }

/// The model's value of a point on the observable's scale (the logarithm for TTF and stresses).
double scaled(FlowObservable o, double y) { return onLogScale(o) ? std::log(y) : y; }

Eigen::Index countPoints(const FlowDataSet& d) {
    Eigen::Index m = 0;
    for (const FlowCurve& c : d.curves) {
        const bool stresses = d.observable == FlowObservable::CriticalStress;
        if (!stresses && c.rate.size() != c.value.size())
            throw InputError(fmt::format("flow data set '{}': a curve at {} mPa s has {} rates and {} values", d.name,
                                         c.etaOutMPaS, c.rate.size(), c.value.size()));
        if (onLogScale(d.observable) && !(c.value.array() > 0.0).all())
            throw InputError(fmt::format("flow data set '{}': a {} at {} mPa s is not > 0 (compared on the log scale)", d.name,
                                         flowObservableName(d.observable), c.etaOutMPaS));
        m += c.value.size();
    }
    if (m == 0) throw InputError(fmt::format("flow data set '{}' has no points", d.name));
    return m;
}

}  // namespace

const char* flowObservableName(FlowObservable o) {
    switch (o) {
        case FlowObservable::Inclination: return "inclination_deg";
        case FlowObservable::Ttf: return "ttf_4pi_f_over_rate";
        case FlowObservable::CriticalStress: return "critical_stress_Pa";
    }
    return "?";
}

FlowModel surrogateFlowModel(std::shared_ptr<const FlowSurrogate> s) {
    FlowModel m;
    m.tankTreading = [s](const Eigen::MatrixXd& x, const Eigen::VectorXd& etaIn) {
        const FlowPrediction p = s->predict(x, etaIn);
        Eigen::MatrixXd y(3, x.cols());
        y.row(0) = p.pTankTreading.transpose();
        y.row(1) = p.inclinationDeg.transpose();
        y.row(2) = p.ttf.transpose();
        return y;
    };
    m.criticalStressPa = [s](const Eigen::MatrixXd& x, const Eigen::VectorXd& etaIn) {
        return s->criticalStressPa(x, etaIn, 0.5, true);
    };
    return m;
}

double offsetNormalLogPdf(const Eigen::Ref<const Eigen::VectorXd>& r, double sigma, double offsetSd) {
    if (!(sigma > 0.0)) return -kInf;
    const double n = static_cast<double>(r.size()), s2 = sigma * sigma, o2 = offsetSd * offsetSd;
    // Sum r^2 - s^2 (sum r)^2 / c = sum (r - rbar)^2 + n rbar^2 sigma^2 / c: the centred form does not
    // cancel when n s^2 >> sigma^2.
    const double c = s2 + n * o2, mean = r.mean();
    const double quadratic = (r.array() - mean).square().sum() / s2 + n * mean * mean / c;
    const double logDet = (n - 1.0) * std::log(s2) + std::log(c);
    return -0.5 * (quadratic + logDet + n * kLog2Pi);
}

const std::vector<std::string>& flowParameterNames() {
    static const std::vector<std::string> names{"v", "mu", "kb", "b2", "r", "sigma"};
    return names;
}

Eigen::VectorXd flowLogLikelihood(const FlowModel& model, const FlowDataSet& d, const Eigen::MatrixXd& cells) {
    if (cells.rows() != 6)
        throw InputError(fmt::format("flow data set '{}': {} cell variables, expected 6 ({})", d.name, cells.rows(),
                                     fmt::join(flowParameterNames(), ", ")));
    if (!(d.regimeErrorRate >= 0.0 && d.regimeErrorRate <= 0.5) || !(d.modelErrorSd >= 0.0))
        throw InputError(fmt::format("flow data set '{}': the regime error rate must lie in [0, 0.5] and the model "
                                     "error be >= 0 (got {}, {})", d.name, d.regimeErrorRate, d.modelErrorSd));
    const Eigen::Index n = cells.cols(), m = countPoints(d);
    const bool stresses = d.observable == FlowObservable::CriticalStress;
    // A critical stress depends on the cell and eta_out only: one column per curve, not per point.
    const Eigen::Index columns = stresses ? static_cast<Eigen::Index>(d.curves.size()) : m;
    // Cells outside the networks' eta_m range have likelihood 0 and are not evaluated: cell i's
    // columns start at slot[i] * columns, slot -1 for those.
    std::vector<Eigen::Index> slot(static_cast<std::size_t>(n), -1);
    Eigen::Index evaluated = 0;
    for (Eigen::Index i = 0; i < n; ++i) {
        const double etam = cells(1, i) * cells(4, i);
        if (etam >= d.etamRange[0] && etam <= d.etamRange[1]) slot[static_cast<std::size_t>(i)] = evaluated++;
    }
    Eigen::MatrixXd x(7, evaluated * columns);
    for (Eigen::Index i = 0; i < n; ++i) {
        if (slot[static_cast<std::size_t>(i)] < 0) continue;
        const double v = cells(0, i), mu = cells(1, i), kb = cells(2, i), b2 = cells(3, i), r = cells(4, i);
        Eigen::Index k = slot[static_cast<std::size_t>(i)] * columns;
        for (const FlowCurve& c : d.curves) {
            // eta_m = mu r; a critical stress's rate is not read by the model: the rate of 1 Pa.
            if (stresses) x.col(k++) << v, mu, fvkFromModuli(mu, kb), b2, mu * r, c.etaOutMPaS, 1e3 / c.etaOutMPaS;
            else
                for (Eigen::Index p = 0; p < c.value.size(); ++p)
                    x.col(k++) << v, mu, fvkFromModuli(mu, kb), b2, mu * r, c.etaOutMPaS, c.rate[p];
        }
    }
    const Eigen::VectorXd etaIn = Eigen::VectorXd::Constant(x.cols(), d.etaInMPaS);
    Eigen::MatrixXd tt;
    Eigen::VectorXd tau;
    if (x.cols() > 0) {
        if (stresses) tau = model.criticalStressPa(x, etaIn);
        else tt = model.tankTreading(x, etaIn);
    }
    const Eigen::Index valueRow = d.observable == FlowObservable::Inclination ? 1 : 2;
    const double e = d.regimeErrorRate;

    Eigen::VectorXd ll(n);
    for (Eigen::Index i = 0; i < n; ++i) {
        if (slot[static_cast<std::size_t>(i)] < 0) {
            ll[i] = -kInf;
            continue;
        }
        const double sigma = cells(5, i);
        double s = 0.0;
        Eigen::Index k = slot[static_cast<std::size_t>(i)] * columns;
        for (const FlowCurve& c : d.curves) {
            Eigen::VectorXd residual(c.value.size());
            if (stresses) {
                residual = c.value.array().log() - std::log(tau[k++]);
            } else {
                double pLeast = 1.0;  // the curve's point the classifier finds least likely to tank-tread
                for (Eigen::Index p = 0; p < c.value.size(); ++p, ++k) {
                    residual[p] = scaled(d.observable, c.value[p]) - scaled(d.observable, tt(valueRow, k));
                    pLeast = std::min(pLeast, std::clamp(tt(0, k), 0.0, 1.0));
                }
                s += std::log(e + (1.0 - 2.0 * e) * pLeast);
            }
            s += offsetNormalLogPdf(residual, sigma, d.modelErrorSd);
        }
        ll[i] = std::isnan(s) ? -kInf : s;
    }
    return ll;
}

}  // namespace trbc
