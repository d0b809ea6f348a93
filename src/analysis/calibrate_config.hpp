#pragma once
// The TOML configuration of `trbc calibrate`: which data, whether to run a campaign and
// train surrogates or use the shipped ones, and the settings of every stage. Every key is checked:
// a syntax error, an unknown key, a wrong type or a value outside its range is an InputError that
// names the file, the line and the key (and the valid range). configs/paper.toml documents every
// key with its default.
#include <cstdint>
#include <filesystem>
#include <utility>
#include <string>
#include <vector>

namespace trbc {

/// One experimental data set (docs/BAYESIAN_INFERENCE.md, data): a CSV in the format of the shipped experiments.
struct CalibrateDataSet {
    std::string name;        ///< unique; names the posterior directories and figures
    std::string experiment;  ///< equilibrium | stretching | relaxation
    std::filesystem::path file;
};

struct CalibrateConfig {
    std::filesystem::path file;  ///< the configuration file itself
    /// The configurations it overrides (key `base`, relative to the file that names it), nearest first.
    std::vector<std::filesystem::path> bases;

    std::uint64_t seed = 20261123;  ///< [run] every stochastic stage derives its seed from it
    int threads = 2;

    std::vector<CalibrateDataSet> data;  ///< [[data]]; default: the seven data sets of docs/BAYESIAN_INFERENCE.md

    /// [campaign] mode: "shipped" (use the shipped surrogates' training set, nothing to run) or
    /// "run" (trbc campaign into OUT/campaign, resumable).
    std::string campaignMode = "shipped";
    long campaignSamples = 50000;
    int campaignForcesPerCell = 20;
    std::string campaignDesign = "uniform";
    int campaignLevel = 4;

    /// [surrogate] mode: "shipped" (data/surrogates), "train" (on the campaign of this run) or
    /// "path" (a model directory `dir`).
    std::string surrogateMode = "shipped";
    std::filesystem::path surrogateDir;

    bool sobolEnabled = true;  ///< [sobol]
    long sobolSamples = 1024;
    int sobolForces = 100;
    int sobolResamples = 100;

    int inferenceSamples = 50000;          ///< [inference] population size of every TMCMC run
    std::string fvkDensity = "closed";     ///< closed | closed-double | nodes50
    /// [inference.prior]: narrowed phase-1 bounds, (canonical name, (lo, hi)) in physical units.
    std::vector<std::pair<std::string, std::pair<double, double>>> inferencePrior;

    int predictionMaxSamples = 5000;       ///< [prediction] posterior samples pushed forward (0 = all)
    int predictionGrid = 100;

    bool cellEnabled = true;               ///< [cell] export of the calibrated cell
    double cellQuantile = 0.5;
    int cellLevel = 4;
    bool validationEnabled = false;        ///< [validation] trbc validate with the theta_new means (transferability)
    std::filesystem::path validationConfig;  ///< its configuration (default: configs/validation.toml of the source tree)
    std::vector<std::string> validationOnly; ///< kinds of case to run (empty: all)
};

/// The seven data sets of docs/BAYESIAN_INFERENCE.md under an experiments directory.
std::vector<CalibrateDataSet> defaultCalibrateData(const std::filesystem::path& experimentsDirectory);

/// Parses and checks a configuration. `base = "FILE"` makes it an override of FILE: its tables
/// merge into FILE's key by key, its other values (arrays such as [[data]] included) replace
/// FILE's; FILE may have a base of its own. Paths (data files, surrogate.dir, validation.config):
/// relative to the directory of the file that sets them; a leading "@experiments/" stands for
/// `experimentsDirectory`. Throws InputError "<file>:<line>: ..." naming the key (a missing base
/// or a cycle of bases: the `base` line).
CalibrateConfig readCalibrateConfig(const std::filesystem::path& file, const std::filesystem::path& experimentsDirectory);

/// The configuration with its bases merged, as TOML (a copy that stands alone), with a comment
/// naming the files.
std::string mergedCalibrateConfig(const std::filesystem::path& file);

}  // namespace trbc
