#include "core/version.hpp"

#include "core/simd.hpp"

#include "trbc_git_describe.hpp"  // generated into the build tree: #define TRBC_GIT_DESCRIBE "..."

namespace trbc {
const char* gitDescribe() { return TRBC_GIT_DESCRIBE; }

nlohmann::json withBuild(nlohmann::json record) {
    record["version"] = kVersion;
    record["revision"] = gitDescribe();
    record["build"] = simd::buildTarget();
    return record;
}
}  // namespace trbc
