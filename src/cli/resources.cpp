// Where trbc finds what it reads at run time: data/, configs/, scripts/ and results/mesh_convergence/,
// laid out as in the source tree (docs/DESIGN.md, installation).
#include <fmt/format.h>

#include <cstdlib>
#include <system_error>

#include "cli/common.hpp"
#include "core/error.hpp"

namespace trbc::cli {
namespace fs = std::filesystem;

namespace {

const char* nonEmptyEnv(const char* name) {
    const char* v = std::getenv(name);
    return v && *v ? v : nullptr;
}

}  // namespace

fs::path resourceRoot() {
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    const fs::path installed = (exe.parent_path() / TRBC_INSTALL_SHARE_RELATIVE).lexically_normal();
    if (!ec && fs::is_directory(installed / "data")) return installed;
#ifdef TRBC_SOURCE_DIR
    return TRBC_SOURCE_DIR;
#else
    throw InputError(fmt::format("trbc reads its data, configs and scripts from {} (where `cmake --install` puts them), "
                                 "which has no data/; install trbc, or name the data folder with TRBC_DATA_DIR",
                                 installed.string()));
#endif
}

fs::path dataDirectory() {
    if (const char* d = nonEmptyEnv("TRBC_DATA_DIR")) return d;
    return resourceRoot() / "data";
}

fs::path defaultSurrogateDirectory() {
    if (const char* d = nonEmptyEnv("TRBC_SURROGATE_DIR")) return d;
    return dataDirectory() / "surrogates";
}

fs::path defaultExperimentDirectory() {
    if (const char* d = nonEmptyEnv("TRBC_EXPERIMENT_DATA")) return d;
    return dataDirectory() / "experiments";
}

fs::path scriptDirectory() { return resourceRoot() / "scripts"; }

}  // namespace trbc::cli
