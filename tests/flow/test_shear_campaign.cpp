// The shear-flow campaign (flow/shear_campaign.hpp): the design, the row format, failure records,
// growth, and a run under mpirun killed and resumed giving the uninterrupted table, with no case
// lost or computed twice.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "core/error.hpp"
#include "flow/shear_campaign.hpp"
#include "sampling/shear_campaign_table.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::CliRun;
using test::runShell;
using test::runTrbc;
using test::shellQuote;
using test::TempDir;

TEST(ShearCampaignDesign, FillsTheBoxOnItsScalesAndGrowsAsAPrefix) {
    const auto pts = shearCampaignDesign(DesignKind::Sobol, 256, 7);
    ASSERT_EQ(pts.size(), 256u);
    int lowStress = 0, lowFvK = 0;
    std::set<std::uint64_t> seeds;
    for (const ShearCampaignPoint& q : pts) {
        EXPECT_EQ(q.caseId, &q - pts.data());
        EXPECT_GE(q.cell.v, 0.65);
        EXPECT_LE(q.cell.v, 1.0);
        EXPECT_GE(q.cell.etam, 0.03);
        EXPECT_LE(q.cell.etam, 3.0);
        EXPECT_GE(q.etaOut, 8.0);
        EXPECT_LE(q.etaOut, 130.0);
        const double stress = q.etaOut * 1e-3 * q.shearRate;
        EXPECT_GE(stress, 0.01 * (1 - 1e-12));
        EXPECT_LE(stress, 25.0 * (1 + 1e-12));
        EXPECT_EQ(q.etaIn, 10.0);
        // Log-uniform: a quarter of the points in each quarter of the decades.
        lowStress += stress < 0.01 * std::pow(2500.0, 0.25);
        lowFvK += q.cell.FvK < 10.0 * std::pow(200.0, 0.25);
        seeds.insert(q.startSeed);
    }
    // 2^8 Sobol' points put exactly 64 in each quarter of every axis; the random shift and the
    // skipped origin move at most a point or two (i.i.d. points: 64 +- 7).
    EXPECT_NEAR(lowStress, 64, 2);
    EXPECT_NEAR(lowFvK, 64, 2);
    EXPECT_EQ(seeds.size(), 256u) << "every case starts from its own random state";
    const auto more = shearCampaignDesign(DesignKind::Sobol, 300, 7);
    for (std::size_t i = 0; i < pts.size(); ++i) {
        EXPECT_EQ(more[i].cell.mu, pts[i].cell.mu);
        EXPECT_EQ(more[i].shearRate, pts[i].shearRate);
        EXPECT_EQ(more[i].startSeed, pts[i].startSeed);
    }
    EXPECT_NE(shearCampaignDesign(DesignKind::Sobol, 4, 8)[1].cell.mu, pts[1].cell.mu) << "the seed shifts the design";
}

TEST(ShearCampaignTable, RowsRoundTripBitForBitAndATornTailIsDropped) {
    TempDir tmp;
    ShearCampaignRow a;
    a.point = shearCampaignDesign(DesignKind::Sobol, 3, 2)[2];
    a.regime = "tank-treading";
    a.inclinationDeg = 12.345678901234567, a.inclinationSeDeg = 0.01, a.swingDeg = 3.25, a.ttf = 0.41234;
    a.turns = 4.0001, a.steady = true, a.wallSeconds = 12.5;
    ShearCampaignRow b;
    b.point = shearCampaignDesign(DesignKind::Sobol, 3, 2)[1];
    b.status = "failed";
    b.reason = "equilibrium: did not converge, \"quoted\"";
    const fs::path f = tmp.path() / "t.csv";
    std::ofstream(f) << "# provenance\n"
                     << shearCampaignCsvHeader() << "\n"
                     << formatShearCampaignRow(a) << "\n"
                     << formatShearCampaignRow(b) << "\n"
                     << formatShearCampaignRow(a).substr(0, 40);
    EXPECT_THROW(readShearCampaignCsv(f), InputError) << "a torn line is an error unless dropped";
    const auto rows = readShearCampaignCsv(f, true);
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(formatShearCampaignRow(rows[0]), formatShearCampaignRow(a));
    EXPECT_EQ(rows[0].point.cell.mu, a.point.cell.mu);
    EXPECT_EQ(rows[0].point.startSeed, a.point.startSeed);
    EXPECT_TRUE(std::isnan(rows[0].swingSeDeg));
    EXPECT_EQ(rows[1].reason, b.reason);
    EXPECT_FALSE(rows[1].ok());

    std::ofstream(tmp.path() / "bad.csv") << shearCampaignCsvHeader() << "\n" << formatShearCampaignRow(a).replace(2, 1, "x") << "\n";
    try {
        readShearCampaignCsv(tmp.path() / "bad.csv");
        ADD_FAILURE() << "a non-numeric field must be refused";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("bad.csv: record 2"), std::string::npos) << e.what();
    }
}

