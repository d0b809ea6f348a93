// The job runner of `trbc validate` (analysis/validation_runner.hpp) with a stand-in for the flow
// commands: a shell script that records its arguments and prints a flow result. Each case runs
// once, a second run resumes from the records, a record of another cell is not reused, an import
// copies finished cases instead of running them, and a failed case is kept with its reason until
// retryFailed.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "analysis/validation_runner.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

/// A stand-in for `trbc flow ...`: appends its arguments to calls.log beside it and prints a result;
/// with FAIL in its folder it exits 3 without one.
fs::path fakeFlowCommand(const fs::path& dir) {
    const fs::path exe = test::writeText(dir / "fake_trbc", R"(#!/bin/sh
here=$(dirname "$0")
echo "$*" >> "$here/calls.log"
if [ -e "$here/FAIL" ]; then echo "solver diverged" >&2; exit 3; fi
if [ -e "$here/DAMAGED" ]; then echo '{"status": "ok", "observables": {"inclination_deg": "12.5"}}'; exit 0; fi
echo '{"status": "ok", "observables": {"regime": "tank-treading", "inclination_deg": 12.5, "ttf_4pi_f_over_shear_rate": 0.31}}'
)");
    fs::permissions(exe, fs::perms::owner_all);
    return exe;
}

int callCount(const fs::path& dir) {
    std::ifstream in(dir / "calls.log");
    int n = 0;
    for (std::string line; std::getline(in, line);) ++n;
    return n;
}

const std::vector<ValidationCase> kCases = {{"angle_eta23.9_rate50", "angle", 23.9, 50.0, 0.0, -1, 0},
                                            {"ttf_eta23.9_rate100", "ttf", 23.9, 100.0, 0.0, -1, 0},
                                            {"angle_eta55.9_rate20", "angle", 55.9, 20.0, 0.0, -1, 0}};

/// A runner writing into `out`, the cases run by `exe`, quiet, two at a time.
void configure(ValidationRunner& R, const fs::path& out, const fs::path& exe) {
    R.cfg.jobs = 2;
    R.cfg.level = 2;
    R.out = out;
    R.exe = exe;
    R.quiet = true;
    fs::create_directories(out / "cases");
}

/// The record of kCases[0] after one run into tmp/out by the stand-in with the file `marker` beside
/// it (FAIL, DAMAGED), which is removed afterwards.
nlohmann::json runFirstCaseWith(const fs::path& tmp, const fs::path& exe, const char* marker, bool quiet = true) {
    test::writeText(tmp / marker, "");
    ValidationRunner R;
    configure(R, tmp / "out", exe);
    R.quiet = quiet;
    R.runAll({kCases[0]});
    fs::remove(tmp / marker);
    return R.resultOf(kCases[0].id);
}

TEST(ValidationRunner, RunsEachCaseOnceAndResumesFromItsRecords) {
    const test::TempDir tmp;
    const fs::path exe = fakeFlowCommand(tmp.path());
    {
        ValidationRunner R;
        configure(R, tmp.path() / "out", exe);
        R.runAll(kCases);
        EXPECT_EQ(R.ranHere, 3);
        EXPECT_EQ(callCount(tmp.path()), 3);
        for (const ValidationCase& c : kCases) {
            ASSERT_TRUE(fs::exists(R.caseFile(c))) << c.id;
            EXPECT_EQ(R.resultOf(c.id).at("status"), "ok");
            EXPECT_DOUBLE_EQ(R.resultOf(c.id).at("observables").at("inclination_deg").get<double>(), 12.5);
        }
        // The command carries the case's flow and the configured cell (Table 1 by default: no cell options).
        const std::string calls = test::slurp(tmp.path() / "calls.log");
        EXPECT_NE(calls.find("flow shear --eta-out 55.9 --shear-rate 20 --eta-in 10 --level 2"), std::string::npos) << calls;
    }
    {
        ValidationRunner R;  // the same cases again: nothing runs
        configure(R, tmp.path() / "out", exe);
        R.runAll(kCases);
        EXPECT_EQ(R.ranHere, 0);
        EXPECT_EQ(R.done, 3);
        EXPECT_EQ(callCount(tmp.path()), 3);
    }
    {
        ValidationRunner R;  // another cell: another key, every case runs again
        configure(R, tmp.path() / "out", exe);
        R.cfg.cellSource = "explicit";
        R.cfg.etam = 0.3;
        R.runAll(kCases);
        EXPECT_EQ(R.ranHere, 3);
        EXPECT_EQ(callCount(tmp.path()), 6);
        EXPECT_NE(test::slurp(tmp.path() / "calls.log").find("--etam 0.3"), std::string::npos);
    }
}

