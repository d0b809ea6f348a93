#pragma once
// The three-phase red-cell inference of INFERENCE.md 1 as one driver: runs (or resumes, or loads)
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
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "inference/hierarchical.hpp"
#include "inference/rbc_problem.hpp"
#include "inference/statistics.hpp"

namespace trbc {

struct RbcInferenceOptions {
    std::filesystem::path outputDirectory;
    int firstPhase = 1, lastPhase = 3;  ///< phases to run (1..3); earlier phases are loaded from outputDirectory
    int populationSize = 50000;         ///< N of every run (5)
    std::uint64_t seed = 0xC0FFEE;      ///< run seed; each run uses splitmix64(seed ^ FNV-1a(run name))
    bool resume = false;                ///< continue from checkpoints / reuse finished runs
    FvkDensityRule fvkRule = FvkDensityRule::ClosedForm;  ///< q(FvK | psi) in phases 2-3 (4.3)
    Phase3bOptions phase3b;             ///< derivation (default) or reference behaviours (4.6)
    nlohmann::json provenance = nlohmann::json::object();  ///< merged into infer.json (command, model, ...)
    std::function<void(const std::string&)> progress;      ///< one line per stage and run (may be empty)
};

/// One row of posterior_stats.csv.
struct PosteriorStatsRow {
    std::string posterior, parameter;
    double mean = 0, median = 0, ml = 0, map = 0, sd = 0, q05 = 0, q95 = 0;
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
    RbcPhaseTiming timing[3];
    double wallSeconds = 0.0;
    std::vector<PosteriorStatsRow> stats;  ///< the rows of DIR/posterior_stats.csv (after phase 3)
};

/// Runs phases firstPhase..lastPhase. Throws InputError for bad options, missing earlier phases or
/// unwritable outputs.
RbcInferenceResult runRbcInference(const RbcModel& model, const std::vector<RbcDataSet>& data, const RbcInferenceOptions& options);

/// Statistics rows (7) of one posterior: samples (physical units) dim x N, their stored
/// log-likelihoods and the log prior density used for the MAP.
std::vector<PosteriorStatsRow> posteriorStatsRows(const std::string& posterior, const Eigen::MatrixXd& samples,
                                                  const std::vector<std::string>& names, const Eigen::VectorXd& logLikelihood,
                                                  const Eigen::VectorXd& logPrior);
void writePosteriorStats(const std::filesystem::path& file, const std::vector<PosteriorStatsRow>& rows);

/// Seed of one run: splitmix64(seed ^ FNV-1a(name)).
std::uint64_t rbcRunSeed(std::uint64_t seed, const std::string& runName);

}  // namespace trbc
