// trbc under faults: concurrent runs on one output directory, SIGKILL of a driver with its child
// running, a full disk (an LD_PRELOAD write shim), corrupted checkpoints and caches, hostile names
// and configurations, and inputs that ask for unbounded work. docs/RELIABILITY.md lists the
// guarantee each test checks.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <sys/stat.h>
#include <string>
#include <thread>
#include <vector>

#include "analysis/calibrate_config.hpp"
#include "analysis/prediction.hpp"
#include "analysis/report.hpp"
#include "analysis/validation.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/simd.hpp"
#include "core/file_io.hpp"
#include "core/output_dir.hpp"
#include "core/version.hpp"
#include "inference/rbc_pipeline.hpp"
#include "inference/rbc_problem.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::CliRun;
using test::runTrbc;
using test::shellQuote;
using test::TempDir;
using test::writeText;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

/// Starts `trbc ARGS` in the background (stdout and stderr to `log`) and returns its pid.
pid_t startTrbc(const std::string& args, const fs::path& log, const fs::path& scratch) {
    const fs::path pidFile = scratch / "bg.pid";
    fs::remove(pidFile);
    const std::string cmd = "(" + shellQuote(TRBC_CLI) + " " + args + " > " + shellQuote(log.string()) + " 2>&1 < /dev/null & echo $! > " +
                            shellQuote(pidFile.string()) + ")";
    if (std::system(cmd.c_str()) != 0) return -1;
    for (int i = 0; i < 200 && test::slurp(pidFile).empty(); ++i) std::this_thread::sleep_for(10ms);
    return static_cast<pid_t>(std::stol(test::slurp(pidFile)));
}

bool alive(pid_t pid) {
    // A zombie (killed, not reaped by the shell that started it) counts as gone.
    const std::string stat = test::slurp(fs::path("/proc") / std::to_string(pid) / "stat");
    if (stat.empty()) return false;
    const auto close = stat.rfind(')');
    return close != std::string::npos && close + 2 < stat.size() && stat[close + 2] != 'Z';
}

/// The shell prefix that makes every write into `dir` fail with ENOSPC after `after` bytes.
std::string fullDisk(const fs::path& dir, long after) {
    return "env LD_PRELOAD=" + shellQuote(TRBC_ENOSPC_SHIM) + " TRBC_ENOSPC_DIR=" + shellQuote(dir.string()) +
           " TRBC_ENOSPC_AFTER=" + std::to_string(after) + " ";
}

// ---- one writer per output directory --------------------------------------------------------

TEST(OutputDirectoryContract, ASecondWriterIsRefusedAndNoLockStaysBehind) {
    TempDir tmp;
    const fs::path out = tmp.path() / "out";
    {
        const OutputDirectory first(out, "campaign");
        EXPECT_TRUE(fs::exists(out / kOutputLockName));
        try {
            const OutputDirectory second(out, "campaign");
            ADD_FAILURE() << "a second writer was let in";
        } catch (const InputError& e) {
            EXPECT_TRUE(contains(e.what(), "another trbc process (pid " + std::to_string(::getpid()) + ") is writing into")) << e.what();
        }
    }
    EXPECT_FALSE(fs::exists(out / kOutputLockName));
    EXPECT_TRUE(fs::exists(out / kOutputMarkerName));
    // A lock file left by a killed holder does not block.
    writeText(out / kOutputLockName, "999999");
    EXPECT_NO_THROW(OutputDirectory(out, "campaign"));
    // Another command's output, and a folder that trbc did not make, are refused.
    EXPECT_THROW(OutputDirectory(out, "infer"), InputError);
    writeText(tmp.path() / "mine" / "notes.txt", "keep me\n");
    try {
        const OutputDirectory foreign(tmp.path() / "mine", "validate");
        ADD_FAILURE() << "a foreign folder was accepted";
    } catch (const InputError& e) {
        EXPECT_TRUE(contains(e.what(), "notes.txt")) << e.what();
    }
    EXPECT_EQ(test::slurp(tmp.path() / "mine" / "notes.txt"), "keep me\n");
    // A run that fails before writing anything leaves no folder behind.
    try {
        const OutputDirectory fresh(tmp.path() / "fresh", "sobol");
        throw InputError("bad option");
    } catch (const InputError&) {
    }
    EXPECT_FALSE(fs::exists(tmp.path() / "fresh"));
}

