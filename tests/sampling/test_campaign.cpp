// The campaign runner (docs/CAMPAIGN_AND_SURROGATE.md, campaign): designs, the table format, failure records, and
// resume after SIGKILL giving the same final table as an uninterrupted run.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <map>
#include <sstream>
#include <functional>
#include <thread>

#include "core/error.hpp"
#include "sampling/campaign.hpp"
#include "sampling/campaign_table.hpp"
#include "sampling/design.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::CliRun;
using test::runShell;
using test::runTrbc;
using test::shellQuote;
using test::TempDir;

// --- Designs ---------------------------------------------------------------------------------------

TEST(CampaignDesign, LatinHypercubeHasOnePointPerStratum) {
    const long n = 97;
    const Eigen::MatrixXd u = unitDesign(DesignKind::LatinHypercube, n, 6, 3);
    for (int j = 0; j < 6; ++j) {
        std::vector<int> count(n, 0);
        for (long i = 0; i < n; ++i) {
            ASSERT_GE(u(i, j), 0.0);
            ASSERT_LT(u(i, j), 1.0);
            ++count[long(u(i, j) * n)];
        }
        EXPECT_TRUE(std::all_of(count.begin(), count.end(), [](int c) { return c == 1; })) << "column " << j;
    }
}

TEST(CampaignDesign, UniformDesignIsSeededAndExtendsAsAPrefix) {
    const Eigen::MatrixXd a = unitDesign(DesignKind::Uniform, 50, 5, 11);
    const Eigen::MatrixXd b = unitDesign(DesignKind::Uniform, 80, 5, 11);
    const Eigen::MatrixXd c = unitDesign(DesignKind::Uniform, 50, 5, 12);
    EXPECT_EQ(a, b.topRows(50));
    EXPECT_NE(a, c);
    // Mean of U[0,1) over 4000 values: sd of the mean 0.0046, tolerance 4.5 sd.
    const Eigen::MatrixXd big = unitDesign(DesignKind::Uniform, 800, 5, 5);
    EXPECT_NEAR(big.mean(), 0.5, 0.021);
}

TEST(CampaignDesign, CellsShareParametersAndCoverTheBox) {
    const auto pts = campaignDesign(DesignKind::LatinHypercube, 103, 10, 9);
    ASSERT_EQ(pts.size(), 103u);
    EXPECT_EQ(pts.back().cellId, 10);  // 11 cells, the last one with 3 rows
    for (const CampaignPoint& q : pts) {
        const CampaignPoint& first = pts[q.cellId * 10];
        EXPECT_EQ(q.p.v, first.p.v);
        EXPECT_EQ(q.p.mu, first.p.mu);
        EXPECT_EQ(q.p.etam, first.p.etam);
        EXPECT_NO_THROW(validateCellParameters(q.p, false));
        EXPECT_NO_THROW(validateForce(q.fext, false));
    }
    // The forces form a 1-D Latin hypercube over all rows: one per stratum of width 200/103 pN.
    std::vector<int> count(103, 0);
    for (const CampaignPoint& q : pts) ++count[long(q.fext / 200.0 * 103)];
    EXPECT_TRUE(std::all_of(count.begin(), count.end(), [](int c) { return c == 1; }));
}

TEST(CampaignDesign, ReferenceDesignIsSixDimensionalUniform) {
    const auto pts = campaignDesign(DesignKind::Uniform, 20, 1, 4);
    const Eigen::MatrixXd u = unitDesign(DesignKind::Uniform, 20, 6, 4);
    for (long i = 0; i < 20; ++i) {
        EXPECT_EQ(pts[i].cellId, i);
        EXPECT_DOUBLE_EQ(pts[i].p.v, 0.65 + 0.35 * u(i, 0));
        EXPECT_DOUBLE_EQ(pts[i].fext, 200.0 * u(i, 5));
    }
}

TEST(CampaignDesign, RejectsBadSizes) {
    EXPECT_THROW(campaignDesign(DesignKind::Uniform, 0, 1, 1), InputError);
    EXPECT_THROW(campaignDesign(DesignKind::Uniform, 10, 0, 1), InputError);
    EXPECT_THROW(parseDesignKind("halton"), InputError);
}

// --- Table -----------------------------------------------------------------------------------------

