#pragma once
// The tables and records of `trbc validate` from the runner's finished cases (docs/VALIDATE.md):
// shear.csv, tube.csv, threshold.csv and comparison.csv (each prediction against the experimental
// scatter, analysis/validation.hpp), validation.md with the method text, and with posterior draws
// draws.csv, bands.csv and the band section; validation.json.
#include <nlohmann/json.hpp>

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "analysis/validation_runner.hpp"

namespace trbc {

/// What the command line selected, for validation.json.
struct ValidationSelection {
    std::vector<std::string> only, imports;
    std::string shard;
    std::string command;  ///< the command line, for the provenance
};

/// The observables of a kind of case (angle, ttf, tube): (name in the tables, key of the flow
/// record's observables); none for a threshold, whose observable is its bracket.
std::vector<std::pair<std::string, std::string>> drawObservables(const std::string& kind);

/// What a draw run's record (cases/<id>.json: its "result" is the flow record) gives for one
/// observable (a key of the flow record's observables): not finished for a failed run, with its
/// reason up to its first line break or 100 characters so that equal failures count together; no
/// value, with the regime, for a tumbling cell's angle.
DrawOutcome drawOutcome(const nlohmann::json& record, const std::string& key);

/// Writes the tables and validation.md into R.out; returns the summary (cases, failed, inside,
/// outside, no_data, other, comparisons; with draws "draws") and the band rows in `bandRows`.
nlohmann::json writeValidationTables(const ValidationRunner& R, nlohmann::json& bandRows);

/// The content of OUT/validation.json: summary, selection, cell, levels, configuration and timing.
nlohmann::json validationRecord(const ValidationRunner& R, const ValidationSelection& o, const nlohmann::json& summary,
                                const nlohmann::json& bandRows, std::size_t configured, double wall);

}  // namespace trbc