TEST(OutputDirectoryContract, ConcurrentAtomicWritesNeverShareATemporary) {
    TempDir tmp;
    const fs::path file = tmp.path() / "record.json";
    std::vector<std::thread> writers;
    std::atomic<int> failures{0};
    for (int t = 0; t < 4; ++t)
        writers.emplace_back([&, t] {
            const std::string text(1000 + t, char('a' + t));
            for (int k = 0; k < 200; ++k) try {
                    writeFileAtomically(file, text);
                } catch (const std::exception&) {
                    ++failures;
                }
        });
    for (std::thread& w : writers) w.join();
    EXPECT_EQ(failures.load(), 0);
    const std::string text = test::slurp(file);
    ASSERT_GE(text.size(), 1000u);
    EXPECT_EQ(text, std::string(text.size(), text[0]));  // one writer's whole text
    int left = 0;
    for (const auto& e : fs::directory_iterator(tmp.path())) left += e.path().filename() != "record.json";
    EXPECT_EQ(left, 0) << "temporaries left behind";
}

TEST(OutputDirectoryContract, EveryWritingCommandRefusesAForeignFolder) {
    TempDir tmp;
    const fs::path foreign = tmp.path() / "foreign";
    writeText(foreign / "validation.md", "a user's notes\n");
    writeText(foreign / "shear.csv", "a user's table\n");
    const fs::path cfg = writeText(tmp.path() / "v.toml", "[run]\nlevel = 1\n[shear]\nrotations = 1\n"
                                                          "[[shear.angle]]\neta_out = 23.9\nrate_min = 40\nrate_max = 40\ncount = 1\n"
                                                          "[tube]\nenabled = false\n");
    const std::string out = " --out " + shellQuote(foreign.string());
    for (const std::string& args :
         {"validate --quiet --config " + shellQuote(cfg.string()) + out, "sobol --samples 2 --forces 2 --resamples 4 --no-plot" + out,
          "infer --phase 1 --samples 100 --quiet" + out, "campaign --samples 8 --forces-per-cell 4 --level 2 --no-cache" + out}) {
        const CliRun r = runTrbc(args, tmp.path());
        EXPECT_EQ(r.status, 2) << args << "\n" << r.err;
        EXPECT_TRUE(contains(r.err, "that `trbc ")) << args << "\n" << r.err;
    }
    EXPECT_EQ(test::slurp(foreign / "validation.md"), "a user's notes\n");
    EXPECT_EQ(test::slurp(foreign / "shear.csv"), "a user's table\n");
    // Its own folder again: accepted, and no lock file is left.
    const fs::path sobol = tmp.path() / "sobol";
    for (int k = 0; k < 2; ++k) {
        const CliRun r = runTrbc("sobol --samples 2 --forces 2 --resamples 4 --no-plot --out " + shellQuote(sobol.string()), tmp.path());
        EXPECT_EQ(r.status, 0) << r.err;
    }
    EXPECT_FALSE(fs::exists(sobol / kOutputLockName));
    const CliRun other = runTrbc("infer --phase 1 --samples 100 --quiet --out " + shellQuote(sobol.string()), tmp.path());
    EXPECT_EQ(other.status, 2);
    EXPECT_TRUE(contains(other.err, "holds the output of `trbc sobol`")) << other.err;
}

