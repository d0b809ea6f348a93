#pragma once
// Transitional MCMC (Ching & Chen 2007) and BASIS (Wu et al. 2018) as one solver
// (docs/BAYESIAN_INFERENCE.md). The solver sees a prior and a log-likelihood, nothing else.
//
// Algorithm: from prior draws (exponent rho_0 = 0), repeat: choose the next exponent by
// bisection so that the coefficient of variation of the weights w_k = exp(Delta l_k) equals the
// target; accumulate log Z += log(mean w); resample N copies by multinomial counts; move the copies
// by random-walk Metropolis chains targeting pi(theta) L(theta)^rho with the proposal covariance
// beta^2 * (weighted sample covariance). Stop after the stage with rho = 1.
//   * maxChainLength = 1: BASIS, every resampled copy makes one recorded step (the default, and
//     what the paper's "TMCMC" runs);
//   * maxChainLength = 0: classical TMCMC, one chain of length n_k per selected sample;
//   * other L: the n_k copies of a sample are split into chains of length <= L.
//
// Reproducibility: every random number comes from a stream keyed by (seed, purpose, stage,
// index) (see Rng), all sums run serially in a fixed order and parallel loops only write
// per-index slots, so a given seed gives bit-identical results on any number of OpenMP threads.
// With a checkpoint directory the state is written after every stage and `resume` continues
// from the last one with bit-identical final results.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "inference/priors.hpp"

namespace trbc {

/// What the sampler needs. Exactly one of the two likelihood callbacks is required; the
/// batched one takes precedence. Both may return -inf (zero likelihood); NaN is an error.
struct TmcmcProblem {
    PriorPtr prior;
    /// l(theta); called concurrently from OpenMP threads, so it must be thread-safe.
    std::function<double(const Eigen::VectorXd& theta)> logLikelihood;
    /// l for a batch: thetas is n x m (one column per candidate), returns m values. Called from
    /// one thread (once per batch); it may thread internally.
    std::function<Eigen::VectorXd(const Eigen::MatrixXd& thetas)> batchLogLikelihood;
};

enum class ProposalCovariance {
    Weighted,        ///<: beta^2 sum_k wbar_k (theta_k - mean)(theta_k - mean)^T  (Ching & Chen)
    SelectionCounts  ///< the reference library's: weights wbar_k n_k renormalised, divided by 1 - sum w'^2
};

/// Everything a stage reports (per stage j+1 >= 1).
struct TmcmcStageInfo {
    int stage = 0;                      ///< 1, 2, ...: the stage that moved to `exponent`
    double exponent = 0.0;              ///< rho_{j+1}
    double coefficientOfVariation = 0;  ///< CoV of the weights achieved at Delta = rho_{j+1} - rho_j
    double acceptanceRate = 0.0;        ///< accepted / proposed Metropolis steps (burn-in included)
    int uniqueSelections = 0;           ///< number of distinct samples with n_k > 0
    double effectiveSampleSize = 0.0;   ///< 1 / sum wbar_k^2
    double maxLogLikelihood = 0.0;      ///< max_k l_k of the population that was weighted
    double logEvidenceIncrement = 0.0;  ///< log(W / N) + a*
    double covarianceJitter = 0.0;      ///< diagonal added to the proposal covariance (0 = none needed)
    long long likelihoodEvaluations = 0;///< in this stage
    double elapsedSeconds = 0.0;        ///< wall time since the start of run() (not reproducible)
};

struct TmcmcOptions {
    int populationSize = 1000;          ///< N >= 2
    double targetCoV = 1.0;             ///< c* > 0 (the reference library's default 1.0; the paper's runs use 0.3-0.8)
    double covarianceScaling = 0.04;    ///< beta^2 > 0
    int maxChainLength = 1;             ///< L: 1 = BASIS, 0 = unlimited (classical TMCMC)
    /// Burn-in B per stage: entry j-1 applies to stage j, the last entry repeats; empty = 0.
    std::vector<int> burnIn;
    double minIncrement = 1e-5;         ///< Delta_min in (0, 1]
    double bisectionTolerance = 1e-10;  ///< relative tolerance on Delta (step 1 of a stage)
    ProposalCovariance proposalCovariance = ProposalCovariance::Weighted;
    std::uint64_t seed = 0;

    int maxStages = 0;                  ///< stop after this many annealing stages in total (0 = no limit)
    std::string checkpointDirectory;    ///< empty = no checkpoints
    bool resume = false;                ///< continue from the checkpoint in checkpointDirectory (if any)
    /// Called after every completed stage (from the calling thread). No printing by the library.
    std::function<void(const TmcmcStageInfo&)> onStage;
};

struct TmcmcResult {
    Eigen::MatrixXd samples;            ///< n x N, one column per (equally weighted) sample
    Eigen::VectorXd logLikelihood;      ///< l of each sample
    Eigen::VectorXd logPrior;           ///< log pi of each sample
    double logEvidence = 0.0;           ///< log Z-hat = sum_j log( (1/N) sum_k exp(Delta_j l_k) )
    double exponent = 0.0;              ///< final rho (1 when completed)
    bool completed = false;             ///< false when stopped by maxStages before rho = 1
    long long likelihoodEvaluations = 0;
    std::vector<TmcmcStageInfo> stages;
};

/// Throws InputError naming the first invalid option and its valid range.
void validateTmcmcOptions(const TmcmcOptions& options);

/// Runs TMCMC/BASIS on the problem. Throws InputError for bad options/problem, NumericalError for
/// a NaN log-likelihood (naming the candidate) or a population without any non-zero likelihood.
TmcmcResult runTmcmc(const TmcmcProblem& problem, const TmcmcOptions& options);

/// The same as a solver object (the problem and the solver are separate).
class Tmcmc {
public:
    explicit Tmcmc(TmcmcOptions options);
    TmcmcResult run(const TmcmcProblem& problem) const { return runTmcmc(problem, options_); }
    const TmcmcOptions& options() const { return options_; }

private:
    TmcmcOptions options_;
};

// Building blocks (exposed for tests and for re-weighting elsewhere).

/// CoV(Delta) = sd(w) / mean(w), w_k = exp(Delta (l_k - max l)), sample sd (divisor N-1);
/// samples with l_k = -inf get weight 0 (step 1 of a stage).
double weightCoefficientOfVariation(const Eigen::VectorXd& logLikelihood, double delta);

/// Next increment Delta in (0, 1 - rho] (before Delta_min): 1 - rho when CoV(1 - rho) <= target,
/// otherwise the bisection root of CoV(Delta) = target (relative tolerance `tolerance`).
double nextTemperingIncrement(const Eigen::VectorXd& logLikelihood, double rho, double targetCoV, double tolerance);

/// Multinomial(N; w) counts (w normalised, w_k >= 0), drawn from `rng` by N sorted uniforms
/// (exponential spacings) walked against the cumulative weights. Zero weights get zero counts.
std::vector<int> multinomialCounts(const Eigen::VectorXd& weights, int n, Rng& rng);

}  // namespace trbc