TEST(CampaignTable, RoundTripIsBitExact) {
    TempDir tmp;
    CampaignRow r;
    r.point = campaignDesign(DesignKind::Uniform, 3, 1, 2)[2];
    r.seed = 2;
    r.D = 7.8123456789012345, r.hmin = 0.1 + 1e-16, r.hmax = 2.5, r.D0 = 5.0 / 3.0, r.D1 = 13.0, r.tc = std::nextafter(0.2, 1.0);
    CampaignRow f = r;
    f.point.sampleId = 3;
    f.tc = NAN;
    f.status = "failed";
    f.reason = csvSafe("relaxation: fit, did not\nconverge");
    const fs::path p = tmp.path() / "t.csv";
    std::ofstream(p) << campaignCsvHeader() << '\n' << formatCampaignRow(r) << '\n' << formatCampaignRow(f) << '\n';
    const auto rows = readCampaignCsv(p);
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(rows[0].point.p.FvK, r.point.p.FvK);
    EXPECT_EQ(rows[0].point.fext, r.point.fext);
    EXPECT_EQ(rows[0].hmin, r.hmin);
    EXPECT_EQ(rows[0].D0, r.D0);
    EXPECT_EQ(rows[0].tc, r.tc);
    EXPECT_TRUE(std::isnan(rows[1].tc));
    EXPECT_EQ(rows[1].reason, "relaxation: fit; did not converge");
}

TEST(CampaignTable, MalformedTablesNameFileAndLine) {
    TempDir tmp;
    CampaignRow r;
    r.point = campaignDesign(DesignKind::Uniform, 1, 1, 2)[0];
    const std::string good = formatCampaignRow(r);
    auto expectError = [&](const std::string& body, const std::string& phrase) {
        const fs::path p = tmp.path() / "bad.csv";
        std::ofstream(p) << body;
        try {
            readCampaignCsv(p);
            ADD_FAILURE() << "accepted: " << body;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(phrase), std::string::npos) << e.what();
        }
    };
    expectError("v,mu\n", "bad.csv:1: not a campaign table header");
    expectError(campaignCsvHeader() + "\n" + good + "\n1,2,3\n", "bad.csv:3: 3 fields, expected 18");
    std::string nonNumeric = good;
    nonNumeric.replace(nonNumeric.find(',', nonNumeric.find(',', nonNumeric.find(',') + 1) + 1) + 1, 1, "x");
    expectError(campaignCsvHeader() + "\n" + nonNumeric + "\n", "bad.csv:2: column v");
    expectError("", "empty file");
}

// --- Runner ----------------------------------------------------------------------------------------

/// The table without the wall_s column (timings differ between runs).
std::vector<std::string> rowsWithoutWallTime(const fs::path& samples) {
    std::vector<std::string> out;
    std::ifstream in(samples);
    std::string line;
    while (std::getline(in, line))
        if (!line.starts_with('#')) out.push_back(line.substr(0, line.rfind(',')));  // not the provenance line
    return out;
}

long countLines(const fs::path& p) {
    std::ifstream in(p);
    return std::count(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>(), '\n');
}

const std::string kTiny = "--samples 160 --forces-per-cell 4 --level 2 --seed 5 --no-cache --inject-failures 13";

long dataLines(const fs::path& part) { return fs::exists(part) ? countLines(part) - 1 : 0; }

/// Runs `trbc campaign kTiny --threads 1 --out dir` in one process and kills it with SIGKILL once
/// `cells` cells (4 rows each) are in its part file; false if it could not start or finished before.
bool killedAfterCells(const fs::path& dir, long cells) {
    const std::string cmd = std::string("exec ") + shellQuote(TRBC_CLI) + " campaign " + kTiny + " --threads 1 --out " +
                            shellQuote(dir.string()) + " >/dev/null 2>&1";
    const pid_t pid = fork();
    if (pid < 0) return false;
    if (pid == 0) {
        execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
        _exit(127);
    }
    const fs::path part = dir / "parts" / "rank0.csv";
    const auto t0 = std::chrono::steady_clock::now();
    while (dataLines(part) < 4 * cells && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60))
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    ::kill(pid, SIGKILL);
    int status = 0;
    ::waitpid(pid, &status, 0);
    return WIFSIGNALED(status);
}