TEST(OutputDirectoryContract, ASecondCampaignResumeIntoARunningOneIsRefused) {
    TempDir tmp;
    const fs::path out = tmp.path() / "c";
    const auto campaign = [&](int forces) {
        return "campaign --samples 600 --forces-per-cell " + std::to_string(forces) + " --level 2 --seed 11 --threads 1 --out " +
               shellQuote(out.string());
    };
    const std::string args = campaign(3);
    const pid_t first = startTrbc(args, tmp.path() / "first.log", tmp.path());
    ASSERT_GT(first, 0);
    for (int i = 0; i < 500 && !fs::exists(out / "parts" / "rank0.csv"); ++i) std::this_thread::sleep_for(10ms);
    ASSERT_TRUE(fs::exists(out / "parts" / "rank0.csv")) << test::slurp(tmp.path() / "first.log");
    const CliRun second = runTrbc(args + " --resume", tmp.path());
    EXPECT_EQ(second.status, 2) << second.err;
    EXPECT_TRUE(contains(second.err, "another trbc process (pid " + std::to_string(first) + ") is writing into")) << second.err;
    EXPECT_TRUE(alive(first)) << test::slurp(tmp.path() / "first.log");
    ::kill(first, SIGKILL);
    for (int i = 0; i < 200 && alive(first); ++i) std::this_thread::sleep_for(10ms);
    // The lock file of the killed run does not block: the next run gets as far as its settings.
    const CliRun third = runTrbc(campaign(2) + " --resume", tmp.path());
    EXPECT_EQ(third.status, 2);
    EXPECT_TRUE(contains(third.err, "was made with different settings")) << third.err;
}

// ---- children die with their parent ---------------------------------------------------------

TEST(ChildProcesses, ASigkilledValidateTakesItsCaseWithItAndResumes) {
    TempDir tmp;
    const std::string head = "[run]\nlevel = 1\njobs = 1\n[shear]\n";
    const std::string cases = "[[shear.angle]]\neta_out = 23.9\nrate_min = 40\nrate_max = 40\ncount = 1\n[tube]\nenabled = false\n";
    const fs::path slow = writeText(tmp.path() / "slow.toml", head + "rotations = 1000\n" + cases);
    const fs::path quick = writeText(tmp.path() / "quick.toml", head + "rotations = 1\n" + cases);
    const fs::path out = tmp.path() / "o";
    const pid_t driver = startTrbc("validate --quiet --config " + shellQuote(slow.string()) + " --out " + shellQuote(out.string()),
                                   tmp.path() / "log", tmp.path());
    ASSERT_GT(driver, 0);
    const std::string caseDir = (out / "cases" / "angle_eta23.9_rate40").string();
    for (int i = 0; i < 500 && test::processesMentioning(caseDir) == 0; ++i) std::this_thread::sleep_for(10ms);
    ASSERT_GT(test::processesMentioning(caseDir), 0) << test::slurp(tmp.path() / "log");
    ::kill(driver, SIGKILL);
    int left = -1;
    for (int i = 0; i < 100; ++i) {
        std::this_thread::sleep_for(50ms);
        if ((left = test::processesMentioning(caseDir)) == 0) break;
    }
    EXPECT_EQ(left, 0) << "the case outlived its driver";
    const CliRun r = runTrbc("validate --quiet --config " + shellQuote(quick.string()) + " --out " + shellQuote(out.string()), tmp.path());
    EXPECT_EQ(r.status, 0) << r.err;
}

// ---- a full disk ----------------------------------------------------------------------------

