#include "core/file_io.hpp"

#include <fmt/format.h>

#include <fstream>

#include "core/error.hpp"

namespace trbc {

void writeFileAtomically(const std::filesystem::path& path, std::string_view text) {
    std::filesystem::path tmp = path;
    tmp += ".tmp";
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        out.write(text.data(), static_cast<std::streamsize>(text.size()));
        out.flush();
        if (!out) throw InputError(fmt::format("cannot write {}", tmp.string()));
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) throw InputError(fmt::format("cannot replace {}: {}", path.string(), ec.message()));
}

}  // namespace trbc
