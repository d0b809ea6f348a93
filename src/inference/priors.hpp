#pragma once
// Prior distributions of the generic sampler (docs/BAYESIAN_INFERENCE.md) and the random numbers they
// draw with.
//
// A prior is something that can be sampled and whose log-density log pi(theta) can be evaluated
// (-inf outside its support). One-dimensional priors (`ScalarPrior`) are combined into a product
// over dimensions (`ProductPrior`); `CustomPrior` takes any sampler + log-density pair.
//
// Random numbers: `Rng` (core/random.hpp), one stream per (seed, stage, chain) tuple, so that every
// chain of every stage has its own stream derived deterministically from the run seed.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/random.hpp"

namespace trbc {

// ------------------------------------------------------------------------------------------------
// Normal-distribution helpers

double normalPdf(double x);        ///< phi(x) = exp(-x^2/2) / sqrt(2 pi)
double normalCdf(double x);        ///< Phi(x) = erfc(-x / sqrt 2) / 2 (accurate in the lower tail)
double normalQuantile(double p);   ///< Phi^{-1}(p), p in (0, 1): A&S 26.2.23 start + Halley steps
/// log(Phi(beta) - Phi(alpha)) for alpha < beta, evaluated in whichever tail keeps precision.
double logNormalMass(double alpha, double beta);
/// Draw from N(0,1) truncated to [alpha, beta] by inversion (one uniform).
double truncatedStandardNormal(double alpha, double beta, Rng& rng);

// ------------------------------------------------------------------------------------------------
// One-dimensional priors

class ScalarPrior {
public:
    virtual ~ScalarPrior() = default;
    /// log density at x; -inf outside [lower(), upper()].
    virtual double logDensity(double x) const = 0;
    virtual double sample(Rng& rng) const = 0;
    virtual double lower() const = 0;  ///< support lower bound (may be -inf)
    virtual double upper() const = 0;  ///< support upper bound (may be +inf)
    virtual std::string describe() const = 0;
    bool inSupport(double x) const { return x >= lower() && x <= upper(); }
};
using ScalarPriorPtr = std::shared_ptr<const ScalarPrior>;

/// U[a, b]: log pi = -log(b - a) on [a, b].
ScalarPriorPtr uniformPrior(double a, double b);

/// N(mean, sd^2), optionally truncated to [lo, hi]:
/// log pi = log phi((x-m)/s) - log s - log(Phi((hi-m)/s) - Phi((lo-m)/s)).
ScalarPriorPtr normalPrior(double mean, double sd, double lo = -std::numeric_limits<double>::infinity(),
                           double hi = std::numeric_limits<double>::infinity());

/// log X ~ N(meanLog, sdLog^2), optionally truncated to X in [lo, hi] (0 <= lo < hi <= inf):
/// log pi = -log x + log phi((log x - m)/s) - log s - log Z.
ScalarPriorPtr logNormalPrior(double meanLog, double sdLog, double lo = 0.0,
                              double hi = std::numeric_limits<double>::infinity());

/// Ratio-uniform (docs/BAYESIAN_INFERENCE.md): Z = X/Y, X ~ U[a,b], Y ~ U[c,e], 0 < a < b, 0 < c < e,
/// p(z) = (min(e, b/z)^2 - max(c, a/z)^2) / (2 (b-a)(e-c)) on [a/e, b/c]; sampled as X/Y.
ScalarPriorPtr ratioUniformPrior(double a, double b, double c, double e);

/// Any 1-D prior on [lo, hi] from callbacks (both must be thread-safe and consistent; the
/// log-density is only called inside [lo, hi], -inf is returned outside).
ScalarPriorPtr customScalarPrior(double lo, double hi, std::function<double(Rng&)> sampler,
                                 std::function<double(double)> logDensity, std::string name = "custom");

/// Moments of the ratio-uniform distribution: E Z = (a+b)/2 * log(e/c)/(e-c),
/// E Z^2 = (a^2+ab+b^2)/3 / (c e).
double ratioUniformMean(double a, double b, double c, double e);
double ratioUniformSecondMoment(double a, double b, double c, double e);

// ------------------------------------------------------------------------------------------------
// Multivariate priors (what the sampler sees)

class Prior {
public:
    virtual ~Prior() = default;
    virtual int dimension() const = 0;
    /// log pi(theta), -inf outside the support; must be thread-safe.
    virtual double logDensity(const Eigen::VectorXd& theta) const = 0;
    virtual Eigen::VectorXd sample(Rng& rng) const = 0;
};
using PriorPtr = std::shared_ptr<const Prior>;

/// Independent coordinates: log pi(theta) = sum_i log pi_i(theta_i).
class ProductPrior : public Prior {
public:
    explicit ProductPrior(std::vector<ScalarPriorPtr> components);
    int dimension() const override { return static_cast<int>(components_.size()); }
    double logDensity(const Eigen::VectorXd& theta) const override;
    Eigen::VectorXd sample(Rng& rng) const override;  ///< coordinates drawn in order from one stream
    const ScalarPrior& component(int i) const { return *components_.at(static_cast<std::size_t>(i)); }
    Eigen::VectorXd lowerBounds() const;
    Eigen::VectorXd upperBounds() const;

private:
    std::vector<ScalarPriorPtr> components_;
};

/// U[lower_i, upper_i] in every coordinate.
std::shared_ptr<const ProductPrior> uniformBoxPrior(const Eigen::VectorXd& lower, const Eigen::VectorXd& upper);

/// A prior from callbacks (thread-safe): sampler(rng) -> theta of size `dimension`, logDensity.
class CustomPrior : public Prior {
public:
    CustomPrior(int dimension, std::function<Eigen::VectorXd(Rng&)> sampler,
                std::function<double(const Eigen::VectorXd&)> logDensity);
    int dimension() const override { return dimension_; }
    double logDensity(const Eigen::VectorXd& theta) const override;
    Eigen::VectorXd sample(Rng& rng) const override;

private:
    int dimension_;
    std::function<Eigen::VectorXd(Rng&)> sampler_;
    std::function<double(const Eigen::VectorXd&)> logDensity_;
};

}  // namespace trbc