TEST(FullDisk, ValidateStopsWithTheSystemMessageAndRecordsNoFailure) {
    TempDir tmp;
    const fs::path cfg = writeText(tmp.path() / "v.toml", "[run]\nlevel = 1\njobs = 1\n[shear]\nrotations = 1\n"
                                                          "[[shear.angle]]\neta_out = 23.9\nrate_min = 40\nrate_max = 40\ncount = 1\n"
                                                          "[tube]\nenabled = false\n");
    const fs::path out = tmp.path() / "o";
    const std::string id = "angle_eta23.9_rate40";
    const std::string args = "validate --quiet --config " + shellQuote(cfg.string()) + " --out " + shellQuote(out.string());
    CliRun r = test::runShell(fullDisk(out / "cases" / id, 64) + shellQuote(TRBC_CLI) + " " + args, tmp.path());
    EXPECT_EQ(r.status, 5) << r.err;
    EXPECT_TRUE(contains(r.err, "No space left on device")) << r.err;
    EXPECT_FALSE(fs::exists(out / "cases" / (id + ".json"))) << test::slurp(out / "cases" / (id + ".json"));
    // Room again: the case runs, and nothing was kept as a failure.
    r = runTrbc(args, tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const nlohmann::json rec = nlohmann::json::parse(test::slurp(out / "cases" / (id + ".json")));
    EXPECT_EQ(rec["result"]["status"], "ok");
}

TEST(FullDisk, CampaignStopsAtTheFirstFailedWriteWithTheSystemMessage) {
    TempDir tmp;
    const fs::path out = tmp.path() / "c";
    const std::string args = "campaign --samples 40 --forces-per-cell 4 --level 2 --seed 5 --no-cache --threads 1 --out " +
                             shellQuote(out.string());
    // The part file's header fits; the first cell's rows do not.
    const CliRun r = test::runShell(fullDisk(out / "parts", 200) + shellQuote(TRBC_CLI) + " " + args, tmp.path());
    EXPECT_EQ(r.status, 5) << r.err;
    EXPECT_TRUE(contains(r.err, "No space left on device")) << r.err;
    std::istringstream records(test::slurp(out / "equilibria" / "rank0.csv"));
    int lines = 0;
    for (std::string l; std::getline(records, l);) lines += !l.empty();
    EXPECT_LE(lines, 2) << "cells went on after the disk was full";
}

TEST(CacheDirectory, WithoutHomeTheCacheIsNamedNotCreatedInTheWorkingDirectory) {
    TempDir tmp;
    const CliRun r = test::runShell("env -u HOME -u XDG_CACHE_HOME -u TRBC_CACHE_DIR " + shellQuote(TRBC_CLI) +
                                        " sfs --v 0.95 --level 1 --out " + shellQuote((tmp.path() / "s.off").string()),
                                    tmp.path());
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_TRUE(contains(r.err, "--cache DIR")) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / ".trbc-cache"));
}

// ---- names that cannot break files ----------------------------------------------------------