/// The table without its provenance line and the wall_s column (timings differ between runs).
std::vector<std::string> rowsWithoutWallTime(const fs::path& table) {
    std::vector<std::string> out;
    std::ifstream in(table);
    for (std::string line; std::getline(in, line);)
        if (!line.starts_with('#')) out.push_back(line.substr(0, line.rfind(',')));
    return out;
}

long dataLines(const fs::path& part) {
    if (!fs::exists(part)) return 0;
    std::ifstream in(part);
    return long(std::count(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>(), '\n')) - 1;
}

// Level 2 (162 vertices): 2-6 s a case; case 2 fails on purpose.
const std::string kTiny = "flow campaign --cases 6 --level 2 --rotations 5 --seed 3 --no-cache --inject-failures 2";

// Another build (FMA, another libm) maps the design to values a few ulps away: its rows still
// count; a row of another design or seed is refused, naming the file and the case.
TEST(ShearCampaignTable, RowsOfAnotherBuildCountAndRowsOfAnotherDesignAreRefused) {
    TempDir tmp;
    const std::vector<ShearCampaignPoint> design = shearCampaignDesign(DesignKind::Sobol, 3, 2);
    auto write = [&](double etaOutFactor, int ulps) {
        ShearCampaignRow r;
        r.point = design[1];
        r.regime = "tumbling";
        r.point.etaOut *= etaOutFactor;
        for (int k = 0; k < ulps; ++k) r.point.etaOut = std::nextafter(r.point.etaOut, 1e9), r.point.cell.mu = std::nextafter(r.point.cell.mu, 0.0);
        fs::create_directories(tmp.path() / "parts");
        std::ofstream(tmp.path() / "parts" / "rank0.csv") << shearCampaignCsvHeader() << "\n" << formatShearCampaignRow(r) << "\n";
    };
    write(1.0, 2);
    const auto rows = finishedShearCampaignRows(tmp.path(), design);
    ASSERT_EQ(rows.size(), 1u);
    EXPECT_EQ(rows.begin()->first, 1);
    write(1.0 + 1e-9, 0);
    try {
        finishedShearCampaignRows(tmp.path(), design);
        FAIL() << "a row of another design was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("rank0.csv: case 1 holds inputs other than the design's"), std::string::npos) << e.what();
    }
}

