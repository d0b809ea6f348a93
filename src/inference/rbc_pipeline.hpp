#pragma once
// The three-phase red-cell inference of docs/BAYESIAN_INFERENCE.md as one driver: runs (or resumes, or loads)
// the TMCMC/BASIS runs of the selected phases on the given forward model and data, and writes per
// posterior its samples, stages and log-evidence, the statistics (posterior_stats.csv,
// posterior_table.md) and the provenance (infer.json). `trbc infer` is a thin front end to it.
//
// Output directory layout (DIR):
//   phase1/<data set>/            samples.csv (physical units), stages.csv, run.json, checkpoint/
//   phase1/posterior_stats.csv    the seven individual posteriors
//   phase2/hyper/...              hyper-parameter posterior (phase2/posterior_stats.csv)
//   phase3/theta_new/...          new-cell posterior (phase 3a) + ancestral_check.csv (4.5 cross-check)
//   phase3/<data set>/...         posteriors given all data (phase 3b)
//   posterior_stats.csv           theta_new and the seven phase-3b posteriors (columns posterior,
//                                 parameter, mean, median, ml, map, sd, q05, q95; kb in J)
//   posterior_table.md            the same laid out like the paper's Table 1
//   infer.json                    command, version, seed, model, data, timings per phase
//
// Every run has its own seed derived from the run seed and its name, and checkpoints after every
// stage in its checkpoint/ directory; `resume` continues unfinished runs and reuses finished ones
// with bit-identical results. Results do not depend on the number of OpenMP threads.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "inference/hierarchical.hpp"
#include "inference/hierarchical_mcmc.hpp"
#include "inference/rbc_hierarchical.hpp"
#include "inference/rbc_problem.hpp"
#include "inference/statistics.hpp"