TEST(CampaignRunner, ResumeAfterSigkillGivesTheUninterruptedTable) {
    TempDir tmp;
    const fs::path a = tmp.path() / "a", b = tmp.path() / "b";
    const CliRun full = runTrbc("campaign " + kTiny + " --threads 2 --out " + shellQuote(a.string()), tmp.path());
    ASSERT_EQ(full.status, 0) << full.err;

    // The same campaign, killed with SIGKILL once some cells are written.
    ASSERT_TRUE(killedAfterCells(b, 8)) << "the run finished before it could be killed";
    const fs::path part = b / "parts" / "rank0.csv";
    EXPECT_FALSE(fs::exists(b / "samples.csv"));
    const long before = countLines(part) - 1;
    EXPECT_LT(before, 160);
    // A torn last line, as a kill in the middle of a write would leave it.
    std::ofstream(part, std::ios::app) << "999,249,5,0.9,3";

    const CliRun again = runTrbc("campaign " + kTiny + " --threads 2 --out " + shellQuote(b.string()), tmp.path());
    EXPECT_EQ(again.status, 2) << "an existing campaign must not be overwritten without --resume";
    EXPECT_NE(again.err.find("add --resume"), std::string::npos) << again.err;

    const CliRun resumed = runTrbc("campaign " + kTiny + " --threads 2 --resume --out " + shellQuote(b.string()), tmp.path());
    ASSERT_EQ(resumed.status, 0) << resumed.err;
    // No finished cell was repeated: the resumed run computed only what was missing.
    EXPECT_NE(resumed.out.find(fmt::format("resumed: {};", before / 4)), std::string::npos) << resumed.out;
    EXPECT_EQ(rowsWithoutWallTime(a / "samples.csv"), rowsWithoutWallTime(b / "samples.csv"));

    // Failures are kept with their reason: the injected cell (rows 12..15), nothing dropped.
    const auto rows = readCampaignCsv(b / "samples.csv");
    ASSERT_EQ(rows.size(), 160u);
    for (const CampaignRow& r : rows) {
        EXPECT_EQ(r.point.sampleId, &r - rows.data());
        if (r.point.cellId == 3) {
            EXPECT_EQ(r.status, "failed");
            EXPECT_EQ(r.reason, "equilibrium: injected failure (--inject-failures)");
            EXPECT_TRUE(std::isnan(r.D));
        } else {
            EXPECT_EQ(r.status, "ok") << r.reason;
            EXPECT_TRUE(std::isfinite(r.tc));
        }
    }
}

#ifdef TRBC_MPIEXEC
/// `mpiexec -n P trbc campaign ...` (built with OpenMPI): root allowed, as in CI containers, and
/// oversubscription allowed, since ctest runs tests side by side on few cores.
/// `timeout` turns a hang (ranks waiting in different collective calls) into a failure.
std::string mpiCampaign(int ranks, const std::string& args) {
    return fmt::format("OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 "
                       "timeout 120 {} -n {} {} campaign {}",
                       shellQuote(TRBC_MPIEXEC), ranks, shellQuote(TRBC_CLI), args);
}

// The same campaign run by one process, by two MPI ranks, and killed in one process then resumed
// by two ranks (a cluster job cut off at its wall time and resubmitted on another node count)
// ends with the same table.
TEST(CampaignMpi, TwoRanksGiveTheOneProcessTableAndResumeAKilledRun) {
    TempDir tmp;
    const fs::path one = tmp.path() / "one", two = tmp.path() / "two", cut = tmp.path() / "cut";
    const CliRun single = runTrbc("campaign " + kTiny + " --threads 2 --out " + shellQuote(one.string()), tmp.path());
    ASSERT_EQ(single.status, 0) << single.err;

    const CliRun ranks2 = runShell(mpiCampaign(2, kTiny + " --threads 1 --out " + shellQuote(two.string())), tmp.path());
    ASSERT_EQ(ranks2.status, 0) << ranks2.out << ranks2.err;
    // Cells are dealt round robin: each rank wrote its 20 cells (80 rows) to its own part file.
    EXPECT_EQ(dataLines(two / "parts" / "rank0.csv"), 80);
    EXPECT_EQ(dataLines(two / "parts" / "rank1.csv"), 80);
    EXPECT_EQ(rowsWithoutWallTime(one / "samples.csv"), rowsWithoutWallTime(two / "samples.csv"));
    EXPECT_EQ(nlohmann::json::parse(std::ifstream(two / "campaign.json")).at("ranks"), 2);

    ASSERT_TRUE(killedAfterCells(cut, 8)) << "the run finished before it could be killed";
    const fs::path part0 = cut / "parts" / "rank0.csv";
    const long before = dataLines(part0);
    ASSERT_LT(before, 160);

    const CliRun resumed =
        runShell(mpiCampaign(2, kTiny + " --threads 1 --resume --out " + shellQuote(cut.string())), tmp.path());
    ASSERT_EQ(resumed.status, 0) << resumed.out << resumed.err;
    EXPECT_EQ(rowsWithoutWallTime(one / "samples.csv"), rowsWithoutWallTime(cut / "samples.csv"));
    // Nothing was computed twice: the rows written after the resume are exactly the missing ones.
    EXPECT_EQ(dataLines(part0) + dataLines(cut / "parts" / "rank1.csv"), 160) << "before the kill: " << before;
    const auto provenance = nlohmann::json::parse(std::ifstream(cut / "campaign.json"));
    EXPECT_EQ(provenance.at("ranks"), 1);
    EXPECT_EQ(provenance.at("resumed_by").back().at("ranks"), 2);

    // Refusals reach every rank: a resume with other settings, and a finished campaign run again
    // without --resume, exit with 2 naming the reason instead of leaving rank 1 waiting.
    const CliRun other = runShell(mpiCampaign(2, kTiny + " --threads 1 --resume --cell-time-limit 100 --out " +
                                                     shellQuote(cut.string())),
                                  tmp.path());
    EXPECT_EQ(other.status, 2) << other.out << other.err;
    EXPECT_NE(other.err.find("cell_time_limit_s"), std::string::npos) << other.err;
    const CliRun again = runShell(mpiCampaign(2, kTiny + " --threads 1 --out " + shellQuote(cut.string())), tmp.path());
    EXPECT_EQ(again.status, 2) << again.out << again.err;
    EXPECT_NE(again.err.find("add --resume"), std::string::npos) << again.err;
    EXPECT_EQ(rowsWithoutWallTime(one / "samples.csv"), rowsWithoutWallTime(cut / "samples.csv"));
}
#endif

