#pragma once
// The job runner of `trbc validate` (docs/VALIDATE.md): every validation case is a `trbc flow
// shear|tube` child process whose JSON is kept in OUT/cases/<id>.json with a key of its command and
// cell; a killed run loses no finished case (resume = run again), a finished case of another output
// directory with the same key is imported instead of run, and `jobs` cases run at a time.
#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "analysis/validation.hpp"
#include "analysis/validation_draws.hpp"
#include "core/clock.hpp"

namespace trbc {

struct ValidationRunner {
    ValidationConfig cfg;
    std::filesystem::path out;     ///< the output directory (absolute)
    std::filesystem::path exe;     ///< the trbc executable the cases run
    bool quiet = false, retryFailed = false, dryRun = false;
    /// Only finished records count: runAll runs nothing and lists the other cases in `missing`
    /// (reading a finished run, as `validate --surrogate --direct` does).
    bool loadOnly = false;
    std::map<std::string, ValidationCase> missing;  ///< case id -> case
    std::vector<std::filesystem::path> imports;  ///< other OUT directories whose finished cases count as finished here
    int imported = 0;                            ///< cases taken from them
    std::mutex mutex;
    std::map<std::string, nlohmann::json> results;  ///< case id -> {"key", "command", "exit", "wall_s", "result"}
    std::vector<ValidationCase> cases;              ///< every case so far, in order
    std::vector<PosteriorDraw> draws;               ///< --draws: the posterior draws run beside the configured cell
    std::uint64_t seed = 0;                         ///< of their choice
    long posteriorSamples = 0;                      ///< samples in the posterior they are drawn from
    int done = 0, total = 0;
    double caseSeconds = 0.0;
    int ranHere = 0;
    SteadyClock::time_point start = SteadyClock::now();

    const PosteriorDraw& drawOf(long sample) const;
    /// The cell options of a case: a draw's parameters, else the configured cell's. A draw of
    /// theta_new is a cell of the population, whose spread reaches past the box of the single-cell
    /// prior (eta_m above 1 Pa s um, b2 above 4); the flow solver needs no surrogate, so the box
    /// does not bind it.
    std::string cellArgs(const ValidationCase& c) const;
    /// What the cell is, for the key: the arguments (a draw's parameters included), the posterior's
    /// bytes, or the Table 1 values the flow commands use by default.
    std::string cellKey(const ValidationCase& c) const;
    /// The flow arguments of a case (without threads and output, which do not change the result).
    std::string caseArgs(const ValidationCase& c) const;
    /// The key a finished record must carry to count for c: version, arguments and cell.
    std::string caseKey(const ValidationCase& c) const;
    /// A draw's record entry: its sample, the seed of the choice, the posterior and the parameters.
    nlohmann::json drawJson(long sample) const;
    std::filesystem::path caseFile(const ValidationCase& c) const;
    /// The record in `file` if it is a finished case with c's key (a failed one only without --retry-failed).
    std::optional<nlohmann::json> matchingRecord(const std::filesystem::path& file, const ValidationCase& c) const;
    /// A finished case of an earlier run with the same key, if any: in OUT, else in an import
    /// directory, whose record and case outputs are then copied into OUT (not in a dry run).
    bool loadFinished(const ValidationCase& c);
    /// Runs one case as a child process and records it (IoError on a full disk, NumericalError when
    /// validate itself is interrupted: neither is recorded).
    void runCase(const ValidationCase& c);
    /// Adds the cases and runs those not finished yet, `cfg.jobs` at a time.
    void runAll(const std::vector<ValidationCase>& batch);
    const nlohmann::json& resultOf(const std::string& id) const;
    /// The threshold cases at eta of the configured cell (sample -1) or of one draw.
    std::vector<RegimePoint> thresholdPoints(double eta, long sample = -1) const;
    /// Rounds of bisection of every threshold bracket (of the configured cell and of each draw),
    /// while a bracket is open.
    void refineThresholds();
};

}  // namespace trbc
