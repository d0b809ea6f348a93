#include "analysis/stage_ledger.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <fstream>
#include <sstream>

#include "core/file_io.hpp"
#include "core/error.hpp"
#include "core/hash.hpp"

namespace trbc {
namespace fs = std::filesystem;

std::string fingerprintOf(const std::vector<std::string>& parts) {
    std::uint64_t h = fnv1a("");
    for (const std::string& p : parts) {
        h = fnv1a(std::to_string(p.size()) + ":", h);
        h = fnv1a(p, h);
    }
    return fmt::format("{:016x}", h);
}

std::string fileFingerprint(const fs::path& file) {
    if (!std::ifstream(file, std::ios::binary)) return "missing";
    return fmt::format("{:016x}", fnv1a(readFileBytes(file)));
}

StageLedger::StageLedger(fs::path directory) : file_(directory / "stages.json") {
    j_ = {{"stages", nlohmann::json::object()}};
    // A damaged ledger only costs re-running the stages.
    const std::optional<nlohmann::json> j = tryReadJson(file_);
    if (j && j->contains("stages") && (*j)["stages"].is_object()) j_["stages"] = (*j)["stages"];
}

bool StageLedger::upToDate(const std::string& stage, const std::string& fingerprint, const std::vector<fs::path>& outputs) const {
    if (this->fingerprint(stage) != fingerprint) return false;
    return std::all_of(outputs.begin(), outputs.end(), [](const fs::path& p) { return fs::exists(p); });
}

std::string StageLedger::fingerprint(const std::string& stage) const {
    const nlohmann::json& s = j_["stages"];
    if (!s.contains(stage) || !s[stage].contains("fingerprint")) return "";
    return s[stage]["fingerprint"].get<std::string>();
}

void StageLedger::finished(const std::string& stage, const std::string& fingerprint, const nlohmann::json& details, double wallSeconds) {
    const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
    j_["stages"][stage] = {{"fingerprint", fingerprint}, {"details", details}, {"wall_s", wallSeconds}, {"finished_at", stamp}};
    ran_.push_back(stage);
    save();
}

void StageLedger::skipped(const std::string& stage) {
    skipped_.push_back(stage);
    save();
}

void StageLedger::invalidate(const std::string& stage) {
    j_["stages"].erase(stage);
    save();
}

void StageLedger::save() const {
    nlohmann::json j = j_;
    j["last_run"] = {{"ran", ran_}, {"skipped", skipped_}};
    writeFileAtomically(file_, j.dump(2) + "\n");
}

}  // namespace trbc
