// The per-process scratch folder (core/scratch_dir.hpp): named by the prefix and the pid, created,
// the same folder on every call, and an IoError naming the folder that cannot be created.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.hpp"
#include "core/scratch_dir.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

TEST(ScratchDir, OneFolderPerProcessNamedByItsPid) {
    const std::string prefix = "trbc_test_scratch_";
    const fs::path p = processTemporaryDirectory(prefix);
    EXPECT_TRUE(fs::is_directory(p));
    EXPECT_EQ(p.parent_path(), fs::temp_directory_path());
    EXPECT_EQ(p.filename().string(), prefix + std::to_string(::getpid()));
    EXPECT_EQ(processTemporaryDirectory(prefix), p);  // the same folder again
    fs::remove_all(p);

    // Below a plain file no folder can be made: the error names it.
    const fs::path blocker = fs::temp_directory_path() / ("trbc_test_scratch_file_" + std::to_string(::getpid()));
    std::ofstream(blocker) << "a file\n";
    try {
        processTemporaryDirectory(blocker.filename().string() + "/inside_");
        ADD_FAILURE() << "no IoError";
    } catch (const IoError& e) {
        EXPECT_NE(std::string(e.what()).find(blocker.string()), std::string::npos) << e.what();
    }
    fs::remove(blocker);
}

}  // namespace
}  // namespace trbc
