#pragma once
// The posteriors of `trbc infer` on disk (the layout of rbc_pipeline.hpp): per run directory
// samples.csv, stages.csv, run.json and the theta_new cross-check; the joint-MCMC draws
// (phase2/joint/draws.bin + draws.json); the reading back of finished runs and earlier records; and
// the provenance DIR/infer.json. Internal to the inference layer.
#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "inference/hierarchical_mcmc.hpp"
#include "inference/rbc_pipeline.hpp"
#include "inference/tmcmc.hpp"

namespace trbc::detail {

/// How a posterior is stored: its directory and the physical-unit columns of its samples.
struct Posterior {
    std::string phase, name;          ///< phase1 / phase2 / phase3, run name
    std::vector<std::string> names;   ///< physical column names (one per sampled variable)
    Eigen::VectorXd scale;            ///< internal -> physical factor per variable
    bool deriveEtam = false;          ///< append etam_Pa_s_um = mu r (theta_new, 4.5)
    std::string label() const { return phase + "/" + name; }
};

/// Samples in physical units (plus derived quantities) and their names.
Eigen::MatrixXd physicalSamples(const Posterior& p, const Eigen::MatrixXd& s, std::vector<std::string>& names);

void writeStages(const std::filesystem::path& file, const TmcmcResult& r);
void writeSamples(const std::filesystem::path& file, const Eigen::MatrixXd& x, const std::vector<std::string>& names,
                  const Eigen::VectorXd& logLikelihood, const Eigen::VectorXd& logPrior);

/// A finished run's timing record (also reused when a finished run is only loaded).
struct RunTiming {
    double wall = 0.0, surrogate = 0.0, population = 0.0;
};

/// The timing recorded in an earlier run.json, if it has one.
std::optional<RunTiming> recordedTiming(const std::filesystem::path& runFile);

nlohmann::json runJson(const Posterior& p, const TmcmcOptions& opt, const TmcmcResult& r, const RunTiming& t);

/// samples.csv (physical units, with `logPrior` as the log-prior column), stages.csv and run.json of
/// a TMCMC run in `dir`; returns the run.json record.
nlohmann::json writeTmcmcRun(const std::filesystem::path& dir, const Posterior& p, const TmcmcOptions& opt, const TmcmcResult& r,
                             const RunTiming& t, const Eigen::VectorXd& logPrior);

/// samples.csv and run.json in `dir` of a posterior given by `chains` Markov chains of equal length
/// laid end to end (`phys`: physical units); returns the run.json record (`info` plus the layout).
nlohmann::json writeChainRun(const std::filesystem::path& dir, const Posterior& p, const Eigen::MatrixXd& phys,
                             const std::vector<std::string>& names, const Eigen::VectorXd& logLikelihood,
                             const Eigen::VectorXd& logPrior, int chains, const nlohmann::json& info);

/// InputError unless `checkpointDirectory` holds a finished run (exponent 1) of the posterior
/// `label`; `phase` is the phase whose `trbc infer --phase` makes it.
void requireFinishedRun(const std::filesystem::path& checkpointDirectory, const std::filesystem::path& outputDirectory,
                        const std::string& label, int phase);

/// The JSON object in `p`, or an empty object when it is missing, unreadable or not an object.
nlohmann::json readJsonOrEmpty(const std::filesystem::path& p);
nlohmann::json timingJson(const RbcPhaseTiming& t);

/// Mean, SD and 5 %/95 % quantiles of each parameter of theta_new from TMCMC and from ancestral
/// sampling, written to `file`; returns them with the largest |mean difference| / ancestral SD.
nlohmann::json ancestralCheck(const Eigen::MatrixXd& tmcmc, const Eigen::MatrixXd& ancestral, const std::filesystem::path& file);

/// Draws of the joint sampler as raw doubles (exact), with a JSON header of the settings they were
/// made with; written to temporary names and renamed.
void saveJointDraws(const std::filesystem::path& dir, const nlohmann::json& settings, const HierarchicalMcmcResult& r);
/// Loads draws saved with the same settings; false when there are none or they were made otherwise.
bool loadJointDraws(const std::filesystem::path& dir, const nlohmann::json& settings, HierarchicalMcmcResult& r);

/// DIR/infer.json: the options, data files and timings of this invocation merged with what earlier
/// invocations wrote there. `runs` and `extrapolation` are this invocation's run records and
/// relaxation extrapolation shares; the seconds are its totals in the surrogate and the population sums.
void writeInferJson(const RbcInferenceOptions& o, const std::vector<RbcDataSet>& data, const RbcInferenceResult& res,
                    const nlohmann::json& runs, const nlohmann::json& extrapolation, double surrogateSeconds,
                    double populationSeconds);

}  // namespace trbc::detail