// A cell over its wall-time budget becomes failed rows with the reason, never a hang or a silent
// gap: with a budget far below one equilibrium, every row fails at the equilibrium.
TEST(CampaignRunner, CellTimeLimitFailsRowsWithTheReason) {
    TempDir tmp;
    const fs::path out = tmp.path() / "c";
    const CliRun r = runTrbc("campaign --samples 8 --forces-per-cell 4 --level 2 --seed 5 --no-cache --cell-time-limit 1e-9 "
                             "--out " + shellQuote(out.string()), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("8 of 8 samples done (0 ok, 8 failed)"), std::string::npos) << r.out;
    for (const CampaignRow& row : readCampaignCsv(out / "samples.csv")) {
        EXPECT_EQ(row.status, "failed");
        EXPECT_EQ(row.reason.rfind("equilibrium: ", 0), 0u) << row.reason;
        EXPECT_NE(row.reason.find("time limit reached"), std::string::npos) << row.reason;
        EXPECT_TRUE(std::isnan(row.D) && std::isnan(row.tc));
    }
    const auto provenance = nlohmann::json::parse(std::ifstream(out / "campaign.json"));
    EXPECT_EQ(provenance.at("settings").at("cell_time_limit_s"), 1e-9);
    // Another budget is another campaign: the resume is refused, naming the setting.
    const CliRun again = runTrbc("campaign --samples 8 --forces-per-cell 4 --level 2 --seed 5 --no-cache --resume "
                                 "--out " + shellQuote(out.string()), tmp.path());
    EXPECT_EQ(again.status, 2);
    EXPECT_NE(again.err.find("cell_time_limit_s"), std::string::npos) << again.err;
}

