#pragma once
// The stage graph of `trbc calibrate` as a table. Every stage is the trbc command a user could
// type, so that its own outputs carry their provenance; the stage ledger (analysis/stage_ledger.hpp)
// skips a stage whose fingerprint, made of the inputs listed here, is unchanged and whose outputs
// exist. In order:
//   data                 the configured CSVs, copied to OUT/data with a datasets.json manifest
//   campaign             (mode run) campaign settings and seed           -> OUT/campaign
//   surrogate            (mode train) the campaign                       -> OUT/surrogate
//   sobol                the surrogate, Sobol' settings                  -> OUT/sobol
//   inference.phase1.X   the surrogate, data set X, inference settings   -> OUT/inference/phase1/X
//   inference.phase23    every phase-1 stage                             -> OUT/inference/phase{2,3}, OUT/figures
//   predict              phase 2-3, the data, prediction settings        -> OUT/predict
//   cell                 phase 2-3, quantile and level                   -> OUT/cell
//   validation           phase 2-3, the validation configuration         -> OUT/validation
//   report               all of the above                                -> OUT/report.{md,html}
// Changing one data CSV therefore re-runs that data set's phase 1, phases 2-3, predict, cell and
// the report, and nothing else. Between the stages stand named fingerprints that are no stage of
// their own (each data set's bytes, the surrogate's networks, the inference settings).
#include <filesystem>
#include <nlohmann/json.hpp>
#include <map>
#include <string>
#include <vector>

#include "analysis/calibrate_config.hpp"
#include "analysis/report.hpp"
#include "analysis/stage_ledger.hpp"

namespace trbc {

/// One input of a fingerprint: a text, or a text followed by the fingerprint of an earlier entry
/// of the table, of a file's bytes, or the one the ledger holds for a stage.
struct FingerprintPart {
    enum class Kind { Text, Entry, File, Recorded };
    Kind kind = Kind::Text;
    std::string text{};              ///< the text, or the prefix of the fingerprint that follows
    std::string entry{};             ///< Entry, Recorded: a stage or a named fingerprint
    std::filesystem::path file{};    ///< File
    std::string missing{};           ///< File: the InputError when the file does not exist ("": fingerprint "missing")

    static FingerprintPart literal(std::string text);
    static FingerprintPart of(std::string entry, std::string prefix = "");
    static FingerprintPart bytesOf(std::filesystem::path file, std::string missing = "");
    static FingerprintPart recorded(std::string stage);
};

/// An entry of the ledger (or a named fingerprint): what its fingerprint is made of, what it leaves behind.
struct CalibrateStage {
    std::string name{};
    std::vector<FingerprintPart> inputs{};
    std::vector<std::filesystem::path> outputs{};  ///< all exist once the stage is done
    std::vector<std::filesystem::path> clean{};    ///< removed before it runs
    std::filesystem::path wallRecord{};            ///< a part's own record with its wall_s ("": the step's time)
};

enum class CalibrateAction {
    Fingerprint,  ///< a named fingerprint only: nothing runs, nothing is recorded
    StageData,    ///< copy the data sets and write their manifest (stageCalibrateData)
    Commands,     ///< run the commands, then the optional ones
    Report,       ///< write OUT/report.{md,html} (writeCalibrationReport)
};

/// One row of the table: a stage, run by its commands. A step with parts runs once for all of them
/// (one command over every data set): only the parts that are out of date are redone, the step's
/// own stage whenever the step runs.
struct CalibrateStep {
    CalibrateAction action = CalibrateAction::Commands;
    std::string name;                    ///< progress lines and OUT/logs/<name>.log
    CalibrateStage stage;                ///< its own ledger entry (the fingerprint of a Fingerprint step)
    std::vector<CalibrateStage> parts;
    std::string partsNote;               ///< progress line of a step with parts; {} = the parts out of date
    std::filesystem::path prune;         ///< subdirectories not cleaned by any part are removed (data no longer configured)
    std::vector<std::string> commands;   ///< each must succeed
    std::vector<std::string> optionalCommands;  ///< figures: a failure only warns
    std::vector<std::string> recorded;   ///< command lines the ledger records for the step's stages
};

/// What the commands run and where the defaults are.
struct CalibrateTools {
    std::filesystem::path trbc;               ///< the trbc executable
    std::filesystem::path python;             ///< interpreter of the figure scripts
    std::filesystem::path scripts;            ///< the figure scripts (plot_*.py)
    std::filesystem::path shippedSurrogates;  ///< surrogate.mode = "shipped"
    std::filesystem::path validationConfig;   ///< [validation] config when none is given
    std::filesystem::path meshConvergence;    ///< mesh-convergence records of the report
};

/// The surrogate directory of a configuration: the shipped one, OUT/surrogate (train) or surrogate.dir.
std::filesystem::path calibrateModelDirectory(const CalibrateConfig& cfg, const std::filesystem::path& out, const CalibrateTools& tools);

/// The table for a configuration, output directory OUT (absolute) and thread count of every stage.
std::vector<CalibrateStep> calibrateSteps(const CalibrateConfig& cfg, const std::filesystem::path& out, int threads,
                                          const CalibrateTools& tools);

/// The entries a stage's fingerprint refers to (FingerprintPart::Entry).
std::vector<std::string> stageDependencies(const CalibrateStage& stage);

/// fingerprintOf its inputs, the entries' fingerprints taken from `known`: InputError for a
/// missing required file, std::logic_error for an entry that is not known (yet).
std::string stageFingerprint(const CalibrateStage& stage, const std::map<std::string, std::string>& known, const StageLedger& ledger);

/// Copies the data sets to DIR/<experiment>/<name>.csv (DIR emptied first) and writes the
/// manifest that `trbc infer --data-dir` and `trbc predict --data-dir` read; returns it.
nlohmann::json stageCalibrateData(const CalibrateConfig& cfg, const std::filesystem::path& dir);

/// What the report of OUT is made from.
CalibrationReportInputs calibrationReportInputs(const CalibrateConfig& cfg, const std::filesystem::path& out, const CalibrateTools& tools);

}  // namespace trbc