TEST(HostileNames, DataSetNamesAreCheckedOnce) {
    TempDir tmp;
    const auto error = [&](const std::string& name) {
        const fs::path file = writeText(tmp.path() / "c.toml", "[[data]]\nname = \"" + name +
                                                                 "\"\nexperiment = \"stretching\"\nfile = "
                                                                 "\"@experiments/stretching/mills_2004/mills_2004.csv\"\n");
        try {
            readCalibrateConfig(file, test::experimentsDir());
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    for (const std::string& bad : {std::string("a,b"), std::string("a\\nb"), std::string("."), std::string(".."),
                                   std::string(253, 'x'), std::string("a|b"), std::string("a b")}) {
        const std::string e = error(bad);
        EXPECT_TRUE(contains(e, "data name")) << bad << ": " << e;
        EXPECT_TRUE(contains(e, "A-Z a-z 0-9 _ . -") || contains(e, "'.' and '..'")) << e;
    }
    EXPECT_EQ(error("mills_2004-copy.2"), "");
    EXPECT_NO_THROW(checkFileName(std::string(100, 'a'), "name"));
    EXPECT_THROW(checkFileName(std::string(101, 'a'), "name"), InputError);
}

TEST(HostileNames, CsvAndMarkdownWritersQuoteEveryTextField) {
    TempDir tmp;
    // Names that would add a column, a row or a table cell if written as they are.
    const std::vector<std::string> names = {"a,b", "c\nd", "e\"f", "g|h"};
    std::vector<PosteriorPrediction> predictions;
    for (const std::string& name : names) {
        PosteriorPrediction p;
        p.label = p.name = name;
        p.experiment = RbcExperiment::Stretching;
        p.haveData = true;
        p.coverage = {{"D0", 10.0, 5.0, 4.0, 5.0, 6.0}, {"D1", 20.0, 7.0, 6.0, 7.0, 8.0}};  // both inside
        predictions.push_back(p);
    }
    const fs::path out = tmp.path() / "out";
    fs::create_directories(out / "predict");
    writeCoverageCsv(out / "predict" / "coverage.csv", predictions);
    const auto rows = readCsvRecords(out / "predict" / "coverage.csv");
    ASSERT_EQ(rows.size(), 1 + 2 * names.size());
    for (std::size_t r = 1; r < rows.size(); ++r) {
        ASSERT_EQ(rows[r].size(), rows[0].size()) << r;
        EXPECT_EQ(rows[r][0], names[(r - 1) / 2]);
        EXPECT_EQ(rows[r][8], "1");
    }
    // One Markdown row per prediction, with the name's '|' escaped and its line break a space.
    const std::string md = coverageMarkdown(predictions);
    EXPECT_TRUE(contains(md, "| a,b | stretching |")) << md;
    EXPECT_TRUE(contains(md, "| c d | stretching |")) << md;
    EXPECT_TRUE(contains(md, "| g\\|h | stretching |")) << md;
    // The report counts what coverage.csv says: all 8 points inside.
    CalibrationReportInputs in;
    in.outputDirectory = out;
    in.configFile = writeText(tmp.path() / "c.toml", "");
    in.version = "test";
    EXPECT_NO_THROW(writeCalibrationReport(in));
    EXPECT_TRUE(contains(test::slurp(out / "report.md"), "**8 of 8**")) << test::slurp(out / "report.md");
    // Posterior statistics keep a name with a comma in one field.
    writePosteriorStats(out / "posterior_stats.csv", {{"x,y", "v", 1, 1, 1, 1, 0.1, 0.9, 1.1}});
    const NumericTable stats = readNumericTable(out / "posterior_stats.csv", {"mean", "q95"});
    ASSERT_EQ(stats.values.rows(), 1);
    EXPECT_EQ(readCsvRecords(out / "posterior_stats.csv").at(1).at(0), "x,y");
    EXPECT_DOUBLE_EQ(stats.column("q95")[0], 1.1);
    // csvRow and the reader are inverse for any text.
    const std::vector<std::string> hostile = {"", " lead", "a,b", "\"q\"", "line\nbreak", "cr\r\nlf", "#x"};
    EXPECT_EQ(parseCsvRecords("h\n" + csvRow(hostile)).at(1), hostile);
    EXPECT_EQ(parseCsvRecords("h\n" + csvRow({"#x", "y"})).at(1), (std::vector<std::string>{"#x", "y"}));
}

TEST(HostileNames, InferManifestNamesAreChecked) {
    TempDir tmp;
    const fs::path dir = tmp.path() / "data";
    fs::create_directories(dir);
    fs::copy_file(test::experimentsDir() / "stretching" / "mills_2004" / "mills_2004.csv", dir / "m.csv");
    for (const std::string& bad : {std::string("a,b"), std::string(".."), std::string(101, 'x')}) {
        writeText(dir / "datasets.json", nlohmann::json::array({{{"name", bad}, {"experiment", "stretching"}, {"file", "m.csv"}}}).dump());
        try {
            loadRbcDataSets(dir);
            ADD_FAILURE() << bad << " accepted";
        } catch (const InputError& e) {
            EXPECT_TRUE(contains(e.what(), "datasets.json")) << e.what();
            EXPECT_TRUE(contains(e.what(), "data set name")) << e.what();
            EXPECT_TRUE(contains(e.what(), "A-Z a-z 0-9 _ . -") || contains(e.what(), "'.' and '..'")) << e.what();
        }
    }
    writeText(dir / "datasets.json", nlohmann::json::array({{{"name", "m-1.x"}, {"experiment", "stretching"}, {"file", "m.csv"}}}).dump());
    EXPECT_EQ(loadRbcDataSets(dir).at(0).name, "m-1.x");
}

TEST(Provenance, EveryCsvTableOpensWithVersionRevisionCommandAndSeed) {
    TempDir tmp;
    // A table written by the CLI names the command that wrote it.
    const fs::path forces = tmp.path() / "f.csv";
    const CliRun r = runTrbc("forces --mesh " + shellQuote(test::meshPath("rbc_498.off")) + " --kb 1 --out " + shellQuote(forces.string()),
                             tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string text = test::slurp(forces);
    const std::string first = text.substr(0, text.find('\n'));
    EXPECT_TRUE(first.starts_with(fmt::format("# trbc {} (", kVersion))) << first;
    EXPECT_TRUE(contains(first, "| command: ") && contains(first, " forces --mesh ")) << first;
    EXPECT_TRUE(contains(first, "| seed: n/a")) << first;
    EXPECT_FALSE(std::string(gitDescribe()).empty());
    EXPECT_EQ(readNumericTable(forces).columns, (std::vector<std::string>{"fx", "fy", "fz"}));  // readers skip it
    // A seeded run names its seed; a line break in an argument stays inside the comment line.
    setProvenanceCommand("trbc infer --seed 7 --out a\nb");
    setProvenanceSeed(7);
    writePosteriorStats(tmp.path() / "s.csv", {{"p", "v", 1, 1, 1, 1, 0.1, 0.9, 1.1}});
    const std::string stats = test::slurp(tmp.path() / "s.csv");
    EXPECT_TRUE(stats.starts_with(fmt::format("# trbc {} ({}) | command: trbc infer --seed 7 --out a b | seed: 7 | build: {}\nposterior,parameter,",
                                              kVersion, gitDescribe(), simd::buildTarget())))
        << stats;
    EXPECT_EQ(readCsvRecords(tmp.path() / "s.csv").size(), 2u);
    setProvenanceCommand("trbc");
}

TEST(HostileNames, CaseIdsAreUniqueForDistinctInputs) {
    const std::vector<ValidationCase> none;
    EXPECT_EQ(uniqueShearCaseId("angle", 23.9, 20.0, none), "angle_eta23.9_rate20");  // short where it can be
    std::vector<ValidationCase> cases = {{uniqueShearCaseId("angle", 23.9, 20.001, none), "angle", 23.9, 20.001}};
    const std::string close = uniqueShearCaseId("angle", 23.9, 20.002, cases);
    EXPECT_NE(close, cases[0].id);
    EXPECT_EQ(uniqueShearCaseId("angle", 23.9, 20.001, cases), cases[0].id);  // the same input keeps its id
    // Two sweeps whose rates agree to four digits give two cases.
    ValidationConfig c;
    c.tubeEnabled = false;
    c.sweeps = {{.kind = "angle", .etaOut = 23.9, .rateMin = 20.001, .rateMax = 20.001, .count = 1},
                {.kind = "angle", .etaOut = 23.9, .rateMin = 20.002, .rateMax = 20.002, .count = 1}};
    const std::vector<ValidationCase> all = initialValidationCases(c);
    ASSERT_EQ(all.size(), 2u);
    EXPECT_NE(all[0].id, all[1].id);
}

// ---- corrupted caches -----------------------------------------------------------------------

TEST(CorruptedCache, EditedSfsMetadataIsRejectedAndAFifoDoesNotHang) {
    TempDir tmp;
    const fs::path cache = tmp.path() / "cache";
    const std::string args = "sfs --v 0.7 --level 1 --cache " + shellQuote(cache.string()) + " --out " + shellQuote((tmp.path() / "s.off").string());
    CliRun r = runTrbc(args, tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    fs::path meta, off;
    for (const auto& e : fs::directory_iterator(cache)) (e.path().extension() == ".json" ? meta : off) = e.path();
    ASSERT_FALSE(meta.empty());
    std::string text = test::slurp(meta);
    const auto at = text.find("\"converged\": true");
    ASSERT_NE(at, std::string::npos) << text;
    text.replace(at, 17, "\"converged\": false");
    writeText(meta, text);
    r = runTrbc(args, tmp.path());
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "metadata checksum mismatch")) << r.err;
    EXPECT_TRUE(contains(test::slurp(meta), "\"converged\": true"));  // rebuilt
    // A FIFO in place of the mesh: skipped, not read.
    fs::remove(off);
    ASSERT_EQ(::mkfifo(off.c_str(), 0644), 0);
    r = test::runShell("timeout 60 " + shellQuote(TRBC_CLI) + " " + args, tmp.path());
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "not a regular file")) << r.err;
}