TEST(ValidationRunner, ImportsFinishedCasesOfAnotherDirectoryInsteadOfRunningThem) {
    const test::TempDir tmp;
    const fs::path exe = fakeFlowCommand(tmp.path());
    {
        ValidationRunner R;
        configure(R, tmp.path() / "part1", exe);
        R.runAll({kCases[0], kCases[1]});
    }
    ValidationRunner R;
    configure(R, tmp.path() / "merged", exe);
    R.imports = {tmp.path() / "part1"};
    R.runAll(kCases);
    EXPECT_EQ(R.imported, 2);
    EXPECT_EQ(R.ranHere, 1);  // the third case was not in part1
    EXPECT_EQ(callCount(tmp.path()), 3);
    for (const ValidationCase& c : kCases) EXPECT_TRUE(fs::exists(R.caseFile(c))) << c.id;
}

TEST(ValidationRunner, KeepsAFailedCaseWithItsReasonUntilRetryFailed) {
    const test::TempDir tmp;
    const fs::path exe = fakeFlowCommand(tmp.path());
    const nlohmann::json r = runFirstCaseWith(tmp.path(), exe, "FAIL");
    EXPECT_EQ(r.at("status"), "failed");
    EXPECT_NE(r.at("reason").get<std::string>().find("exit 3 without a result: solver diverged"), std::string::npos) << r;
    {
        ValidationRunner R;  // kept: a failure counts as finished
        configure(R, tmp.path() / "out", exe);
        R.runAll({kCases[0]});
        EXPECT_EQ(R.ranHere, 0);
        EXPECT_EQ(R.resultOf(kCases[0].id).at("status"), "failed");
    }
    {
        ValidationRunner R;
        configure(R, tmp.path() / "out", exe);
        R.retryFailed = true;
        R.runAll({kCases[0]});
        EXPECT_EQ(R.ranHere, 1);
        EXPECT_EQ(R.resultOf(kCases[0].id).at("status"), "ok");
    }
    EXPECT_EQ(callCount(tmp.path()), 2);
}

// A run that exits 0 with a damaged result (an observable that is not a number) fails its case
// with the reader's message; a damaged case record on disk is run again.
TEST(ValidationRunner, ADamagedResultFailsItsCaseAndADamagedRecordIsRunAgain) {
    const test::TempDir tmp;
    const fs::path exe = fakeFlowCommand(tmp.path());
    const nlohmann::json r = runFirstCaseWith(tmp.path(), exe, "DAMAGED", false);  // not quiet: the progress line reads the result too
    EXPECT_EQ(r.at("status"), "failed");
    EXPECT_NE(r.at("reason").get<std::string>().find("'observables.inclination_deg' is \"12.5\" (string)"), std::string::npos) << r;
    const fs::path file = tmp.path() / "out" / "cases" / (kCases[0].id + ".json");
    nlohmann::json record = nlohmann::json::parse(test::slurp(file));
    record["result"] = {{"status", "ok"}, {"observables", {{"inclination_deg", "12.5"}}}};
    test::writeText(file, record.dump());
    ValidationRunner R;
    configure(R, tmp.path() / "out", exe);
    R.runAll({kCases[0]});
    EXPECT_EQ(R.ranHere, 1);
    EXPECT_EQ(R.resultOf(kCases[0].id).at("status"), "ok");
    EXPECT_EQ(callCount(tmp.path()), 2);
}

}  // namespace
}  // namespace trbc