// The equilibrium's symmetry (docs/EQUILIBRIUM.md "Two equilibria near v = 1") is part of the
// settings: the default (lowest) records its seed and kicks; campaigns of the symmetric disc resume
// only with --equilibrium-symmetry inversion, those made before the option (no key) only with none,
// and a campaign of one kind never continues with another.
TEST(CampaignRunner, EquilibriumSymmetryIsASettingThatOldCampaignsResumeWith) {
    TempDir tmp;
    const std::string base = "campaign --samples 4 --forces-per-cell 2 --level 2 --seed 5 --no-cache ";
    const fs::path lowest = tmp.path() / "lowest", sym = tmp.path() / "sym", old = tmp.path() / "old";
    ASSERT_EQ(runTrbc(base + "--out " + shellQuote(lowest.string()), tmp.path()).status, 0);
    const auto settings = nlohmann::json::parse(std::ifstream(lowest / "campaign.json")).at("settings");
    EXPECT_EQ(settings.at("equilibrium_symmetry"), "lowest");
    EXPECT_EQ(settings.at("equilibrium_seed"), ExperimentOptions{}.kicks.seed);
    EXPECT_EQ(settings.at("equilibrium_kicks"), ExperimentOptions{}.kicks.perRound);
    const CliRun otherSeed = runTrbc(base + "--resume --equilibrium-seed 1 --out " + shellQuote(lowest.string()), tmp.path());
    EXPECT_EQ(otherSeed.status, 2);
    EXPECT_NE(otherSeed.err.find("equilibrium_seed"), std::string::npos) << otherSeed.err;

    ASSERT_EQ(runTrbc(base + "--equilibrium-symmetry inversion --out " + shellQuote(sym.string()), tmp.path()).status, 0);
    const auto symSettings = nlohmann::json::parse(std::ifstream(sym / "campaign.json")).at("settings");
    EXPECT_EQ(symSettings.at("equilibrium_symmetry"), "inversion");
    EXPECT_FALSE(symSettings.contains("equilibrium_seed"));
    const CliRun symRefused = runTrbc(base + "--resume --out " + shellQuote(sym.string()), tmp.path());
    EXPECT_EQ(symRefused.status, 2);
    EXPECT_NE(symRefused.err.find("equilibrium_symmetry"), std::string::npos) << symRefused.err;
    const CliRun symResumed = runTrbc(base + "--resume --equilibrium-symmetry inversion --out " + shellQuote(sym.string()), tmp.path());
    EXPECT_EQ(symResumed.status, 0) << symResumed.err;

    const CliRun none = runTrbc(base + "--equilibrium-symmetry none --out " + shellQuote(old.string()), tmp.path());
    ASSERT_EQ(none.status, 0) << none.err;
    EXPECT_FALSE(nlohmann::json::parse(std::ifstream(old / "campaign.json")).at("settings").contains("equilibrium_symmetry"));
    const CliRun refused = runTrbc(base + "--resume --out " + shellQuote(old.string()), tmp.path());
    EXPECT_EQ(refused.status, 2);
    EXPECT_NE(refused.err.find("equilibrium_symmetry"), std::string::npos) << refused.err;
    EXPECT_EQ(runTrbc(base + "--resume --equilibrium-symmetry none --out " + shellQuote(old.string()), tmp.path()).status, 0);
    const CliRun bad = runTrbc(base + "--equilibrium-symmetry mirror --out " + shellQuote((tmp.path() / "bad").string()), tmp.path());
    EXPECT_NE(bad.status, 0);
    EXPECT_NE(bad.err.find("--equilibrium-symmetry"), std::string::npos) << bad.err;
    const CliRun badKicks = runTrbc(base + "--equilibrium-kicks 0 --out " + shellQuote((tmp.path() / "bad").string()), tmp.path());
    EXPECT_EQ(badKicks.status, 2);
    EXPECT_NE(badKicks.err.find("--equilibrium-kicks"), std::string::npos) << badKicks.err;
}

/// Rewrites a finished campaign's samples.csv after `edit` changed its rows.
void editSamples(const fs::path& dir, const std::function<void(std::vector<CampaignRow>&)>& edit) {
    auto rows = readCampaignCsv(dir / "samples.csv");
    edit(rows);
    std::ofstream out(dir / "samples.csv");
    out << campaignCsvHeader() << "\n";
    for (const CampaignRow& r : rows) out << formatCampaignRow(r) << "\n";
}

