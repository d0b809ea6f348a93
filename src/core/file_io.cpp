#include "core/file_io.hpp"

#include <fmt/format.h>

#include <fstream>
#include <sstream>

#include "core/error.hpp"

namespace trbc {

void writeFileAtomically(const std::filesystem::path& path, std::string_view text) {
    std::error_code ec;
    const auto kind = std::filesystem::status(path, ec).type();
    if (kind != std::filesystem::file_type::not_found && kind != std::filesystem::file_type::regular &&
        kind != std::filesystem::file_type::none) {
        // A device or a pipe (/dev/stdout, /dev/full) cannot be replaced: written in place, and its
        // errors (a full device) surface at the flush and the close.
        std::ofstream out(path, std::ios::binary);
        out.write(text.data(), static_cast<std::streamsize>(text.size()));
        out.flush();
        out.close();
        if (!out) throw InputError(fmt::format("cannot write {} (device full or not writable)", path.string()));
        return;
    }
    std::filesystem::path tmp = path;
    tmp += ".tmp";
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        out.write(text.data(), static_cast<std::streamsize>(text.size()));
        out.flush();
        out.close();
        if (!out) {
            std::filesystem::remove(tmp, ec);
            throw InputError(fmt::format("cannot write {} (disk full or not writable)", path.string()));
        }
    }
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        const std::string why = ec.message();
        std::filesystem::remove(tmp, ec);
        throw InputError(fmt::format("cannot replace {}: {}", path.string(), why));
    }
}

std::string readFileBytes(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    return bytes.str();
}

std::optional<nlohmann::json> tryReadJson(const std::filesystem::path& path) {
    if (!std::filesystem::exists(path)) return std::nullopt;
    nlohmann::json j = nlohmann::json::parse(readFileBytes(path), nullptr, false);
    if (j.is_discarded()) return std::nullopt;
    return j;
}

}  // namespace trbc
