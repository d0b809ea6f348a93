#pragma once
// Convergence diagnostics and Monte Carlo standard errors of Markov chains, after Vehtari, Gelman,
// Simpson, Carpenter and Buerkner (2021), "Rank-normalization, folding, and localization: an
// improved R-hat for assessing convergence of MCMC", Bayesian Analysis 16(2) 667-718.
//
// A parameter's draws are given as one vector per chain (equal lengths). Every function splits each
// chain into its two halves first, so that a chain that drifts shows up as two chains that disagree.
//   * R-hat: max of the split R-hat of the rank-normalised draws and of the rank-normalised folded
//     draws |x - median| (detects differences in location and in scale);
//   * bulk ESS: effective sample size of the rank-normalised draws;
//   * tail ESS: min of the ESS of the indicators 1{x <= q05} and 1{x <= q95};
//   * ESS of a function: Geyer's initial monotone sequence on the multi-chain autocorrelation
//     rho_t = 1 - (W - mean_j acov_j(t)) / var+ (the estimator of Stan), capped at S log10(S).
// The Monte Carlo standard error of a self-normalised average sum_t w_t a_t / sum_t w_t (the
// posterior mean is w = 1, a Rao-Blackwellised mean has a = E[theta | psi_t]) is the delta-method
// one, sd(u) / sqrt(ESS(u)) with u_t = w_t (a_t - estimate) / mean(w).
#include <Eigen/Core>
#include <vector>

namespace trbc {

using Chains = std::vector<Eigen::VectorXd>;

struct ChainDiagnostics {
    double rhat = 0.0;     ///< rank-normalised split R-hat (max of bulk and folded)
    double essBulk = 0.0;
    double essTail = 0.0;
    double essMean = 0.0;  ///< ESS of the raw draws (for the MCSE of the mean)
};

/// All four diagnostics of one parameter (any number of chains of equal length >= 4).
ChainDiagnostics chainDiagnostics(const Chains& chains);

/// The chains laid end to end (one vector of every draw).
Eigen::VectorXd pooledDraws(const Chains& chains);

/// Effective sample size of the draws as they are (split chains, Geyer's initial monotone sequence).
double effectiveSampleSize(const Chains& chains);
/// Split R-hat of the draws as they are (no rank normalisation).
double splitRhat(const Chains& chains);
/// Normal scores of the pooled ranks, z = Phi^-1((r - 3/8) / (S + 1/4)), ties averaged; same shape.
Chains rankNormalise(const Chains& chains);

/// Estimate and Monte Carlo standard error.
struct McEstimate {
    double value = 0.0, mcse = 0.0;
};
/// sum w a / sum w over all draws with the delta-method MCSE (see the header comment).
McEstimate selfNormalisedMean(const Chains& weights, const Chains& values);
/// Mean of the draws and its MCSE sd / sqrt(ESS).
McEstimate chainMean(const Chains& chains);
/// Population SD of the draws; MCSE by the delta method on the second central moment.
McEstimate chainSd(const Chains& chains);
/// Quantile (type 7) of the pooled draws; MCSE from the ESS of the indicator 1{x <= q}:
/// half the distance between the quantiles at p -+ sqrt(p (1 - p) / ESS).
McEstimate chainQuantile(const Chains& chains, double p);

}  // namespace trbc
