#include "core/hash.hpp"

#include <fmt/format.h>

#include <fstream>
#include <sstream>

namespace trbc {

std::string fingerprintOf(const std::vector<std::string>& parts) {
    std::uint64_t h = fnv1a("");
    for (const std::string& p : parts) {
        h = fnv1a(std::to_string(p.size()) + ":", h);
        h = fnv1a(p, h);
    }
    return fmt::format("{:016x}", h);
}

std::string fileFingerprint(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) return "missing";
    std::ostringstream s;
    s << in.rdbuf();
    return fmt::format("{:016x}", fnv1a(s.str()));
}

}  // namespace trbc
