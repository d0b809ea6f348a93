#include "core/scratch_dir.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <system_error>

#include "core/error.hpp"

namespace trbc {

std::filesystem::path processTemporaryDirectory(std::string_view prefix) {
    const std::filesystem::path p = std::filesystem::temp_directory_path() / fmt::format("{}{}", prefix, ::getpid());
    std::error_code ec;
    std::filesystem::create_directories(p, ec);
    if (ec) throw IoError(fmt::format("cannot create the temporary directory {}: {}", p.string(), ec.message()));
    return p;
}

}  // namespace trbc
