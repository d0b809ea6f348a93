#include "inference/priors.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include "core/error.hpp"

namespace trbc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
void requireFinite(const char* prior, const char* name, double value) {
    if (!std::isfinite(value))
        throw InputError(fmt::format("{} prior: {} = {} is invalid: must be finite", prior, name, value));
}

void requireOrdered(const char* prior, const char* loName, double lo, const char* hiName, double hi) {
    if (std::isnan(lo) || std::isnan(hi) || !(lo < hi))
        throw InputError(fmt::format("{} prior: bounds {} = {}, {} = {} are invalid: need {} < {}", prior,
                                     loName, lo, hiName, hi, loName, hiName));
}

}  // namespace


// ------------------------------------------------------------------------------------------------
// Normal-distribution helpers

double normalPdf(double x) { return std::exp(-0.5 * x * x) / std::sqrt(2.0 * std::numbers::pi); }

double normalCdf(double x) { return 0.5 * std::erfc(-x / std::numbers::sqrt2); }

double normalQuantile(double p) {
    if (!(p > 0.0 && p < 1.0)) {
        if (p == 0.0) return -kInf;
        if (p == 1.0) return kInf;
        throw InputError(fmt::format("normalQuantile: p = {} is invalid: must be in [0, 1]", p));
    }
    if (p > 0.5) return -normalQuantile(1.0 - p);
    // Abramowitz & Stegun 26.2.23 (|error| < 4.5e-4) for the lower tail ...
    const double t = std::sqrt(-2.0 * std::log(p));
    double x = -(t - (2.515517 + t * (0.802853 + t * 0.010328)) / (1.0 + t * (1.432788 + t * (0.189269 + t * 0.001308))));
    // ... refined by Halley's method on Phi(x) - p (cubic convergence: 3 steps reach round-off).
    for (int it = 0; it < 3; ++it) {
        const double e = normalCdf(x) - p;
        const double u = e * std::sqrt(2.0 * std::numbers::pi) * std::exp(0.5 * x * x);
        x -= u / (1.0 + 0.5 * x * u);
    }
    return x;
}

double logNormalMass(double alpha, double beta) {
    if (alpha > 0.0) return std::log(normalCdf(-alpha) - normalCdf(-beta));  // both in the upper tail
    if (beta < 0.0) return std::log(normalCdf(beta) - normalCdf(alpha));     // both in the lower tail
    return std::log1p(-(normalCdf(alpha) + normalCdf(-beta)));               // straddles 0
}

double truncatedStandardNormal(double alpha, double beta, Rng& rng) {
    if (alpha > 0.0) return -truncatedStandardNormal(-beta, -alpha, rng);  // invert in the lower tail
    const double pa = normalCdf(alpha), pb = normalCdf(beta);
    const double u = pa + (pb - pa) * rng.uniformOpen();
    return std::clamp(normalQuantile(u), alpha, beta);
}

// ------------------------------------------------------------------------------------------------
// One-dimensional priors