// ---- bounded work from bounded input --------------------------------------------------------

TEST(BoundedWork, AllocationBombsExitTwoQuicklyUnderAMemoryLimit) {
    TempDir tmp;
    // A surrogate directory whose relaxation network claims a million-wide hidden layer.
    const fs::path model = tmp.path() / "model";
    fs::copy(test::sourceRoot() / "data" / "surrogates", model, fs::copy_options::recursive);
    writeText(model / "relaxation.json", R"({"format":"trbc-mlp","version":1,"activation":"tanh","layer_sizes":[3,1048576,60,3],)"
                                         R"("weights":[[],[],[]],"biases":[[],[],[]]})");
    const fs::path in = writeText(tmp.path() / "in.csv", "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN\n0.95,4,250,1.5,0.7,100\n");
    std::string deep = "[a";
    for (int k = 0; k < 60000; ++k) deep += ".a";
    const fs::path deepToml = writeText(tmp.path() / "deep.toml", deep + "]\nx = 1\n");
    const fs::path bigToml = writeText(tmp.path() / "big.toml", "note = \"" + std::string(5u << 20, 'x') + "\"\n");
    struct Bomb {
        std::string args, message;
    };
    const std::string out = " --out " + shellQuote((tmp.path() / "o").string());
    const std::vector<Bomb> bombs = {
        {"surrogate eval --model " + shellQuote(model.string()) + " --in " + shellQuote(in.string()) + out, "weights"},
        {"sobol --samples 16777216 --no-plot" + out, "2^27"},
        {"infer --samples 100000000" + out, "[100, 1e6]"},
        {"surrogate train --data " + shellQuote(tmp.path().string()) + " --distill-samples 1e8" + out, "--distill-samples"},
        {"flow shear --eta-out 23.9 --shear-rate 10 --rotations 1000 --frame-interval 1e-6 --level 1 --no-cache" + out, "saved frames"},
        {"validate --config " + shellQuote(deepToml.string()) + out, "nested deeper than 32"},
        {"calibrate --config " + shellQuote(deepToml.string()) + out, "nested deeper than 32"},
        {"validate --config " + shellQuote(bigToml.string()) + out, "more than the limit of 4 MiB"},
        {"mesh icosphere --level 1 --area 1e-300 --out " + shellQuote((tmp.path() / "m.vtk").string()), "[1e-100, 1e100]"},
    };
    for (const Bomb& b : bombs) {
        const auto t0 = std::chrono::steady_clock::now();
        const CliRun r = test::runShell("ulimit -v 2000000; exec " + shellQuote(TRBC_CLI) + " " + b.args, tmp.path());
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        EXPECT_EQ(r.status, 2) << b.args << "\n" << r.err;
        EXPECT_TRUE(contains(r.err, b.message)) << b.args << "\n" << r.err;
        EXPECT_LT(seconds, 30.0) << b.args;
    }
    EXPECT_FALSE(fs::exists(tmp.path() / "m.vtk"));
}

}  // namespace
}  // namespace trbc
