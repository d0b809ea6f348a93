#pragma once
// FNV-1a, 64 bit: content checksums of cache entries and training-data hashes (not cryptographic).
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace trbc {

inline std::uint64_t fnv1a(std::string_view bytes, std::uint64_t h = 1469598103934665603ull) {
    for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
    return h;
}

/// FNV-1a fingerprint of a list of strings (each length-prefixed, so that ("ab","c") != ("a","bc")).
std::string fingerprintOf(const std::vector<std::string>& parts);
/// FNV-1a of a file's bytes ("missing" when it does not exist).
std::string fileFingerprint(const std::filesystem::path& file);

}  // namespace trbc
