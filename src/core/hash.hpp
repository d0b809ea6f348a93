#pragma once
// FNV-1a, 64 bit: content checksums of cache entries and training-data hashes (not cryptographic).
#include <cstdint>
#include <string_view>

namespace trbc {

inline std::uint64_t fnv1a(std::string_view bytes, std::uint64_t h = 1469598103934665603ull) {
    for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
    return h;
}

}  // namespace trbc
