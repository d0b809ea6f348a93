#pragma once
// `trbc validate` as a library call (docs/VALIDATE.md): configuration and command-line overrides,
// the selection of cases (--only, --shard), the listing of a dry run, the runner, the refinement of
// the thresholds, the tables, the figures and the summary; or, with flow networks, the bands of
// the shear cases through them (analysis/flow_bands.hpp).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace trbc {

struct ValidationRunOptions {
    std::filesystem::path config, out, posterior, surrogate;
    std::filesystem::path direct;  ///< with surrogate: a finished direct run of draws to compare the networks with
    std::vector<std::string> only, imports;
    std::string shard;
    std::string thresholdProtocol;                     ///< empty: the configuration's
    int jobs = 0, threads = 0, level = 0, draws = 0;  ///< 0: the configuration's
    std::uint64_t seed = 1;                            ///< of the choice of the draws
    bool quiet = false, dryRun = false, retryFailed = false;
    // Where the run finds its tools and data, and what it records as its command.
    std::filesystem::path exe;            ///< the trbc executable that runs the cases
    std::filesystem::path scripts;        ///< folder of plot_validation.py
    std::filesystem::path python;         ///< interpreter of the figure script
    std::filesystem::path experimentDir;  ///< default experimental data (the config's data_dir overrides it)
    std::string command;                  ///< the command line, for the provenance
};

/// Runs the validation set into o.out (resumable); prints the summary on stdout and progress on
/// stderr unless quiet. NumericalError when a case failed (after the tables are written).
void runValidation(const ValidationRunOptions& o);

}  // namespace trbc
