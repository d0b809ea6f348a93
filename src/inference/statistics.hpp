#pragma once
// Posterior statistics (docs/BAYESIAN_INFERENCE.md) of a sample set: mean, median, population SD, central
// credible intervals from empirical quantiles, the ML and MAP samples; weighted versions for
// weighted sample sets; the profile-likelihood diagnostic.
#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

#include "inference/tmcmc.hpp"

namespace trbc {

struct CredibleInterval {
    double level = 0.0;  ///< c, e.g. 0.9
    double lower = 0.0;  ///< q_{(1-c)/2}
    double upper = 0.0;  ///< q_{(1+c)/2}
};

struct ParameterSummary {
    std::string name;
    double mean = 0.0;    ///< sum_k w_k theta_k (w_k = 1/N unweighted)
    double median = 0.0;  ///< q_0.5
    double sd = 0.0;      ///< unweighted: population SD (divisor N); weighted: sqrt(sum w (theta - mean)^2 / (1 - sum w^2))
    double q05 = 0.0, q95 = 0.0;
    double ml = 0.0;      ///< this coordinate of the maximum-likelihood sample
    double map = 0.0;     ///< this coordinate of the maximum-a-posteriori sample
    std::vector<CredibleInterval> intervals;
};

struct PosteriorSummary {
    std::vector<ParameterSummary> parameters;
    Eigen::Index mlIndex = -1;      ///< argmax_k l_k
    Eigen::Index mapIndex = -1;     ///< argmax_k l_k + log pi_k
    double maxLogLikelihood = 0.0;
    double maxLogPosterior = 0.0;   ///< l + log pi at the MAP sample (unnormalised)
    double effectiveSampleSize = 0.0;  ///< N unweighted, 1 / sum w^2 weighted
    /// The summary of the parameter called `name` (InputError if there is none).
    const ParameterSummary& operator[](const std::string& name) const;
};

/// Statistics of samples (n x N, one column per sample) with their stored log-likelihoods and
/// log-priors. `weights` (size N, >= 0, any normalisation) switches to the weighted
/// formulas; empty = equally weighted. `names` default to theta0, theta1, ...
PosteriorSummary posteriorStatistics(const Eigen::MatrixXd& samples, const Eigen::VectorXd& logLikelihood,
                                     const Eigen::VectorXd& logPrior, const std::vector<std::string>& names = {},
                                     const Eigen::VectorXd& weights = Eigen::VectorXd(),
                                     const std::vector<double>& levels = {0.5, 0.75, 0.9, 0.99});

/// The same for the final (equally weighted) population of a TMCMC/BASIS run.
PosteriorSummary posteriorStatistics(const TmcmcResult& result, const std::vector<std::string>& names = {});

// Building blocks.

/// Empirical quantile with linear interpolation between order statistics (Hyndman-Fan type 7,
/// numpy's default): h = (N-1) p, q = x_(floor h) + (h - floor h)(x_(floor h + 1) - x_(floor h)).
double quantile(const Eigen::VectorXd& values, double p);
/// The same on already sorted values.
double quantileSorted(const std::vector<double>& sorted, double p);
/// Monte Carlo standard error of quantileSorted(sorted, p) for draws of effective sample size
/// `ess`: the fraction of draws below the true quantile has SD sqrt(p (1 - p) / ess), mapped
/// through the empirical quantile function, i.e. half the distance between the quantiles at
/// p -+ sqrt(p (1 - p) / ess) (levels clamped to [0, 1], so an extreme quantile of few draws gets
/// the one-sided spread; a lower bound there). 0 for a single draw.
double quantileMcseSorted(const std::vector<double>& sorted, double p, double ess);
/// Whether quantileMcseSorted(., p, ess) clamps a level, so that it is a lower bound.
bool quantileMcseIsLowerBound(double p, double ess);
/// Weighted quantile: sorted values at the rescaled mid-point cumulative weights
/// p_i = (C_i - w_i/2 - w_1/2) / (1 - w_1/2 - w_N/2) (C_i = cumulative normalised weight),
/// linear interpolation between them; equal weights reduce it exactly to type 7. Zero weights
/// are dropped.
double weightedQuantile(const Eigen::VectorXd& values, const Eigen::VectorXd& weights, double p);

double mean(const Eigen::VectorXd& values);
double populationSd(const Eigen::VectorXd& values);  ///< sqrt(sum (x - mean)^2 / N)
/// sum w x / sum w.
double weightedMean(const Eigen::VectorXd& values, const Eigen::VectorXd& weights);
/// sqrt(sum w (x - mean_w)^2 / (1 - sum w^2)) with w normalised (7, reliability weights).
double weightedSd(const Eigen::VectorXd& values, const Eigen::VectorXd& weights);
/// 1 / sum w^2 with w normalised.
double effectiveSampleSize(const Eigen::VectorXd& weights);

/// Index of the largest value (first one on ties; NaN ignored; 0 if every value is -inf/NaN).
Eigen::Index argmax(const Eigen::VectorXd& values);

/// Profile-likelihood diagnostic: `bins` equal bins over [min, max] of the values, the
/// sample count and the maximum log-likelihood per bin (-inf for an empty bin).
struct ProfileLikelihood {
    Eigen::VectorXd edges;          ///< bins + 1
    Eigen::VectorXi counts;         ///< bins
    Eigen::VectorXd maxLogLikelihood;  ///< bins
};
ProfileLikelihood profileLikelihood(const Eigen::VectorXd& values, const Eigen::VectorXd& logLikelihood, int bins = 50);

/// Appends the row f(theta_k) to samples (derived quantities, e.g. eta_m = mu r, taken sample by
/// sample before statistics, 7) and its name to `names`.
void appendDerivedParameter(Eigen::MatrixXd& samples, std::vector<std::string>& names, const std::string& name,
                            const std::function<double(const Eigen::VectorXd&)>& f);

}  // namespace trbc