// --reuse-from: a campaign of the lowest-energy equilibrium that takes the stretching and relaxation of
// an earlier campaign of the symmetric disc gives the table of a run without it. At level 2 the kicks
// find lower states in cells 6-8 of this design, which must be computed in full; a donor cell whose
// equilibrium differs (tampered D) is computed in full too, and a donor cell that matches is really
// taken over (its tampered D0 shows).
TEST(CampaignRunner, ReuseFromASymmetricCampaignGivesTheTableOfAFullRun) {
    TempDir tmp;
    const std::string base = "campaign --samples 10 --forces-per-cell 1 --level 2 --seed 5 --no-cache --threads 2 ";
    const fs::path sym = tmp.path() / "sym", fresh = tmp.path() / "fresh", reuse = tmp.path() / "reuse";
    ASSERT_EQ(runTrbc(base + "--equilibrium-symmetry inversion --out " + shellQuote(sym.string()), tmp.path()).status, 0);
    ASSERT_EQ(runTrbc(base + "--out " + shellQuote(fresh.string()), tmp.path()).status, 0);
    editSamples(sym, [](std::vector<CampaignRow>& rows) { rows[0].D *= 1.0 + 1e-15; });
    const CliRun run = runTrbc(base + "--reuse-from " + shellQuote(sym.string()) + " --out " + shellQuote(reuse.string()), tmp.path());
    ASSERT_EQ(run.status, 0) << run.err;
    EXPECT_EQ(rowsWithoutWallTime(fresh / "samples.csv"), rowsWithoutWallTime(reuse / "samples.csv"));

    // equilibria.csv: cell_id,v,FvK,branch,energy_gap_J,reused
    std::ifstream in(reuse / "equilibria.csv");
    std::string line;
    ASSERT_TRUE(std::getline(in, line));
    EXPECT_TRUE(line.starts_with("# trbc ")) << line;  // the provenance line
    ASSERT_TRUE(std::getline(in, line));
    EXPECT_EQ(line, "cell_id,v,FvK,branch,energy_gap_J,reused");
    long cells = 0, kicked = 0, reused = 0;
    while (std::getline(in, line)) {
        std::vector<std::string> f;
        std::istringstream fields(line);
        for (std::string x; std::getline(fields, x, ',');) f.push_back(x);
        ASSERT_EQ(f.size(), 6u) << line;
        const bool isKicked = f[3] == "kicked", isReused = f[5] == "1";
        ++cells;
        kicked += isKicked;
        reused += isReused;
        EXPECT_TRUE(isKicked || f[3] == "symmetric") << line;
        EXPECT_EQ(std::stod(f[4]) > 0.0, isKicked) << line;
        EXPECT_EQ(isReused, !isKicked && f[0] != "0") << line;
    }
    EXPECT_EQ(cells, 10);
    EXPECT_EQ(kicked, 3);
    EXPECT_EQ(reused, 6);
    const auto j = nlohmann::json::parse(std::ifstream(reuse / "campaign.json"));
    EXPECT_EQ(j.at("cells_reused"), 6);
    EXPECT_EQ(j.at("equilibrium_branches").at("kicked"), 3);
    EXPECT_EQ(j.at("reuse_from"), sym.string());

    // A reused cell carries the donor's outputs, not a recomputation.
    editSamples(sym, [](std::vector<CampaignRow>& rows) { rows[1].D0 += 0.5; });
    const fs::path again = tmp.path() / "again";
    ASSERT_EQ(runTrbc(base + "--reuse-from " + shellQuote(sym.string()) + " --out " + shellQuote(again.string()), tmp.path()).status, 0);
    const auto a = readCampaignCsv(again / "samples.csv"), f = readCampaignCsv(fresh / "samples.csv");
    EXPECT_EQ(a[1].D0, f[1].D0 + 0.5);

    // The donor must be this design with the symmetric disc.
    const CliRun otherSeed = runTrbc("campaign --samples 10 --forces-per-cell 1 --level 2 --seed 6 --no-cache --reuse-from " +
                                     shellQuote(sym.string()) + " --out " + shellQuote((tmp.path() / "x").string()), tmp.path());
    EXPECT_EQ(otherSeed.status, 2);
    EXPECT_NE(otherSeed.err.find("seed"), std::string::npos) << otherSeed.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "x" / "campaign.json"));
    const CliRun lowestDonor = runTrbc(base + "--reuse-from " + shellQuote(fresh.string()) + " --out " +
                                       shellQuote((tmp.path() / "y").string()), tmp.path());
    EXPECT_EQ(lowestDonor.status, 2);
    EXPECT_NE(lowestDonor.err.find("equilibrium_symmetry"), std::string::npos) << lowestDonor.err;
    const CliRun notLowest = runTrbc(base + "--equilibrium-symmetry inversion --reuse-from " + shellQuote(sym.string()) +
                                     " --out " + shellQuote((tmp.path() / "z").string()), tmp.path());
    EXPECT_EQ(notLowest.status, 2);
    EXPECT_NE(notLowest.err.find("--reuse-from"), std::string::npos) << notLowest.err;
}

