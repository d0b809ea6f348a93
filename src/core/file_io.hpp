#pragma once
// Whole-file writes that a kill cannot leave half done: the text goes to PATH.tmp.<pid>.<n> (created
// exclusively, so concurrent writers never share it), which then
// replaces PATH by rename(2) (atomic on POSIX file systems). Used for every record that a resumed
// run trusts (campaign parts and provenance, stage ledgers, validation cases, reports).
// Reading back the optional records (timings, earlier results) that a run can do without.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

namespace trbc {

/// Writes `text` to `path` atomically; IoError naming the file and the system's reason when it
/// cannot be written (the temporary is removed, so no partial file is left). A path that is a device or a pipe is written
/// in place and checked after the flush.
void writeFileAtomically(const std::filesystem::path& path, std::string_view text);

/// The bytes of a file ("" when it cannot be read).
std::string readFileBytes(const std::filesystem::path& path);

/// The JSON document in `path`, or nothing when the file is missing, unreadable or not valid JSON
/// (a record that is only reused when intact; records that must exist are read with their own errors).
std::optional<nlohmann::json> tryReadJson(const std::filesystem::path& path);

}  // namespace trbc
