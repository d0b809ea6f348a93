#include "core/version.hpp"

#include "trbc_git_describe.hpp"  // generated into the build tree: #define TRBC_GIT_DESCRIBE "..."

namespace trbc {
const char* gitDescribe() { return TRBC_GIT_DESCRIBE; }
}  // namespace trbc