// The rows of a campaign directory, or of its cases.csv, carry the level and the start of its campaign.json.
TEST(ShearCampaignTable, RowsCarryTheirCampaignsLevel) {
    TempDir tmp;
    const std::vector<ShearCampaignPoint> design = shearCampaignDesign(DesignKind::Sobol, 4, 7);
    ShearCampaignRow r;
    r.point = design[2];
    r.regime = "tumbling";
    fs::create_directories(tmp.path() / "c" / "parts");
    std::ofstream(tmp.path() / "c" / "campaign.json")
        << R"({"settings": {"design": "sobol", "cases": 4, "seed": 7, "eta_in_mPa_s": 10.0, "level": 2, "start": "in-plane"}})";
    std::ofstream(tmp.path() / "c" / "parts" / "rank0.csv") << shearCampaignCsvHeader() << "\n" << formatShearCampaignRow(r) << "\n";
    bool complete = true;
    const auto parts = readShearCampaignRows(tmp.path() / "c", &complete);
    ASSERT_EQ(parts.size(), 1u);
    EXPECT_FALSE(complete);
    EXPECT_EQ(parts[0].meshLevel, 2);
    EXPECT_EQ(parts[0].start, "in-plane");
    std::ofstream(tmp.path() / "c" / "cases.csv") << shearCampaignCsvHeader() << "\n" << formatShearCampaignRow(r) << "\n";
    EXPECT_EQ(readShearCampaignRows(tmp.path() / "c")[0].meshLevel, 2);
    EXPECT_EQ(readShearCampaignRows(tmp.path() / "c" / "cases.csv")[0].meshLevel, 2);
    fs::copy_file(tmp.path() / "c" / "cases.csv", tmp.path() / "alone.csv");
    EXPECT_EQ(readShearCampaignRows(tmp.path() / "alone.csv")[0].meshLevel, 0);  // no campaign beside it
    EXPECT_EQ(readShearCampaignRows(tmp.path() / "alone.csv")[0].start, "");
    // Finished rows of a campaign on another box cannot be matched to this build's design.
    nlohmann::json other = {{"settings", {{"design", "sobol"}, {"cases", 4}, {"seed", 7}, {"eta_in_mPa_s", 10.0}, {"level", 2},
                                          {"box", shearCampaignBoxJson()}}}};
    other["settings"]["box"][1]["lo"] = 1.0;
    fs::create_directories(tmp.path() / "d" / "parts");
    std::ofstream(tmp.path() / "d" / "campaign.json") << other.dump();
    std::ofstream(tmp.path() / "d" / "parts" / "rank0.csv") << shearCampaignCsvHeader() << "\n" << formatShearCampaignRow(r) << "\n";
    try {
        readShearCampaignRows(tmp.path() / "d");
        FAIL() << "a campaign on another box was read";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("the campaign was made on another design box"), std::string::npos) << e.what();
    }
    other["settings"]["box"] = shearCampaignBoxJson();
    std::ofstream(tmp.path() / "d" / "campaign.json") << other.dump();
    EXPECT_EQ(readShearCampaignRows(tmp.path() / "d").size(), 1u);
}

// Campaigns trained together differ only in level, size and start.
TEST(ShearCampaignTable, FlowTrainRefusesCampaignsOfOtherSettings) {
    TempDir tmp;
    for (const char* name : {"a", "b"}) fs::create_directories(tmp.path() / name / "parts");
    std::ofstream(tmp.path() / "a" / "campaign.json")
        << R"({"settings": {"design": "sobol", "cases": 64, "seed": 7, "eta_in_mPa_s": 10.0, "level": 3, "start": "random"}})";
    std::ofstream(tmp.path() / "b" / "campaign.json")
        << R"({"settings": {"design": "sobol", "cases": 4096, "seed": 8, "eta_in_mPa_s": 10.0, "level": 2, "start": "in-plane"}})";
    const CliRun r = runTrbc("flow train --campaign " + shellQuote((tmp.path() / "a").string()) + " --campaign " +
                                 shellQuote((tmp.path() / "b").string()) + " --out " + shellQuote((tmp.path() / "m").string()),
                             tmp.path());
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_NE(r.err.find("its setting 'seed' (8) differs from the first campaign's (7)"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "m"));
}