namespace {

class UniformPrior final : public ScalarPrior {
public:
    UniformPrior(double a, double b) : a_(a), b_(b), logDensity_(-std::log(b - a)) {}
    double logDensity(double x) const override { return (x >= a_ && x <= b_) ? logDensity_ : -kInf; }
    double sample(Rng& rng) const override { return a_ + (b_ - a_) * rng.uniform(); }
    double lower() const override { return a_; }
    double upper() const override { return b_; }
    std::string describe() const override { return fmt::format("U[{}, {}]", a_, b_); }

private:
    double a_, b_, logDensity_;
};

/// N(m, s^2) truncated to [lo, hi] (possibly infinite bounds).
class NormalPrior final : public ScalarPrior {
public:
    NormalPrior(double m, double s, double lo, double hi)
        : m_(m), s_(s), lo_(lo), hi_(hi), truncated_(std::isfinite(lo) || std::isfinite(hi)) {
        logNorm_ = std::log(s * std::sqrt(2.0 * std::numbers::pi)) + (truncated_ ? logNormalMass(alpha(), beta()) : 0.0);
        if (!std::isfinite(logNorm_))
            throw InputError(fmt::format("normal prior N({}, {}^2) on [{}, {}]: the interval holds no "
                                         "probability mass in double precision", m, s, lo, hi));
    }
    double logDensity(double x) const override {
        if (!(x >= lo_ && x <= hi_)) return -kInf;
        const double z = (x - m_) / s_;
        return -0.5 * z * z - logNorm_;
    }
    double sample(Rng& rng) const override {
        if (!truncated_) return m_ + s_ * rng.normal();
        return std::clamp(m_ + s_ * truncatedStandardNormal(alpha(), beta(), rng), lo_, hi_);
    }
    double lower() const override { return lo_; }
    double upper() const override { return hi_; }
    std::string describe() const override {
        return truncated_ ? fmt::format("N({}, {}^2) on [{}, {}]", m_, s_, lo_, hi_) : fmt::format("N({}, {}^2)", m_, s_);
    }

private:
    double alpha() const { return (lo_ - m_) / s_; }
    double beta() const { return (hi_ - m_) / s_; }
    double m_, s_, lo_, hi_;
    bool truncated_;
    double logNorm_ = 0.0;
};

/// log X ~ N(m, s^2), X truncated to [lo, hi].
class LogNormalPrior final : public ScalarPrior {
public:
    LogNormalPrior(double m, double s, double lo, double hi)
        : lo_(lo), hi_(hi), logPrior_(m, s, lo > 0.0 ? std::log(lo) : -kInf, std::isfinite(hi) ? std::log(hi) : kInf) {}
    double logDensity(double x) const override {
        if (!(x >= lo_ && x <= hi_) || !(x > 0.0)) return -kInf;
        const double y = std::log(x);
        return logPrior_.logDensity(y) - y;  // change of variables: p(x) = p_log(log x) / x
    }
    double sample(Rng& rng) const override { return std::clamp(std::exp(logPrior_.sample(rng)), lo_, hi_); }
    double lower() const override { return lo_; }
    double upper() const override { return hi_; }
    std::string describe() const override { return "log" + logPrior_.describe() + " (of log x)"; }

private:
    double lo_, hi_;
    NormalPrior logPrior_;
};

class RatioUniformPrior final : public ScalarPrior {
public:
    RatioUniformPrior(double a, double b, double c, double e)
        : a_(a), b_(b), c_(c), e_(e), logNorm_(std::log(2.0 * (b - a) * (e - c))) {}
    double logDensity(double z) const override {
        if (!(z >= lower() && z <= upper())) return -kInf;
        const double hi = std::min(e_, b_ / z), lo = std::max(c_, a_ / z);
        const double numerator = hi * hi - lo * lo;  // docs/BAYESIAN_INFERENCE.md
        return numerator > 0.0 ? std::log(numerator) - logNorm_ : -kInf;
    }
    double sample(Rng& rng) const override {
        const double x = a_ + (b_ - a_) * rng.uniform();
        const double y = c_ + (e_ - c_) * rng.uniformOpen();
        return std::clamp(x / y, lower(), upper());
    }
    double lower() const override { return a_ / e_; }
    double upper() const override { return b_ / c_; }
    std::string describe() const override {
        return fmt::format("ratio-uniform U[{}, {}] / U[{}, {}]", a_, b_, c_, e_);
    }

private:
    double a_, b_, c_, e_, logNorm_;
};

class CustomScalarPrior final : public ScalarPrior {
public:
    CustomScalarPrior(double lo, double hi, std::function<double(Rng&)> sampler, std::function<double(double)> logDensity,
                      std::string name)
        : lo_(lo), hi_(hi), sampler_(std::move(sampler)), logDensity_(std::move(logDensity)), name_(std::move(name)) {}
    double logDensity(double x) const override { return (x >= lo_ && x <= hi_) ? logDensity_(x) : -kInf; }
    double sample(Rng& rng) const override { return sampler_(rng); }
    double lower() const override { return lo_; }
    double upper() const override { return hi_; }
    std::string describe() const override { return fmt::format("{} on [{}, {}]", name_, lo_, hi_); }

private:
    double lo_, hi_;
    std::function<double(Rng&)> sampler_;
    std::function<double(double)> logDensity_;
    std::string name_;
};

}  // namespace

ScalarPriorPtr uniformPrior(double a, double b) {
    requireFinite("uniform", "a", a);
    requireFinite("uniform", "b", b);
    requireOrdered("uniform", "a", a, "b", b);
    return std::make_shared<UniformPrior>(a, b);
}

ScalarPriorPtr normalPrior(double mean, double sd, double lo, double hi) {
    requireFinite("normal", "mean", mean);
    if (!(sd > 0.0 && std::isfinite(sd)))
        throw InputError(fmt::format("normal prior: sd = {} is invalid: must be > 0 and finite", sd));
    requireOrdered("normal", "lo", lo, "hi", hi);
    return std::make_shared<NormalPrior>(mean, sd, lo, hi);
}

ScalarPriorPtr logNormalPrior(double meanLog, double sdLog, double lo, double hi) {
    requireFinite("log-normal", "meanLog", meanLog);
    if (!(sdLog > 0.0 && std::isfinite(sdLog)))
        throw InputError(fmt::format("log-normal prior: sdLog = {} is invalid: must be > 0 and finite", sdLog));
    if (!(lo >= 0.0)) throw InputError(fmt::format("log-normal prior: lo = {} is invalid: must be >= 0", lo));
    requireOrdered("log-normal", "lo", lo, "hi", hi);
    return std::make_shared<LogNormalPrior>(meanLog, sdLog, lo, hi);
}