namespace trbc {

/// How phases 2 and 3 reach the hierarchical posterior.
enum class HierarchicalMethod {
    /// The joint posterior of hyper-parameters, every data set's parameters and error models by
    /// multi-chain MCMC (hierarchical_mcmc.hpp), theta_new by Rao-Blackwellisation over its
    /// hyper-parameter draws (rbc_hierarchical.hpp). Default: exact (no importance-sampling
    /// estimator in the likelihood), with R-hat, ESS and MCSE for every statistic.
    Joint,
    /// The paper's route: phase 2 re-weights the phase-1 samples, phase 3 samples mixtures
    /// over the phase-2 samples with TMCMC/BASIS (4.5-4.6).
    Reweighting
};

struct RbcInferenceOptions {
    std::filesystem::path outputDirectory;
    HierarchicalMethod method = HierarchicalMethod::Joint;
    /// Joint method: chains, warm-up sweeps, kept draws per chain and sweeps per kept draw (the
    /// seed is derived from `seed`).
    int chains = 16, warmup = 1000, draws = 2500, thin = 4;
    /// Population model choices for sensitivity studies (hyper-prior SD bounds and truncation:
    /// joint method only; the theta_new box: both methods).
    PopulationVariant population;
    int firstPhase = 1, lastPhase = 3;  ///< phases to run (1..3); earlier phases are loaded from outputDirectory
    int populationSize = 50000;         ///< N of every run
    /// Unrecorded Metropolis steps per BASIS stage of the phase-1 runs (0: the paper's BASIS).
    int phase1BurnIn = 0;
    std::uint64_t seed = 0xC0FFEE;      ///< run seed; each run uses splitmix64(seed ^ FNV-1a(run name))
    bool resume = false;                ///< continue from checkpoints / reuse finished runs
    FvkDensityRule fvkRule = FvkDensityRule::ClosedForm;  ///< q(FvK | psi) in phases 2-3
    Phase3bOptions phase3b;             ///< derivation (default) or reference behaviours
    nlohmann::json provenance = nlohmann::json::object();  ///< merged into infer.json (command, model, ...)
    std::function<void(const std::string&)> progress;      ///< one line per stage and run (may be empty)
};

/// One row of posterior_stats.csv: the statistics (mean, median, ML, MAP, SD, 5 % and 95 % quantiles), the Monte Carlo standard error of
/// each, and the chain diagnostics (NaN where a route has none, e.g. the BASIS populations).
struct PosteriorStatsRow {
    std::string posterior, parameter;
    double mean = 0, median = 0, ml = 0, map = 0, sd = 0, q05 = 0, q95 = 0;
    double mcseMean = kNoValue, mcseMedian = kNoValue, mcseSd = kNoValue, mcseQ05 = kNoValue, mcseQ95 = kNoValue;
    double rhat = kNoValue, essBulk = kNoValue, essTail = kNoValue;
    static constexpr double kNoValue = std::numeric_limits<double>::quiet_NaN();
};

/// Wall time of a phase split into forward model (surrogate), population sums and the rest
/// (sampler, statistics, I/O).
struct RbcPhaseTiming {
    bool ran = false;
    double wallSeconds = 0.0, surrogateSeconds = 0.0, populationSeconds = 0.0;
    long long surrogateEvaluations = 0, populationTerms = 0;
    double samplerSeconds() const { return wallSeconds - surrogateSeconds - populationSeconds; }
};

struct RbcInferenceResult {
    std::vector<TmcmcResult> phase1;   ///< per data set (loaded when not run)
    TmcmcResult phase2;                ///< hyper-parameters
    TmcmcResult phase3a;               ///< theta_new
    std::vector<TmcmcResult> phase3b;  ///< per data set
    Eigen::MatrixXd ancestral;         ///< 4.5 cross-check samples of theta_new (5 x N)
    HierarchicalMcmcResult joint;      ///< the joint method's draws (phases 2-3)
    RbcPhaseTiming timing[3];
    double wallSeconds = 0.0;
    std::vector<PosteriorStatsRow> stats;  ///< the rows of DIR/posterior_stats.csv (after phase 3)
};

/// InputError for options, data sets or a model that runRbcInference would refuse (a flow data set
/// under the re-weighting method or without flow networks, phases, sizes), before anything is written.
void validateRbcInference(const RbcModel& model, const std::vector<RbcDataSet>& data, const RbcInferenceOptions& options);

/// Runs phases firstPhase..lastPhase. Throws InputError for bad options, missing earlier phases or
/// unwritable outputs.
RbcInferenceResult runRbcInference(const RbcModel& model, const std::vector<RbcDataSet>& data, const RbcInferenceOptions& options);

/// Statistics rows of one posterior: samples (physical units) dim x N, their stored
/// log-likelihoods and the log prior density used for the MAP. The samples are `chains` Markov
/// chains of equal length laid end to end; MCSEs come from their multi-chain ESS
/// (mcmc_diagnostics.hpp), and R-hat and ESS are filled when chains >= 2. A BASIS population
/// (chains = 1, columns in the order of their parents) gets an MCSE that sees the repeats of a
/// resampled sample but not the ancestry of earlier stages: a lower bound of its Monte Carlo error.
std::vector<PosteriorStatsRow> posteriorStatsRows(const std::string& posterior, const Eigen::MatrixXd& samples,
                                                  const std::vector<std::string>& names, const Eigen::VectorXd& logLikelihood,
                                                  const Eigen::VectorXd& logPrior, int chains = 1);
void writePosteriorStats(const std::filesystem::path& file, const std::vector<PosteriorStatsRow>& rows);

/// DIR/phase1_prior_box.json: the prior box of the phase-1 posteriors in DIR (and the flow networks'
/// fingerprint when flow sets are chosen), which phases 2-3 and a resumed phase 1 must share.
inline constexpr const char* kPhase1PriorBoxFile = "phase1_prior_box.json";
/// {"<parameter>": [lo, hi]} in physical units, for every parameter of the box.
nlohmann::json priorBoxJson(const RbcPriorBox& box);
/// The phase-1 posteriors in `out` are reused (`reuses`: phases 2-3, or a resumed phase 1) only if
/// they were made with the same `record` (priorBoxJson, with "flow_model", the flow networks'
/// fingerprint, when flow sets are chosen): InputError naming both otherwise. `writes`: phase 1
/// runs and records it in out/kPhase1PriorBoxFile.
void checkPhase1Record(const std::filesystem::path& out, const nlohmann::json& record, bool reuses, bool writes);

/// Seed of one run: splitmix64(seed ^ FNV-1a(name)).
std::uint64_t rbcRunSeed(std::uint64_t seed, const std::string& runName);

}  // namespace trbc
