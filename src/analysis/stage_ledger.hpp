#pragma once
// Bookkeeping of a staged pipeline (trbc calibrate): each stage has a fingerprint of everything it
// depends on (settings, seeds, version, the fingerprints of its upstream stages, the bytes of its
// input files). A stage whose recorded fingerprint matches, and whose outputs exist, is skipped.
// The ledger lives in OUT/stages.json, rewritten atomically after every finished stage, so that a
// run killed during a stage redoes that stage (and only that one) next time.
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

#include "core/hash.hpp"

namespace trbc {

class StageLedger {
public:
    /// Loads OUT/stages.json when it exists (an unreadable ledger is treated as empty: every stage runs).
    explicit StageLedger(std::filesystem::path directory);

    /// True when `stage` was finished with this fingerprint and every path in `outputs` exists.
    bool upToDate(const std::string& stage, const std::string& fingerprint, const std::vector<std::filesystem::path>& outputs) const;

    /// Records a finished stage (its fingerprint, command lines, wall time) and saves the ledger.
    void finished(const std::string& stage, const std::string& fingerprint, const nlohmann::json& details, double wallSeconds);
    /// Records that the stage was skipped in this run.
    void skipped(const std::string& stage);
    /// Forgets a stage (its outputs were removed).
    void invalidate(const std::string& stage);

    /// Fingerprint recorded for a stage ("" when none).
    std::string fingerprint(const std::string& stage) const;
    const std::vector<std::string>& ran() const { return ran_; }
    const std::vector<std::string>& skippedStages() const { return skipped_; }
    const nlohmann::json& json() const { return j_; }
    void save() const;

private:
    std::filesystem::path file_;
    nlohmann::json j_;
    std::vector<std::string> ran_, skipped_;
};


}  // namespace trbc
