#pragma once
// A scratch folder of one process, for files that concurrent processes must not share (a test's or
// a benchmark's shape cache).
#include <filesystem>
#include <string_view>

namespace trbc {

/// The directory <system temporary directory>/<prefix><pid>, created (IoError naming it when it
/// cannot be). The caller removes it.
std::filesystem::path processTemporaryDirectory(std::string_view prefix);

}  // namespace trbc
