#pragma once
// The hierarchical posterior sampled as one joint distribution: the population hyper-parameters
// psi, every group's (data set's) parameters and its error-model parameters together, by
// multi-chain adaptive Metropolis-within-Gibbs with location-scale moves. An alternative to the
// three-phase route (phase-1 posteriors, re-weighting, mixtures: hierarchical.hpp) that needs no
// phase-1 samples in its likelihood, so it has no importance-sampling estimator to be noisy.
//
// Model. Pooled components j = 0..P-1 with a population density TN(x; m_j, s_j, [lo_j, hi_j])
// (untruncated when the bounds are infinite) and uniform hyper-priors m_j ~ U[mLo_j, mHi_j],
// s_j ~ U[sLo_j, sHi_j]. Group g has variables y_g = (x_g, e_g): x_g are its values of the pooled
// components it sees (pooled[g]), e_g its own error-model parameters. The target is
//   log p = sum_g [ sum_{j in pooled[g]} log TN(x_gj; m_j, s_j, [lo_j, hi_j]) + logSupport_g(y_g) + l_g(y_g) ],
// logSupport_g = 0 on the group's support (its phase-1 box) plus the log prior of e_g. This is the
// joint density whose psi-marginal phase 2 samples: the re-weighting of phase-1 samples
// p(theta | psi) / pi_i(theta) integrates exactly this over the phase-1 support.
//
// One sweep of every chain:
//   1. each group's block y_g: random-walk Metropolis, proposal covariance adapted in warm-up
//      (pooled over the chains, started from the covariance of `start`), scale by Robbins-Monro
//      towards acceptance 0.25;
//   2. each component's (m_j, s_j): `hyperSteps` random-walk Metropolis steps (no likelihood);
//   3. for each component a shift m_j += d, x_gj += d and a scale move s_j *= e^c,
//      x_gj = m_j + (x_gj - m_j) e^c (Jacobian e^{c (n_j + 1)}, n_j = groups that see j), which
//      re-evaluate only the groups that see j: the moves that cross the funnel between small s_j
//      and spread-out x_gj, which Gibbs-type updates cross only slowly when few groups see j.
// Adaptation stops after warm-up, so the draws are from a fixed Markov kernel with the target as
// its invariant distribution. Chains run in lock-step: each group's proposals of all chains form
// one batch of the likelihood. Every chain has its own random stream (seed, chain), so results do
// not depend on the number of threads.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace trbc {

struct PopulationComponent {
    std::string name;
    double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
    double meanLo = 0.0, meanHi = 1.0;  ///< hyper-prior of m_j
    double sdLo = 0.01, sdHi = 1.0;     ///< hyper-prior of s_j
};

struct HierarchicalGroup {
    std::string name;
    std::vector<int> pooled;             ///< component of each of the first pooled.size() variables
    std::vector<std::string> names;      ///< every variable (pooled first, then the error model)
    /// 0 / log prior of the error-model variables on the support, -inf outside. Thread-safe.
    std::function<double(const Eigen::VectorXd&)> logSupport;
    /// l_g for a batch (variables x candidates); -inf allowed, NaN is an error.
    std::function<Eigen::VectorXd(const Eigen::MatrixXd&)> batchLogLikelihood;
    /// Starting points (variables x K, inside the support), e.g. the group's phase-1 samples;
    /// their covariance is the first proposal covariance.
    Eigen::MatrixXd start;
    /// Variables (> 0) whose random walk runs on their logarithm (Jacobian prod y'/y in the
    /// acceptance): moduli whose ratio the data fix (mu and kb through FvK) and scale parameters.
    std::vector<int> logVariables;
    /// Updates of this block per sweep, in units of HierarchicalMcmcOptions::groupSteps: more for
    /// blocks whose likelihood is cheap (one network row) than for those that cost many.
    int stepsPerSweep = 1;
};

struct HierarchicalModel {
    std::vector<PopulationComponent> population;
    std::vector<HierarchicalGroup> groups;
};

/// log TN(x; m, s, [lo, hi]) (-inf outside [lo, hi]).
double truncatedNormalLogDensity(double x, double m, double s, double lo, double hi);

/// Moments of N(m, s^2) restricted to [a, b]: log of its mass there, mean and variance (stable in
/// the tails; [a, b] may be infinite on either side).
struct TruncatedMoments {
    double logMass = 0.0, mean = 0.0, variance = 0.0;
};
TruncatedMoments truncatedNormalMoments(double m, double s, double a, double b);
/// CDF of N(m, s^2) restricted to [a, b] at x.
double truncatedNormalCdf(double x, double m, double s, double a, double b);

struct HierarchicalMcmcOptions {
    int chains = 16;
    int warmup = 1000;       ///< sweeps per chain, discarded (adaptation)
    int draws = 2000;        ///< draws kept per chain (draws x thin sweeps after warm-up)
    int groupSteps = 2;      ///< updates of each group block per sweep
    int hyperSteps = 4;      ///< (m_j, s_j) updates per sweep
    int thin = 4;            ///< keep every thin-th sweep
    bool locationScaleMoves = true;
    std::uint64_t seed = 0;
    std::function<void(const std::string&)> progress;  ///< a line now and then (may be empty)
};

struct HierarchicalMcmcResult {
    /// hyper[c]: 2P x draws of chain c, rows (m_0, s_0, m_1, s_1, ...).
    std::vector<Eigen::MatrixXd> hyper;
    /// group[g][c]: variables x draws; logLikelihood[g][c]: l_g of each draw.
    std::vector<std::vector<Eigen::MatrixXd>> group;
    std::vector<std::vector<Eigen::VectorXd>> logLikelihood;
    /// Acceptance rates after warm-up: per group block, per component (hyper), shift, scale.
    std::vector<double> groupAcceptance, hyperAcceptance;
    double shiftAcceptance = 0.0, scaleAcceptance = 0.0;
    long long likelihoodEvaluations = 0;  ///< candidates (columns) evaluated
    double wallSeconds = 0.0;
};

/// InputError naming the first option out of its range.
void validateHierarchicalMcmcOptions(const HierarchicalMcmcOptions& options);

/// Throws InputError for an inconsistent model or options, NumericalError for a NaN likelihood.
HierarchicalMcmcResult runHierarchicalMcmc(const HierarchicalModel& model, const HierarchicalMcmcOptions& options);

}  // namespace trbc
