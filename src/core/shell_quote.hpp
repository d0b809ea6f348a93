#pragma once
// Command lines for /bin/sh (the child processes of `trbc calibrate` and `trbc validate`).
#include <filesystem>
#include <string>

namespace trbc {

/// A path in single quotes for /bin/sh; a single quote inside becomes '\''.
inline std::string shellQuote(const std::filesystem::path& p) {
    std::string s = "'";
    for (char c : p.string()) s += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return s + "'";
}

}  // namespace trbc