ScalarPriorPtr ratioUniformPrior(double a, double b, double c, double e) {
    for (auto [name, v] : {std::pair{"a", a}, {"b", b}, {"c", c}, {"e", e}}) requireFinite("ratio-uniform", name, v);
    if (!(a > 0.0 && a < b) || !(c > 0.0 && c < e))
        throw InputError(fmt::format("ratio-uniform prior: (a, b, c, e) = ({}, {}, {}, {}) is invalid: need "
                                     "0 < a < b and 0 < c < e", a, b, c, e));
    return std::make_shared<RatioUniformPrior>(a, b, c, e);
}

ScalarPriorPtr customScalarPrior(double lo, double hi, std::function<double(Rng&)> sampler,
                                 std::function<double(double)> logDensity, std::string name) {
    requireOrdered("custom", "lo", lo, "hi", hi);
    if (!sampler || !logDensity)
        throw InputError("custom prior: both the sampler and the log-density callback must be given");
    return std::make_shared<CustomScalarPrior>(lo, hi, std::move(sampler), std::move(logDensity), std::move(name));
}

double ratioUniformMean(double a, double b, double c, double e) {
    return 0.5 * (a + b) * std::log(e / c) / (e - c);  // E X * E[1/Y]
}

double ratioUniformSecondMoment(double a, double b, double c, double e) {
    return (a * a + a * b + b * b) / 3.0 / (c * e);  // E X^2 * E[1/Y^2]
}

// ------------------------------------------------------------------------------------------------
// Multivariate priors

ProductPrior::ProductPrior(std::vector<ScalarPriorPtr> components) : components_(std::move(components)) {
    if (components_.empty()) throw InputError("product prior: needs at least one component (dimension >= 1)");
    for (std::size_t i = 0; i < components_.size(); ++i)
        if (!components_[i]) throw InputError(fmt::format("product prior: component {} is null", i));
}

double ProductPrior::logDensity(const Eigen::VectorXd& theta) const {
    if (theta.size() != dimension())
        throw InputError(fmt::format("product prior: theta has {} coordinates, the prior has {}", theta.size(), dimension()));
    double sum = 0.0;
    for (int i = 0; i < dimension(); ++i) {
        const double li = components_[static_cast<std::size_t>(i)]->logDensity(theta[i]);
        if (li == -kInf) return -kInf;
        sum += li;
    }
    return sum;
}

Eigen::VectorXd ProductPrior::sample(Rng& rng) const {
    Eigen::VectorXd theta(dimension());
    for (int i = 0; i < dimension(); ++i) theta[i] = components_[static_cast<std::size_t>(i)]->sample(rng);
    return theta;
}

Eigen::VectorXd ProductPrior::lowerBounds() const {
    Eigen::VectorXd v(dimension());
    for (int i = 0; i < dimension(); ++i) v[i] = components_[static_cast<std::size_t>(i)]->lower();
    return v;
}

Eigen::VectorXd ProductPrior::upperBounds() const {
    Eigen::VectorXd v(dimension());
    for (int i = 0; i < dimension(); ++i) v[i] = components_[static_cast<std::size_t>(i)]->upper();
    return v;
}

std::shared_ptr<const ProductPrior> uniformBoxPrior(const Eigen::VectorXd& lower, const Eigen::VectorXd& upper) {
    if (lower.size() != upper.size())
        throw InputError(fmt::format("uniform box prior: {} lower bounds but {} upper bounds", lower.size(), upper.size()));
    std::vector<ScalarPriorPtr> c;
    for (Eigen::Index i = 0; i < lower.size(); ++i) c.push_back(uniformPrior(lower[i], upper[i]));
    return std::make_shared<ProductPrior>(std::move(c));
}

CustomPrior::CustomPrior(int dimension, std::function<Eigen::VectorXd(Rng&)> sampler,
                         std::function<double(const Eigen::VectorXd&)> logDensity)
    : dimension_(dimension), sampler_(std::move(sampler)), logDensity_(std::move(logDensity)) {
    if (dimension < 1) throw InputError(fmt::format("custom prior: dimension = {} is invalid: must be >= 1", dimension));
    if (!sampler_ || !logDensity_)
        throw InputError("custom prior: both the sampler and the log-density callback must be given");
}

double CustomPrior::logDensity(const Eigen::VectorXd& theta) const { return logDensity_(theta); }

Eigen::VectorXd CustomPrior::sample(Rng& rng) const {
    Eigen::VectorXd theta = sampler_(rng);
    if (theta.size() != dimension_)
        throw InputError(fmt::format("custom prior: the sampler returned {} coordinates, expected {}", theta.size(), dimension_));
    return theta;
}

}  // namespace trbc