TEST(ShearCampaignRunner, RecordsFailuresAndRefusesAnotherDesignOnResume) {
    TempDir tmp;
    const fs::path out = tmp.path() / "c";
    const CliRun r = runTrbc(kTiny + " --threads 2 --out " + shellQuote(out.string()), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("6 of 6 cases done (5 ok, 1 failed)"), std::string::npos) << r.out;
    const auto rows = readShearCampaignRows(out);
    ASSERT_EQ(rows.size(), 6u);
    int tankTreading = 0;
    for (const ShearCampaignRow& row : rows) {
        if (row.point.caseId == 2) {
            EXPECT_EQ(row.status, "failed");
            EXPECT_EQ(row.reason, "injected failure (--inject-failures)");
            EXPECT_TRUE(row.regime.empty());
            continue;
        }
        ASSERT_TRUE(row.ok()) << row.reason;
        EXPECT_TRUE(row.regime == "tank-treading" || row.regime == "tumbling" || row.regime == "intermittent") << row.regime;
        EXPECT_GE(row.turns, 4.0 - 1e-9);
        EXPECT_LE(row.turns, 5.0 + 1e-9);
        EXPECT_EQ(row.tankTreading(), std::isfinite(row.inclinationDeg));
        EXPECT_EQ(row.tankTreading(), std::isfinite(row.ttf));
        tankTreading += row.tankTreading();
    }
    EXPECT_GT(tankTreading, 0);
    const auto j = nlohmann::json::parse(std::ifstream(out / "campaign.json"));
    EXPECT_EQ(j.at("status"), "complete");
    EXPECT_EQ(j.at("settings").at("start"), "random");
    EXPECT_EQ(j.at("cases_done"), 6);

    const CliRun again = runTrbc(kTiny + " --out " + shellQuote(out.string()), tmp.path());
    EXPECT_EQ(again.status, 2);
    EXPECT_NE(again.err.find("add --resume"), std::string::npos) << again.err;
    const CliRun other = runTrbc(kTiny + " --start in-plane --resume --out " + shellQuote(out.string()), tmp.path());
    EXPECT_EQ(other.status, 2);
    EXPECT_NE(other.err.find("start"), std::string::npos) << other.err;
    // A larger Sobol' design grows the campaign: only the new cases run, the old rows stay.
    const auto firstTable = rowsWithoutWallTime(out / "cases.csv");
    const CliRun grown = runTrbc(fmt::format("flow campaign --cases 7 --level 2 --rotations 5 --seed 3 --no-cache "
                                             "--inject-failures 2 --resume --out {}",
                                             shellQuote(out.string())),
                                 tmp.path());
    ASSERT_EQ(grown.status, 0) << grown.err;
    EXPECT_NE(grown.out.find("cases computed now: 1, resumed: 6"), std::string::npos) << grown.out;
    const auto grownTable = rowsWithoutWallTime(out / "cases.csv");
    ASSERT_EQ(grownTable.size(), 8u);
    ASSERT_EQ(firstTable.size(), 7u);
    for (std::size_t i = 0; i < firstTable.size(); ++i) EXPECT_EQ(grownTable[i], firstTable[i]);
}