// A cell is taken whole from one part file: a run killed mid-write and resumed by other ranks can
// leave the start of a cell in one file and the whole recomputed cell in another.
TEST(CampaignRunner, ACellIsNeverMixedFromTwoPartFiles) {
    TempDir tmp;
    const fs::path a = tmp.path() / "a", b = tmp.path() / "b";
    const CliRun full = runTrbc("campaign " + kTiny + " --threads 2 --out " + shellQuote(a.string()), tmp.path());
    ASSERT_EQ(full.status, 0) << full.err;
    const auto rows = readCampaignCsv(a / "samples.csv");
    fs::create_directories(b / "parts");
    fs::copy_file(a / "campaign.json", b / "campaign.json");
    std::string torn = campaignCsvHeader() + "\n", whole = campaignCsvHeader() + "\n";
    for (const CampaignRow& r : rows) {
        if (r.point.cellId == 0 && r.point.sampleId < 2) {  // the first two rows of cell 0, from another computation
            CampaignRow other = r;
            other.D += 1.0;
            torn += formatCampaignRow(other) + "\n";
        }
        whole += formatCampaignRow(r) + "\n";
    }
    std::ofstream(b / "parts" / "rank0.csv") << torn;
    std::ofstream(b / "parts" / "rank1.csv") << whole;
    bool complete = true;
    const auto read = readCampaignRows(b, &complete);
    EXPECT_FALSE(complete);
    ASSERT_EQ(read.size(), rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i)
        EXPECT_EQ(formatCampaignRow(read[i]), formatCampaignRow(rows[i])) << "sample " << i;
}

TEST(CampaignRunner, ResumeRefusesOtherSettings) {
    TempDir tmp;
    const fs::path a = tmp.path() / "a";
    ASSERT_EQ(runTrbc("campaign --samples 4 --forces-per-cell 4 --level 2 --seed 5 --no-cache --out " + shellQuote(a.string()),
                      tmp.path())
                  .status,
              0);
    const CliRun r = runTrbc(
        "campaign --samples 4 --forces-per-cell 4 --level 2 --seed 6 --no-cache --resume --out " + shellQuote(a.string()), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("seed (was 5, now 6)"), std::string::npos) << r.err;

    // A campaign of an earlier forward-model revision (no such key, revision 1) is not continued.
    const fs::path file = a / "campaign.json";
    nlohmann::json j;
    {
        std::ifstream in(file);
        j = nlohmann::json::parse(in);
    }
    j["settings"].erase("forward_model_revision");
    std::ofstream(file) << j.dump(2);
    const CliRun old = runTrbc(
        "campaign --samples 4 --forces-per-cell 4 --level 2 --seed 5 --no-cache --resume --out " + shellQuote(a.string()), tmp.path());
    EXPECT_EQ(old.status, 2);
    EXPECT_NE(old.err.find("forward_model_revision (was null, now 2)"), std::string::npos) << old.err;
}

TEST(CampaignRunner, UniformCampaignGrowsWhenResumedWithMoreSamples) {
    TempDir tmp;
    const fs::path a = tmp.path() / "a";
    const std::string base = "campaign --forces-per-cell 2 --level 2 --seed 7 --no-cache --threads 1 --out " + shellQuote(a.string());
    ASSERT_EQ(runTrbc(base + " --samples 4", tmp.path()).status, 0);
    const auto small = rowsWithoutWallTime(a / "samples.csv");

    // Refused: a smaller campaign, and a grown one without --resume.
    const CliRun shrink = runTrbc(base + " --samples 2 --resume", tmp.path());
    EXPECT_EQ(shrink.status, 2);
    EXPECT_NE(shrink.err.find("samples (was 4, now 2)"), std::string::npos) << shrink.err;
    EXPECT_NE(shrink.err.find("only a uniform design"), std::string::npos) << shrink.err;
    EXPECT_EQ(runTrbc(base + " --samples 8", tmp.path()).status, 2);

    const CliRun grown = runTrbc(base + " --samples 8 --resume", tmp.path());
    ASSERT_EQ(grown.status, 0) << grown.err;
    EXPECT_NE(grown.out.find("cells computed now: 2, resumed: 2"), std::string::npos) << grown.out;
    const auto big = rowsWithoutWallTime(a / "samples.csv");
    ASSERT_EQ(big.size(), 9u);  // header + 8 rows
    EXPECT_TRUE(std::equal(small.begin(), small.end(), big.begin()));
    const auto rows = readCampaignCsv(a / "samples.csv");
    const auto design = campaignDesign(DesignKind::Uniform, 8, 2, 7);
    for (std::size_t i = 0; i < rows.size(); ++i) {
        EXPECT_EQ(rows[i].point.p.FvK, design[i].p.FvK);
        EXPECT_EQ(rows[i].point.fext, design[i].fext);
        EXPECT_TRUE(rows[i].ok()) << rows[i].reason;
    }
    nlohmann::json j;
    {
        std::ifstream in(a / "campaign.json");
        j = nlohmann::json::parse(in);
    }
    EXPECT_EQ(j["settings"]["samples"], 8);
    EXPECT_EQ(j["status"], "complete");
    EXPECT_EQ(j["resumed_by"].back()["grown_from_samples"], 4);

    // A part file whose rows are not the design's (another seed copied in) is refused by name.
    const fs::path part = a / "parts" / "rank0.csv";
    auto lines = readCampaignCsv(part);
    lines[1].point.p.v += 1e-9;
    {
        std::ofstream out(part);
        out << campaignCsvHeader() << '\n';
        for (const CampaignRow& r : lines) out << formatCampaignRow(r) << '\n';
    }
    fs::remove(a / "samples.csv");
    const CliRun foreign = runTrbc(base + " --samples 8 --resume", tmp.path());
    EXPECT_EQ(foreign.status, 2);
    EXPECT_NE(foreign.err.find("sample 1 holds inputs other than the design's"), std::string::npos) << foreign.err;

    // An lhs design is not a prefix of a larger one, and neither is a campaign ending inside a cell.
    const fs::path b = tmp.path() / "b", c = tmp.path() / "c";
    const std::string lhs = "campaign --forces-per-cell 2 --level 2 --seed 7 --no-cache --design lhs --out " + shellQuote(b.string());
    ASSERT_EQ(runTrbc(lhs + " --samples 2", tmp.path()).status, 0);
    EXPECT_EQ(runTrbc(lhs + " --samples 4 --resume", tmp.path()).status, 2);
    const std::string odd = "campaign --forces-per-cell 2 --level 2 --seed 7 --no-cache --out " + shellQuote(c.string());
    ASSERT_EQ(runTrbc(odd + " --samples 3", tmp.path()).status, 0);
    EXPECT_EQ(runTrbc(odd + " --samples 4 --resume", tmp.path()).status, 2);
}

