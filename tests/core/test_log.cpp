// The library's log sink (core/log.hpp): the default line on stderr, a replaced sink that receives
// the library's messages instead (the SFS cache's), and messages from many threads.
#include <gtest/gtest.h>
#include <omp.h>

#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "core/log.hpp"
#include "experiments/sfs.hpp"
#include "test_support.hpp"

using namespace trbc;

namespace {

struct Logged {
    LogLevel level;
    std::string message;
};

// Installs a sink that records every message, and restores the previous sink afterwards.
class RecordingSink {
public:
    RecordingSink() : previous_(setLogSink([this](LogLevel l, const std::string& m) { logged.push_back({l, m}); })) {}
    ~RecordingSink() { setLogSink(std::move(previous_)); }
    RecordingSink(const RecordingSink&) = delete;
    RecordingSink& operator=(const RecordingSink&) = delete;
    std::vector<Logged> logged;

private:
    LogSink previous_;
};

}  // namespace

TEST(Log, DefaultSinkWritesOnePrefixedLineToStderr) {
    testing::internal::CaptureStderr();
    logMessage(LogLevel::Warning, "a message");
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "trbc: a message\n");
}

TEST(Log, ReplacedSinkReceivesMessagesAndEmptySinkRestoresDefault) {
    {
        RecordingSink sink;
        testing::internal::CaptureStderr();
        logMessage(LogLevel::Info, "first");
        logMessage(LogLevel::Warning, "second");
        EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
        ASSERT_EQ(sink.logged.size(), 2u);
        EXPECT_EQ(sink.logged[0].level, LogLevel::Info);
        EXPECT_EQ(sink.logged[0].message, "first");
        EXPECT_EQ(sink.logged[1].level, LogLevel::Warning);
        EXPECT_EQ(sink.logged[1].message, "second");
    }
    const LogSink previous = setLogSink({});  // the default again
    testing::internal::CaptureStderr();
    logMessage(LogLevel::Info, "back");
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "trbc: back\n");
    setLogSink(previous);
}

TEST(Log, CorruptSfsCacheEntryIsReportedToTheSinkNotToStderr) {
    test::TempDir dir;
    EXPECT_FALSE(stressFreeState(0.9, 2, dir.path()).fromCache);
    std::ofstream(sfsCachePath(dir.path(), 0.9, 2)) << "OFF\n3 1";  // truncated entry
    RecordingSink sink;
    testing::internal::CaptureStderr();
    EXPECT_FALSE(stressFreeState(0.9, 2, dir.path()).fromCache);
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
    ASSERT_EQ(sink.logged.size(), 1u);
    EXPECT_EQ(sink.logged[0].level, LogLevel::Warning);
    EXPECT_NE(sink.logged[0].message.find("SFS cache entry"), std::string::npos) << sink.logged[0].message;
    EXPECT_NE(sink.logged[0].message.find(sfsCachePath(dir.path(), 0.9, 2).string()), std::string::npos)
        << sink.logged[0].message;
}

TEST(Log, MessagesFromManyThreadsReachTheSinkOneAtATime) {
    RecordingSink sink;  // its vector is not thread-safe: the sink's lock makes it so
    const int n = 4000;
#pragma omp parallel for num_threads(4)
    for (int i = 0; i < n; ++i) logMessage(LogLevel::Info, std::to_string(i));
    ASSERT_EQ(sink.logged.size(), std::size_t(n));
    std::vector<bool> seen(n, false);
    for (const Logged& l : sink.logged) seen[std::size_t(std::stoi(l.message))] = true;
    EXPECT_EQ(std::count(seen.begin(), seen.end(), false), 0);
}