// --full-length runs every case all its turns and records it turn by turn; `flow steady-rules` then
// judges stop rules on those records. A resume that drops --full-length is refused naming it; rules
// are range-checked.
TEST(ShearCampaignRunner, FullLengthRunsRecordEveryTurnForTheStopRuleStudy) {
    TempDir tmp;
    const fs::path out = tmp.path() / "c";
    const std::string run = "flow campaign --cases 2 --level 2 --rotations 5 --seed 3 --no-cache --full-length --out " + shellQuote(out.string());
    const CliRun r = runTrbc(run, tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    for (const ShearCampaignRow& row : readShearCampaignRows(out)) {
        ASSERT_TRUE(row.ok()) << row.reason;
        EXPECT_NEAR(row.turns, 5.0, 0.1 / (4.0 * M_PI));  // the last frame, at most one frame interval before the end
        EXPECT_FALSE(row.steady);
    }
    const auto j = nlohmann::json::parse(std::ifstream(out / "campaign.json"));
    EXPECT_EQ(j.at("settings").at("full_length"), true);
    EXPECT_FALSE(j.at("settings").contains("steady_rule"));
    for (int id : {0, 1}) {
        const auto rec = nlohmann::json::parse(std::ifstream(out / "by_turn" / fmt::format("case{}.json", id)));
        EXPECT_EQ(rec.at("case"), id);
        EXPECT_EQ(rec.at("turns").back().at("turn"), 5);  // the whole run, although its last frame is before turn 5
        EXPECT_GT(rec.at("turns").back().at("gmres_iterations").get<long>(), rec.at("turns").front().at("gmres_iterations").get<long>());
    }
    const CliRun study = runTrbc("flow steady-rules --campaign " + shellQuote(out.string()) + " --rule 4,0.1,0.005 --rule 3,1,0.05", tmp.path());
    ASSERT_EQ(study.status, 0) << study.err;
    EXPECT_NE(study.out.find("2 full-length cases"), std::string::npos) << study.out;
    EXPECT_NE(study.out.find("| 4, 0.1, 0.5 % | 2 |"), std::string::npos) << study.out;
    EXPECT_NE(study.out.find("| 3, 1, 5 % | 2 |"), std::string::npos) << study.out;

    const CliRun stopped = runTrbc("flow campaign --cases 2 --level 2 --rotations 5 --seed 3 --no-cache --resume --out " +
                                       shellQuote(out.string()),
                                   tmp.path());
    EXPECT_EQ(stopped.status, 2);
    EXPECT_NE(stopped.err.find("full_length (was true, now absent)"), std::string::npos) << stopped.err;
    const CliRun both = runTrbc(run + " --resume --steady-rule 4,0.2,0.01", tmp.path());
    EXPECT_EQ(both.status, 2);
    EXPECT_NE(both.err.find("a --full-length campaign stops no case"), std::string::npos) << both.err;
    const CliRun half = runTrbc("flow campaign --cases 1 --rotations 7.5 --full-length --out " + shellQuote((tmp.path() / "h").string()),
                                tmp.path());
    EXPECT_EQ(half.status, 2);
    EXPECT_NE(half.err.find("--rotations 7.5: a --full-length campaign runs whole turns"), std::string::npos) << half.err;
    const CliRun loose = runTrbc("flow steady-rules --campaign " + shellQuote(out.string()) + " --rule 4,0,0.005", tmp.path());
    EXPECT_EQ(loose.status, 2);
    EXPECT_NE(loose.err.find("--rule 4,0,0.005: the first turn must be in [2, 5]"), std::string::npos) << loose.err;
    const CliRun bad = runTrbc("flow campaign --cases 1 --steady-rule 1,0.1,0.005 --out " + shellQuote((tmp.path() / "b").string()), tmp.path());
    EXPECT_EQ(bad.status, 2);
    EXPECT_NE(bad.err.find("--steady-rule 1,0.1,0.005: the first turn must be in [2, 10]"), std::string::npos) << bad.err;
    // The rule of a campaign that stops its cases is one of its settings (its one case fails on purpose).
    const fs::path ruled = tmp.path() / "r";
    const CliRun withRule = runTrbc("flow campaign --cases 1 --inject-failures 0 --steady-rule 3,0.2,0.01 --out " + shellQuote(ruled.string()),
                                    tmp.path());
    ASSERT_EQ(withRule.status, 0) << withRule.err;
    const auto rj = nlohmann::json::parse(std::ifstream(ruled / "campaign.json"));
    EXPECT_EQ(rj.at("settings").at("steady_rule").at("min_rotations"), 3.0);
    EXPECT_EQ(rj.at("settings").at("steady_rule").at("angle_tolerance_deg"), 0.2);
    EXPECT_EQ(rj.at("settings").at("steady_rule").at("ttf_tolerance"), 0.01);
    EXPECT_FALSE(rj.at("settings").contains("full_length"));
    const CliRun two = runTrbc("flow steady-rules --campaign " + shellQuote(out.string()) + " --rule 4,0.1", tmp.path());
    EXPECT_EQ(two.status, 2);
    EXPECT_NE(two.err.find("--rule: '4,0.1' has 2 numbers, 3 expected"), std::string::npos) << two.err;
}

#ifdef TRBC_MPIEXEC
std::string mpiFlowCampaign(const std::string& args) {
    return fmt::format("export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1; "
                       "exec timeout 120 {} -n 2 {} {}",
                       shellQuote(TRBC_MPIEXEC), shellQuote(TRBC_CLI), args);
}

/// Starts `mpiexec -n 2 trbc flow campaign ...` and stops it as a batch system does at a job's wall
/// time once `rows` rows are in the part files: SIGTERM to the launcher, which ends the ranks (they
/// have no handler, so they die wherever they are, mid-write included). A SIGKILL of the launcher
/// alone would leave the ranks running. False if the run finished first.
bool killedAfterRows(const fs::path& dir, long rows) {
    const std::string cmd = mpiFlowCampaign(kTiny + " --threads 1 --out " + shellQuote(dir.string())) + " >/dev/null 2>&1";
    const pid_t pid = fork();
    if (pid < 0) return false;
    if (pid == 0) {
        execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
        _exit(127);
    }
    const auto written = [&] { return dataLines(dir / "parts" / "rank0.csv") + dataLines(dir / "parts" / "rank1.csv"); };
    const auto t0 = std::chrono::steady_clock::now();
    while (written() < rows && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(90))
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    ::kill(pid, SIGTERM);  // timeout passes it on to mpiexec, mpiexec to the ranks
    int status = 0;
    ::waitpid(pid, &status, 0);  // timeout waits for mpiexec
    // mpiexec can exit before its ranks are gone (measured under load: a rank still held the output
    // directory's lock when the resume started); a batch system's next job starts after them too.
    for (int k = 0; k < 3000 && test::processesMentioning(dir.string()) > 0; ++k)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return !(WIFEXITED(status) && WEXITSTATUS(status) == 0) && !fs::exists(dir / "cases.csv");
}

TEST(ShearCampaignMpi, KilledUnderMpirunAndResumedLosesAndRepeatsNoCase) {
    TempDir tmp;
    const fs::path one = tmp.path() / "one", cut = tmp.path() / "cut";
    const CliRun single = runTrbc(kTiny + " --threads 2 --out " + shellQuote(one.string()), tmp.path());
    ASSERT_EQ(single.status, 0) << single.err;

    ASSERT_TRUE(killedAfterRows(cut, 2)) << "the run finished before it could be killed";
    const auto before = [&] { return dataLines(cut / "parts" / "rank0.csv") + dataLines(cut / "parts" / "rank1.csv"); };
    const long written = before();
    ASSERT_GE(written, 2);
    ASSERT_LT(written, 6);

    const CliRun resumed = runShell(mpiFlowCampaign(kTiny + " --threads 1 --resume --out " + shellQuote(cut.string())), tmp.path());
    ASSERT_EQ(resumed.status, 0) << resumed.out << resumed.err;
    // No case lost, none computed twice: the part files hold each case once, and the table is the
    // uninterrupted one-process table.
    EXPECT_EQ(before(), 6);
    std::set<long> ids;
    for (const char* part : {"rank0.csv", "rank1.csv"})
        for (const ShearCampaignRow& r : readShearCampaignCsv(cut / "parts" / part)) EXPECT_TRUE(ids.insert(r.point.caseId).second);
    EXPECT_EQ(ids.size(), 6u);
    EXPECT_EQ(rowsWithoutWallTime(one / "cases.csv"), rowsWithoutWallTime(cut / "cases.csv"));
    EXPECT_EQ(nlohmann::json::parse(std::ifstream(cut / "campaign.json")).at("resumed_by").back().at("ranks"), 2);
}
#endif

}  // namespace
}  // namespace trbc