TEST(CampaignRunner, RowsOfACellMatchTheDirectForwardModel) {
    // A cell's stretching is a continuation over its forces; each row must agree with a direct
    // solve at its own force (within the static tolerance's effect, 0.02 um as for trbc simulate).
    // Level 3: on the level-2 mesh (162 vertices) the stretched shape has nearby alternative
    // equilibria and the two paths can end in different ones (0.16 um apart in D0).
    ExperimentOptions opt;
    opt.level = 3;
    auto cell = campaignDesign(DesignKind::Uniform, 3, 3, 8);
    const auto rows = runCampaignCell(cell, 8, opt);
    for (const CampaignRow& r : rows) {
        ASSERT_TRUE(r.ok()) << r.reason;
        const SampleResult s = runSample(r.point.p, r.point.fext, {true, true, false}, opt);
        EXPECT_EQ(r.D, s.equilibrium.observables.D);
        EXPECT_NEAR(r.D0, s.stretching[0].observables.D0, 0.02);
        EXPECT_NEAR(r.D1, s.stretching[0].observables.D1, 0.02);
    }
}

TEST(CampaignCli, RejectsBadOptions) {
    TempDir tmp;
    const std::string out = " --out " + shellQuote((tmp.path() / "x").string());
    const std::pair<std::string, std::string> cases[] = {
        {"--samples 0", "--samples: 0 is out of range (valid: [1, 1e8])"},
        {"--samples 4 " "--design halton", "unknown design 'halton' (valid: uniform, lhs, sobol)"},
        {"--samples 4 " "--design sobol", "--design sobol is for `trbc flow campaign`"},
        {"--samples 4 " "--forces-per-cell 0", "--forces-per-cell: 0 is out of range (valid: [1, 1000])"},
        {"--samples 4 " "--threads 0", "--threads: 0 is out of range (valid: [1, 1024])"},
        {"--samples 4 " "--level 9", "--level: 9 is out of range (valid: [2, 6])"},
        {"--samples 4 " "--level 1", "--level: 1 is out of range (valid: [2, 6])"},
        {"--samples 4 " "--cell-time-limit nan", "--cell-time-limit: 'nan' is not a finite number (valid: [0, 1e6] s)"},
        {"--samples 4 " "--inject-failures 3,x", "'x' is not a sample id"},
        {"--samples 4 " "--cell-time-limit -1", "--cell-time-limit: -1 is out of range (valid: [0, 1e6] s)"},
    };
    for (const auto& [args, phrase] : cases) {
        const CliRun r = runTrbc("campaign " + args + out, tmp.path());
        EXPECT_EQ(r.status, 2) << args;
        EXPECT_NE(r.err.find(phrase), std::string::npos) << args << ": " << r.err;
    }
}

}  // namespace
}  // namespace trbc
