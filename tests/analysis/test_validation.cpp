// trbc validate: configuration, the cases of docs/VALIDATE.md, the
// tumbling/tank-treading bracket and its refinement, the comparison with the experimental scatter,
// and the resumable runner on a tiny set.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "analysis/validation.hpp"
#include "core/error.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

TEST(ValidationReasons, AShortenedReasonEndsAtAWordBoundary) {
    const std::string reason = "exit 2 without a result: trbc: error: frames = duration / frame interval is more than the "
                               "limit; raise --frame-interval to at least 0.2\nRun with --help";
    const std::string s = shortenedReason(reason, 60);
    EXPECT_LE(s.size(), 64u);
    EXPECT_EQ(s.substr(s.size() - 4), " ...");
    EXPECT_EQ(reason.find(s.substr(0, s.size() - 4) + " "), 0u);  // a whole-word prefix
    EXPECT_EQ(shortenedReason(reason, 1000), reason.substr(0, reason.find('\n')));  // first line only
    EXPECT_EQ(shortenedReason(std::string(300, 'x'), 100), std::string(100, 'x') + " ...");  // one long word
}
using test::TempDir;
using test::writeText;

using test::tableBody;

const fs::path kRepo = test::sourceRoot();
const fs::path kExperiments = test::experimentsDir();

std::string configError(const TempDir& dir, const std::string& toml) {
    const fs::path file = writeText(dir.path() / "v.toml", toml);
    try {
        readValidationConfig(file, kExperiments);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(ValidationConfig, ShippedConfigHasEveryCaseOfValidationMd) {
    const ValidationConfig c = readValidationConfig(kRepo / "configs" / "validation.toml", kExperiments);
    const std::vector<ValidationCase> cases = initialValidationCases(c);
    int angle = 0, ttf = 0, thr = 0, tube = 0;
    for (const ValidationCase& x : cases)
        (x.kind == "angle" ? angle : x.kind == "ttf" ? ttf : x.kind == "threshold" ? thr : tube)++;
    EXPECT_EQ(angle, 56);  // 14 rates at 10.7, 23.9, 55.9 and 104 mPa s
    EXPECT_EQ(ttf, 6);
    EXPECT_EQ(thr, 3 * (4 * 6 + 4 * 5));  // the eight scripted sweeps, three fluctuating members per rate
    EXPECT_EQ(c.thresholdProtocol, "fluctuating");
    EXPECT_EQ(tube, 15);            // 5, 10, ..., 75 mmHg/mm
    TempDir dir;
    const fs::path dup = writeText(dir.path() / "dup.toml", "[tube]\npressure_gradients = [10, 10, 20]\n");
    int tubes = 0;
    for (const ValidationCase& x : initialValidationCases(readValidationConfig(dup, kExperiments))) tubes += x.kind == "tube";
    EXPECT_EQ(tubes, 2);
    EXPECT_EQ(cases.front().id, "angle_eta10.7_rate1");
    EXPECT_NEAR(cases[13].rate, 200.0, 1e-9);
    EXPECT_EQ(cases.back().id, "tube_pg75");
    EXPECT_DOUBLE_EQ(c.tubeRadius, 3.3);
    EXPECT_EQ(c.cellSource, "table1");
    EXPECT_DOUBLE_EQ(c.stepTol, 1e-3);       // the shear's
    EXPECT_DOUBLE_EQ(c.tubeStepTol, 6.25e-5);  // the tube's (docs/FLOW_TUBE.md, "Step tolerance")
    // The two higher viscosities alone: the same 28 angle cases as the full set's, with its cell
    // (--posterior replaces it in both) and its shear settings.
    const ValidationConfig hv = readValidationConfig(kRepo / "configs" / "validation_high_viscosity.toml", kExperiments);
    const std::vector<ValidationCase> hvCases = initialValidationCases(hv);
    ASSERT_EQ(hvCases.size(), 28u);
    EXPECT_EQ(hv.cellSource, c.cellSource);
    EXPECT_EQ(hv.stepTol, c.stepTol);
    EXPECT_EQ(hv.etaIn, c.etaIn);
    EXPECT_EQ(hv.rotations, c.rotations);
    EXPECT_EQ(hv.tiltDeg, c.tiltDeg);
    for (std::size_t k = 0; k < hvCases.size(); ++k) EXPECT_EQ(hvCases[k].id, cases[28 + k].id);
}

TEST(ValidationConfig, ErrorsNameFileLineKeyAndRange) {
    TempDir dir;
    std::string e = configError(dir, "[run]\nlevel = 7\n");
    EXPECT_NE(e.find("v.toml:2: 'run.level' = 7 is out of range: valid range [1, 4]"), std::string::npos) << e;
    e = configError(dir, "[shear]\neta_in = -1\n");
    EXPECT_NE(e.find("v.toml:2: 'shear.eta_in' = -1 is out of range"), std::string::npos) << e;
    e = configError(dir, "[[shear.angle]]\neta_out = 10\nrate_min = 5\nrate_max = 1\n");
    EXPECT_NE(e.find("rate_max = 1 < rate_min = 5"), std::string::npos) << e;
    e = configError(dir, "[[shear.ttf]]\neta_out = 0\nrate_min = 5\nrate_max = 10\n");
    EXPECT_NE(e.find("'shear.ttf.eta_out' = 0 is out of range"), std::string::npos) << e;
    e = configError(dir, "[tube]\nradius = 1.0\n");
    EXPECT_NE(e.find("v.toml:2: 'tube.radius' = 1 is out of range: valid range [1.497, 10000]"), std::string::npos) << e;
    e = configError(dir, "[tube]\npressure_gradients = [5, -10]\n");
    EXPECT_NE(e.find("v.toml:2: 'tube.pressure_gradients' must be a non-empty array of numbers > 0"), std::string::npos) << e;
    e = configError(dir, "[tube]\nsettle_relax = 0\n");
    EXPECT_NE(e.find("v.toml:2: 'tube.settle_relax' = 0 is out of range"), std::string::npos) << e;
    e = configError(dir, "[tube]\nstep_tol = 0\n");
    EXPECT_NE(e.find("v.toml:2: 'tube.step_tol' = 0 is out of range"), std::string::npos) << e;
    e = configError(dir, "[tube]\nsettle_relax = 1\nsettle_etam = 0.01\n");
    EXPECT_NE(e.find("v.toml:3: 'tube.settle_etam' and 'tube.settle_relax' both given"), std::string::npos) << e;
    e = configError(dir, "[cell]\nsource = \"posterior\"\n");
    EXPECT_NE(e.find("needs cell.posterior"), std::string::npos) << e;
    // Keys that the chosen source does not read are refused, naming the file, the key and why.
    e = configError(dir, "[cell]\nsource = \"table1\"\nv = 0.8\n");
    EXPECT_NE(e.find("v.toml:3: 'cell.v' is not read with cell.source = \"table1\" (the cell is Table 1's means)"), std::string::npos) << e;
    e = configError(dir, "[cell]\nv = 0.8\n");  // table1 is the default source
    EXPECT_NE(e.find("v.toml:2: 'cell.v' is not read with cell.source = \"table1\""), std::string::npos) << e;
    e = configError(dir, "[cell]\nsource = \"explicit\"\nv = 0.8\nb2 = 1.5\n");
    EXPECT_NE(e.find("v.toml:2: cell.source = \"explicit\" needs all of v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um; missing: mu_uN_per_m, "
                     "kb_J, etam_Pa_s_um"), std::string::npos) << e;
    e = configError(dir, "[cell]\nsource = \"explicit\"\nposterior = \".\"\nv = 0.94\nmu_uN_per_m = 4.99\nkb_J = 2.1e-19\nb2 = 1.84\n"
                         "etam_Pa_s_um = 0.69\n");
    EXPECT_NE(e.find("v.toml:3: 'cell.posterior' is not read with cell.source = \"explicit\""), std::string::npos) << e;
    e = configError(dir, "[cell]\nsource = \"posterior\"\nposterior = \".\"\netam_Pa_s_um = 0.5\n");
    EXPECT_NE(e.find("v.toml:4: 'cell.etam_Pa_s_um' is not read with cell.source = \"posterior\" (the cell is the posterior's means)"),
              std::string::npos) << e;
    e = configError(dir, "[cell]\nmu_uN_per_m = 20\n");
    EXPECT_NE(e.find("'cell.mu_uN_per_m' = 20 is out of range: valid range [1, 10]"), std::string::npos) << e;
    e = configError(dir, "[shear]\nrotation = 3\n");
    EXPECT_NE(e.find("unknown key 'shear.rotation'"), std::string::npos) << e;
    e = configError(dir, "[data]\ndir = \"nowhere\"\n");
    EXPECT_NE(e.find("lacks shear_flow/ or microtube/"), std::string::npos) << e;
    e = configError(dir, "[run\n");
    EXPECT_NE(e.find("TOML syntax error"), std::string::npos) << e;
}

TEST(ValidationThreshold, BracketIsHighestTumblingAndLowestTankTreading) {
    const ThresholdBracket b = thresholdBracket(
        {{10, "tank-treading"}, {1, "tumbling"}, {2, "tumbling"}, {3, "intermittent"}, {5, "tank-treading"}, {0.5, "tumbling"}});
    ASSERT_TRUE(b.gammaLo && b.gammaHi);
    EXPECT_DOUBLE_EQ(*b.gammaLo, 2.0);
    EXPECT_DOUBLE_EQ(*b.gammaHi, 5.0);
    EXPECT_TRUE(b.monotone);
    ASSERT_EQ(b.intermittentRates.size(), 1u);
    EXPECT_FALSE(thresholdBracket({{4, "tumbling"}, {2, "tank-treading"}}).monotone);
}

TEST(ValidationThreshold, RefinementBisectsGeometricallyAndSearchesOutwards) {
    EXPECT_NEAR(*refinementRate({{1, "tumbling"}, {4, "tank-treading"}}), 2.0, 1e-12);
    EXPECT_FALSE(refinementRate({{1, "tumbling"}, {1.04, "tank-treading"}}).has_value());  // converged
    EXPECT_NEAR(*refinementRate({{1, "tumbling"}, {3, "tumbling"}}), 6.0, 1e-12);         // everything tumbled
    EXPECT_NEAR(*refinementRate({{1, "tumbling"}, {3, "intermittent"}}), 6.0, 1e-12);     // no tank-treading yet
    EXPECT_NEAR(*refinementRate({{2, "tank-treading"}, {8, "tank-treading"}}), 1.0, 1e-12);
    EXPECT_FALSE(refinementRate({{4, "tumbling"}, {2, "tank-treading"}}).has_value());    // non-monotone
    EXPECT_FALSE(refinementRate({{1, ""}, {2, ""}}).has_value());                         // all failed
    EXPECT_FALSE(refinementRate({}).has_value());
    // Intermittent rates inside the bracket are gap edges: the widest gap is bisected, never a rate run before.
    EXPECT_NEAR(*refinementRate({{1, "tumbling"}, {2, "intermittent"}, {8, "tank-treading"}}), 4.0, 1e-12);
    EXPECT_NEAR(*refinementRate({{1, "tumbling"}, {2, "intermittent"}, {4, "intermittent"}, {8, "tank-treading"}}),
                std::sqrt(2.0), 1e-12);
    // Intermittent below tank-treading and no tumbling yet: search downwards.
    EXPECT_NEAR(*refinementRate({{2, "intermittent"}, {4, "tank-treading"}}), 1.0, 1e-12);
}

TEST(ValidationComparison, ScatterWindowsAndBands) {
    ExperimentalPoints d;
    d.x = {1.0, 2.0, 4.0};
    d.y = {{10.0, 12.0}, {11.0}, {20.0}};
    ScatterComparison s = compareWithScatter(2.0, 11.0, d, 1.2);
    EXPECT_EQ(s.verdict, "inside");
    EXPECT_EQ(s.points, 1);
    s = compareWithScatter(1.5, 11.5, d, 1.5);  // window [1, 2.25]: 10, 12, 11
    EXPECT_EQ(s.points, 3);
    EXPECT_DOUBLE_EQ(s.lo, 10.0);
    EXPECT_DOUBLE_EQ(s.hi, 12.0);
    EXPECT_EQ(compareWithScatter(1.5, 9.0, d, 1.5).verdict, "outside");
    EXPECT_EQ(compareWithScatter(1.5, NAN, d, 1.5).verdict, "outside");  // tumbling where data show tank-treading
    EXPECT_EQ(compareWithScatter(100.0, 1.0, d, 1.5).verdict, "no data");
    // Threshold intervals.
    ExperimentalPoints t;
    t.x = {23.9, 23.9, 104.0};
    t.y = {{0.06}, {0.23}, {0.056}};
    EXPECT_EQ(compareInterval(23.9, 0.1, 0.2, t, 0.1).verdict, "inside");
    EXPECT_EQ(compareInterval(23.9, 0.3, 0.5, t, 0.1).verdict, "outside");
    EXPECT_EQ(compareInterval(23.9, 0.03, std::nullopt, t, 0.1).verdict, "not bracketed");
    EXPECT_EQ(compareInterval(23.9, 0.3, 0.1, t, 0.1).verdict, "not monotone");
    EXPECT_EQ(compareInterval(50.0, 0.1, 0.2, t, 0.1).verdict, "no data");
    // Length band (value, high, low) interpolated in log v.
    ExperimentalPoints l;
    l.x = {0.1, 1.0};
    l.y = {{7.0, 8.0, 6.0}, {9.0, 10.0, 8.0}};
    s = compareWithBand(std::sqrt(0.1), 8.5, l);
    EXPECT_EQ(s.verdict, "inside");
    EXPECT_NEAR(s.lo, 7.0, 1e-12);
    EXPECT_NEAR(s.hi, 9.0, 1e-12);
    EXPECT_EQ(compareWithBand(std::sqrt(0.1), 9.5, l).verdict, "outside");
    EXPECT_EQ(compareWithBand(2.0, 9.0, l).verdict, "no data");
}

TEST(ValidationComparison, EvidenceWindowsAndVerdictsOfEachObservable) {
    TempDir dir;
    const fs::path shear = dir.path() / "shear_flow", tube = dir.path() / "microtube";
    writeText(shear / "tt_tb_critical_stress" / "Fischer2013.csv", "eta,tau\n23.9,0.06\n");
    writeText(shear / "tt_tb_critical_stress" / "Abkarian2007.csv", "eta,tau\n24.5,0.09\n100,0.5\n");
    writeText(shear / "inclination_angle" / "Fisher2015_eta_23.9_mPa_s.csv", "shear_rate,angle1,angle2,angle3,angle4,angle5,angle6,angle7\n10,20,24,,,,,\n100,10,,,,,,\n");
    writeText(shear / "ttf" / "data_donors12.csv", "shear_rate,TTF\n10,0.02\n11,0.03\n");
    writeText(tube / "Tomaiuolo2009_pg_v_6.6um.csv", "pg,v\n10,0.1\n12,0.2\n");
    writeText(tube / "Tomaiuolo2009_v_l_6.6um.csv", "v,l,l_high,l_low\n0.1,8,9,7\n1,10,11,9\n");
    writeText(tube / "Hochmut1970_v_l_6.7um.csv", "v,l\n0.5,9\n");  // drawn, never judged
    ValidationEvidence e(dir.path());
    EXPECT_FALSE(e.inclination(50.0, 10.0, 22.0, "tank-treading"));  // no data at that viscosity
    std::optional<ScatterComparison> a = e.inclination(23.9, 11.0, 22.0, "tank-treading");
    ASSERT_TRUE(a);
    EXPECT_EQ(a->verdict, "inside");
    EXPECT_EQ(a->points, 2);  // rates within a factor 1.5: only 10
    EXPECT_EQ(e.inclination(23.9, 11.0, NAN, "tank-treading")->verdict, "no prediction");
    EXPECT_EQ(e.inclination(23.9, 11.0, NAN, "tumbling")->verdict, "outside");
    const ScatterComparison f = e.tankTreadingFrequency(10.5, 0.3, "tank-treading");  // scatter 4 pi [0.02, 0.03]
    EXPECT_EQ(f.verdict, "inside");
    EXPECT_NEAR(f.hi, 4.0 * M_PI * 0.03, 1e-12);
    EXPECT_EQ(e.tankTreadingFrequency(10.5, NAN, "tank-treading").verdict, "no prediction");
    EXPECT_EQ(e.tubeVelocity(11.0, 0.15).verdict, "inside");
    EXPECT_EQ(e.tubeVelocity(11.0, 0.3).verdict, "outside");
    EXPECT_EQ(e.tubeLength(std::sqrt(0.1), 9.0).verdict, "inside");  // band [8, 10] at the geometric mean
    ThresholdBracket b;
    b.gammaLo = 2.0;
    b.gammaHi = 4.0;
    const auto [lo, hi] = criticalStressInterval(b, 23.9);
    ASSERT_TRUE(lo && hi);
    EXPECT_NEAR(*lo, 2.0 * 23.9e-3, 1e-15);
    EXPECT_NEAR(*hi, 4.0 * 23.9e-3, 1e-15);
    const ScatterComparison c = e.criticalStress(23.9, lo, hi);  // both data sets within 10 %: [0.06, 0.09]
    EXPECT_EQ(c.verdict, "inside");
    EXPECT_EQ(c.points, 2);
    b.gammaHi.reset();
    EXPECT_EQ(e.criticalStress(23.9, criticalStressInterval(b, 23.9).first, std::nullopt).verdict, "not bracketed");
}

TEST(ValidationShard, DealsUnitsRoundRobinAndKeepsAThresholdViscosityTogether) {
    const std::vector<ValidationCase> all = {
        {"a1", "angle", 10.7, 1.0, 0.0},     {"a2", "angle", 10.7, 2.0, 0.0},     {"h1", "threshold", 10.0, 30.0, 0.0},
        {"h2", "threshold", 10.0, 60.0, 0.0}, {"k1", "threshold", 14.0, 7.0, 0.0},  {"h3", "threshold", 10.0, 90.0, 0.0},
        {"k2", "threshold", 14.0, 14.0, 0.0}, {"t1", "tube", 1.003, 0.0, 30.0}};
    const auto ids = [](const std::vector<ValidationCase>& v) {
        std::string s;
        for (const ValidationCase& c : v) s += c.id + " ";
        return s;
    };
    // Units: a1 0, a2 1, eta 10 (h1 h2 h3) 2, eta 14 (k1 k2) 3, t1 4.
    EXPECT_EQ(ids(validationShard(all, 1, 2)), "a1 h1 h2 h3 t1 ");
    EXPECT_EQ(ids(validationShard(all, 2, 2)), "a2 k1 k2 ");
    EXPECT_EQ(ids(validationShard(all, 2, 3)), "a2 t1 ");
    EXPECT_EQ(ids(validationShard(all, 1, 1)), ids(all));
    EXPECT_TRUE(validationShard(all, 7, 7).empty());
    EXPECT_THROW(validationShard(all, 3, 2), InputError);
    EXPECT_EQ(parseShard("2/4", "--shard"), std::make_pair(2, 4));
    for (const char* bad : {"3/2", "0/2", "a/b", "2/4x", "2", "", "2-4", "-1/2"}) {
        try {
            parseShard(bad, "--shard");
            ADD_FAILURE() << "accepted '" << bad << "'";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(std::string("--shard '") + bad + "': expected K/N with 1 <= K <= N"), std::string::npos)
                << e.what();
        }
    }
}

/// Two angle cases and a two-rate threshold sweep with one refinement, level 1, one rotation.
fs::path writeTinyValidationConfig(const TempDir& dir) {
    return writeText(dir.path() / "tiny.toml",
                     "[run]\nlevel = 1\njobs = 2\n[shear]\nrotations = 1\nthreshold_refinements = 1\nthreshold_protocol = \"in-plane\"\n"
                     "[[shear.angle]]\neta_out = 23.9\nrate_min = 20\nrate_max = 60\ncount = 2\n"
                     "[[shear.threshold]]\neta_out = 23.9\nrate_min = 1\nrate_max = 12\ncount = 2\n"
                     "[tube]\nenabled = false\n");
}

TEST(ThresholdEnsemble, MajorityOfTheMembersFinishedDecidesTheRegimeOfARate) {
    const std::vector<RegimePoint> members = {{4, "tank-treading"}, {2, "tumbling"},     {4, "tank-treading"}, {2, "tank-treading"},
                                              {4, "tumbling"},      {2, "intermittent"}, {8, ""},              {1, ""},
                                              {1, "tumbling"},      {6, "tank-treading"}, {6, "tumbling"}};
    const std::vector<RegimePoint> p = ensembleRegimePoints(members);
    ASSERT_EQ(p.size(), 5u);
    const std::vector<std::pair<double, std::string>> want = {
        {1, "tumbling"}, {2, "tumbling"}, {4, "tank-treading"}, {6, "intermittent"}, {8, ""}};
    for (std::size_t k = 0; k < want.size(); ++k) {
        EXPECT_EQ(p[k].rate, want[k].first);
        EXPECT_EQ(p[k].regime, want[k].second) << "rate " << want[k].first;
    }
    // 2 of 3 at rate 2 do not tank-tread (tumbling, intermittent); the failed member at 1 is not counted.
    const ThresholdBracket b = thresholdBracket(p);
    EXPECT_EQ(*b.gammaLo, 2.0);
    EXPECT_EQ(*b.gammaHi, 4.0);
}

TEST(ThresholdEnsemble, EveryThresholdRateRunsItsMembersFromRandomStarts) {
    TempDir dir;
    const fs::path cfg = writeText(dir.path() / "e.toml",
                                   "[run]\nlevel = 1\njobs = 2\n[shear]\nrotations = 1\nthreshold_refinements = 1\n"
                                   "threshold_protocol = \"ensemble\"\nthreshold_members = 2\n"
                                   "[[shear.angle]]\neta_out = 23.9\nrate_min = 20\nrate_max = 20\ncount = 1\n"
                                   "[[shear.threshold]]\neta_out = 23.9\nrate_min = 1\nrate_max = 12\ncount = 2\n"
                                   "[tube]\nenabled = false\n");
    const ValidationConfig c = readValidationConfig(cfg, kExperiments);
    EXPECT_EQ(c.thresholdMembers, 2);
    EXPECT_EQ(thresholdMemberCount(c), 2);
    const std::vector<ValidationCase> cases = initialValidationCases(c);
    ASSERT_EQ(cases.size(), 5u);  // one angle case, two rates x two members
    EXPECT_EQ(cases[0].member, 0);
    EXPECT_EQ(cases[1].id, "threshold_eta23.9_rate1_m1");
    EXPECT_EQ(cases[2].id, "threshold_eta23.9_rate1_m2");
    EXPECT_EQ(baseCaseId(cases[2]), "threshold_eta23.9_rate1");
    EXPECT_EQ(cases[4].member, 2);
    const std::string out = (dir.path() / "o").string();
    test::CliRun r = test::runTrbc("validate --config " + cfg.string() + " --out " + out + " --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("threshold_eta23.9_rate12_m2: trbc flow shear --eta-out 23.9 --shear-rate 12 "), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("--start random --seed 2"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("--temperature"), std::string::npos) << r.out;
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const nlohmann::json rec = nlohmann::json::parse(test::slurp(fs::path(out) / "cases" / "threshold_eta23.9_rate12_m1.json"));
    EXPECT_EQ(rec["member"].get<int>(), 1);
    EXPECT_NE(test::slurp(fs::path(out) / "validation.md").find("2 members per rate from random starts"), std::string::npos);
    EXPECT_TRUE(fs::exists(fs::path(out) / "threshold.csv"));
}

// The default protocol is the fluctuating cell: three members per rate at 293.15 K from the
// configured start, each seeded by its member; --threshold-protocol overrides the file, and the
// in-plane protocol gives the cases (and case keys) of one run per rate.
TEST(ThresholdEnsemble, TheDefaultProtocolIsTheFluctuatingCell) {
    TempDir dir;
    const std::string sweeps = "[[shear.threshold]]\neta_out = 23.9\nrate_min = 1\nrate_max = 12\ncount = 2\n[tube]\nenabled = false\n";
    const fs::path cfg = writeText(dir.path() / "f.toml", "[run]\nlevel = 1\njobs = 2\n[shear]\nrotations = 1\n"
                                                          "threshold_refinements = 0\ntilt_deg = 5\n" + sweeps);
    const ValidationConfig c = readValidationConfig(cfg, kExperiments);
    EXPECT_EQ(c.thresholdProtocol, "fluctuating");
    EXPECT_EQ(thresholdMemberCount(c), 3);
    EXPECT_DOUBLE_EQ(c.temperatureK, 293.15);
    ASSERT_EQ(initialValidationCases(c).size(), 6u);
    const std::string out = (dir.path() / "o").string();
    test::CliRun r = test::runTrbc("validate --config " + cfg.string() + " --out " + out + " --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("threshold_eta23.9_rate12_m3: trbc flow shear --eta-out 23.9 --shear-rate 12 "), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("--tilt-deg 5 --temperature 293.15 --seed 3"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("--start random"), std::string::npos) << r.out;
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const nlohmann::json rec = nlohmann::json::parse(test::slurp(fs::path(out) / "cases" / "threshold_eta23.9_rate1_m2.json"));
    EXPECT_EQ(rec["member"].get<int>(), 2);
    EXPECT_GT(rec["result"]["diagnostics"]["thermal"]["kT_internal"].get<double>(), 0.0) << rec.dump(1);
    const nlohmann::json v = nlohmann::json::parse(test::slurp(fs::path(out) / "validation.json"));
    EXPECT_EQ(v["threshold_protocol"]["protocol"], "fluctuating");
    EXPECT_EQ(v["threshold_protocol"]["members_per_rate"], 3);
    EXPECT_NE(test::slurp(fs::path(out) / "validation.md").find("3 thermally fluctuating members per rate at 293.15 K"),
              std::string::npos);
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + (dir.path() / "p").string() +
                          " --threshold-protocol in-plane --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    // The command, and so the case key, of one run per rate as before the protocols existed.
    EXPECT_NE(r.out.find("threshold_eta23.9_rate12: trbc flow shear --eta-out 23.9 --shear-rate 12 --eta-in 10 --level 1 "
                         "--rotations 1 --step-tol 0.001 --tilt-deg 5 \n"),
              std::string::npos)
        << r.out;
    EXPECT_EQ(r.out.find("_m1"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("--temperature"), std::string::npos) << r.out;
    // The shipped config sets the members and the temperature; a config based on it may choose
    // another protocol, and those keys, which it cannot unset, are not refused.
    const fs::path based = writeText(dir.path() / "based.toml", "base = \"" + (kRepo / "configs" / "validation.toml").string() +
                                                                    "\"\n[shear]\nthreshold_protocol = \"in-plane\"\n");
    EXPECT_EQ(thresholdMemberCount(readValidationConfig(based, kExperiments)), 0);
    // Bad input is named with its valid range.
    for (const auto& [text, want] : std::vector<std::pair<std::string, std::string>>{
             {"[shear]\nthreshold_protocol = \"ensemble\"\nthreshold_members = 100\n",
              "'shear.threshold_members' = 100 is out of range: valid range [1, 64]"},
             {"[shear]\nthreshold_members = 0\n", "threshold_protocol = \"in-plane\""},
             {"[shear]\nthreshold_members = 8\n", "'shear.threshold_members' without 'shear.threshold_protocol'"},
             {"[shear]\nthreshold_protocol = \"thermal\"\n", "is not one of: in-plane, ensemble, fluctuating"},
             {"[shear]\ntemperature_K = -3\n", "'shear.temperature_K' = -3 is out of range: valid range (0, 400]"},
             {"[shear]\nthreshold_protocol = \"in-plane\"\nthreshold_members = 3\n",
              "'shear.threshold_members' is not read with threshold_protocol = \"in-plane\""},
             {"[shear]\nthreshold_protocol = \"ensemble\"\ntemperature_K = 300\n",
              "'shear.temperature_K' is not read with threshold_protocol = \"ensemble\": only \"fluctuating\" cells use it"}}) {
        try {
            readValidationConfig(writeText(dir.path() / "b.toml", text), kExperiments);
            ADD_FAILURE() << text << " was accepted";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(want), std::string::npos) << e.what();
        }
    }
}

TEST(ValidateCli, TinySetRunsResumesAndTabulates) {
    TempDir dir;
    const fs::path cfg = writeTinyValidationConfig(dir);
    const std::string out = (dir.path() / "o").string();
    test::CliRun r = test::runTrbc("validate --config " + cfg.string() + " --out " + out, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find("[4/4]"), std::string::npos) << r.err;
    for (const char* f : {"shear.csv", "threshold.csv", "tube.csv", "comparison.csv", "validation.md", "validation.json"})
        EXPECT_TRUE(fs::exists(fs::path(out) / f)) << f;
    // The experimental sets the verdicts compared with, as the figures read them.
    const nlohmann::json data = nlohmann::json::parse(test::slurp(fs::path(out) / "experimental_data.json"));
    EXPECT_TRUE(data == validationDataJson(readValidationDataSets(readValidationConfig(cfg, kExperiments).dataDir)));  // too long to print
    const nlohmann::json j = nlohmann::json::parse(test::slurp(fs::path(out) / "validation.json"));
    const int cases = j["summary"]["cases"].get<int>();
    EXPECT_GE(cases, 4);  // plus the threshold refinement
    EXPECT_EQ(j["summary"]["failed"].get<int>(), 0);
    const std::string shear = test::slurp(fs::path(out) / "shear.csv");
    EXPECT_NE(shear.find("angle_eta23.9_rate20,angle,23.9,20,"), std::string::npos) << shear;
    // The threshold protocol is named where the set ran threshold cases, and only there.
    EXPECT_NE(test::slurp(fs::path(out) / "validation.md").find("Threshold protocol: one run per rate"), std::string::npos);
    r = test::runTrbc("validate --config " + cfg.string() + " --only angle --out " + out + "_angle --import " + out, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("0 run now"), std::string::npos) << r.out;
    EXPECT_EQ(test::slurp(fs::path(out + "_angle") / "validation.md").find("Threshold protocol"), std::string::npos);
    // Resume: nothing runs again; a lost case record (a run killed before it finished) runs again alone.
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("0 run now"), std::string::npos) << r.out;
    fs::remove(fs::path(out) / "cases" / "angle_eta23.9_rate60.json");
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("1 run now"), std::string::npos) << r.out;
    // The dry run marks the finished cases (all of them here) and counts them.
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out + " --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("angle_eta23.9_rate60 [finished]: trbc flow shear"), std::string::npos) << r.out;
    EXPECT_NE(r.err.find(": 4 finished, 0 failed and kept, 0 to run"), std::string::npos) << r.err;
    // A failed record is kept (marked [failed]) unless --retry-failed, which would run it again.
    const fs::path rec = fs::path(out) / "cases" / "angle_eta23.9_rate60.json";
    nlohmann::json failedRecord = nlohmann::json::parse(test::slurp(rec));
    failedRecord["result"]["status"] = "failed";
    std::ofstream(rec) << failedRecord.dump();
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out + " --dry-run", dir.path());
    EXPECT_NE(r.out.find("angle_eta23.9_rate60 [failed]: trbc"), std::string::npos) << r.out;
    EXPECT_NE(r.err.find(": 3 finished, 1 failed and kept, 0 to run"), std::string::npos) << r.err;
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out + " --dry-run --retry-failed --quiet", dir.path());
    EXPECT_NE(r.out.find("angle_eta23.9_rate60: trbc"), std::string::npos) << r.out;
    EXPECT_EQ(r.err.find("to run"), std::string::npos) << r.err;
    // Another cell changes every case's key: everything runs again.
    const fs::path cfg2 = writeText(dir.path() / "tiny2.toml", test::slurp(cfg) + "[cell]\nsource = \"explicit\"\nv = 0.94\nmu_uN_per_m = 4.99\nkb_J = 2.10e-19\nb2 = 1.84\netam_Pa_s_um = 0.3\n");
    r = test::runTrbc("validate --config " + cfg2.string() + " --out " + out + " --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("--etam 0.3\n"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("[finished]"), std::string::npos) << r.out;
    r = test::runTrbc("validate --config " + cfg2.string() + " --out " + out + " --dry-run --level 3", dir.path());
    EXPECT_NE(r.out.find("--level 3"), std::string::npos) << r.out;
    // The tube's settling viscosity: settle_relax by default, settle_etam when given instead.
    const fs::path tubeA = writeText(dir.path() / "tubeA.toml", "[tube]\npressure_gradients = [30]\n");
    r = test::runTrbc("validate --config " + tubeA.string() + " --only tube --out " + out + "_t --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("--settle-relax 1.5 "), std::string::npos) << r.out;
    // The tube's own step tolerance (6.25e-5 by default), whatever [run] step_tol says for the shear.
    EXPECT_NE(r.out.find("--step-tol 6.25e-05 "), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("--settle-etam"), std::string::npos) << r.out;
    const fs::path tubeC = writeText(dir.path() / "tubeC.toml", "[run]\nstep_tol = 0.002\n[tube]\npressure_gradients = [30]\nstep_tol = 3e-4\n");
    const test::CliRun rc = test::runTrbc("validate --config " + tubeC.string() + " --out " + out + "_t --dry-run", dir.path());
    ASSERT_EQ(rc.status, 0) << rc.err;
    EXPECT_NE(rc.out.find("tube_pg30: trbc flow tube"), std::string::npos) << rc.out;
    EXPECT_NE(rc.out.find("--step-tol 0.0003 "), std::string::npos) << rc.out;
    EXPECT_NE(rc.out.find("flow shear"), std::string::npos) << rc.out;
    EXPECT_NE(rc.out.find("--step-tol 0.002 "), std::string::npos) << rc.out;
    const fs::path tubeB = writeText(dir.path() / "tubeB.toml", "[tube]\npressure_gradients = [30]\nsettle_etam = 0.02\n");
    r = test::runTrbc("validate --config " + tubeB.string() + " --only tube --out " + out + "_t --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("--settle-etam 0.02"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("--settle-relax"), std::string::npos) << r.out;
    // Bad config: exit 2 naming the key, nothing written.
    const fs::path bad = writeText(dir.path() / "bad.toml", "[run]\njobs = 0\n");
    r = test::runTrbc("validate --config " + bad.string() + " --out " + (dir.path() / "b").string(), dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("bad.toml:2: 'run.jobs' = 0 is out of range"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir.path() / "b"));
}

// One set run in two parts on "two machines" (separate OUT directories), then merged with --import:
// nothing runs again and the tables are the union of the parts' (the threshold refinement made in
// part 1 is the one the merged run asks for).
TEST(ValidateCli, ShardsRunApartAndImportMergesThem) {
    TempDir dir;
    const fs::path cfg = writeTinyValidationConfig(dir);
    const fs::path o1 = dir.path() / "o1", o2 = dir.path() / "o2", merged = dir.path() / "m";
    const std::string base = "validate --config " + cfg.string();
    test::CliRun r = test::runTrbc(base + " --out " + o1.string() + " --shard 1/2", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("--only/--shard: 3 of the 4 configured initial cases selected"), std::string::npos) << r.out;
    r = test::runTrbc(base + " --out " + o2.string() + " --shard 2/2", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("1 run now"), std::string::npos) << r.out;
    EXPECT_TRUE(fs::exists(o2 / "cases" / "angle_eta23.9_rate60.json"));
    EXPECT_FALSE(fs::exists(o2 / "cases" / "angle_eta23.9_rate20.json"));
    EXPECT_EQ(test::slurp(o2 / "threshold.csv").find("23.9,"), std::string::npos);  // not this part's

    const std::string imports = " --import " + o1.string() + " --import " + o2.string();
    r = test::runTrbc(base + " --out " + merged.string() + imports + " --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find(": 4 finished (4 in --import directories), 0 failed and kept, 0 to run"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(merged));  // a dry run copies nothing
    r = test::runTrbc(base + " --out " + merged.string() + imports, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("0 run now"), std::string::npos) << r.out;
    EXPECT_TRUE(fs::exists(merged / "cases" / "angle_eta23.9_rate60" / "flow.json"));
    const auto rows = [](const fs::path& csv) {
        std::vector<std::string> lines;
        std::istringstream in(test::slurp(csv));
        for (std::string l; std::getline(in, l);)
            if (!l.starts_with('#')) lines.push_back(l);  // not the provenance line
        return lines;
    };
    std::vector<std::string> parts = rows(o1 / "shear.csv"), whole = rows(merged / "shear.csv");
    const std::vector<std::string> second = rows(o2 / "shear.csv");
    parts.insert(parts.end(), second.begin() + 1, second.end());  // without its header
    std::sort(parts.begin(), parts.end());
    std::sort(whole.begin(), whole.end());
    EXPECT_EQ(whole, parts);
    EXPECT_EQ(whole.size(), 6u);  // header, 4 initial cases, 1 refinement
    EXPECT_EQ(tableBody(merged / "threshold.csv"), tableBody(o1 / "threshold.csv"));
    const nlohmann::json j = nlohmann::json::parse(test::slurp(merged / "validation.json"));
    EXPECT_EQ(j["cases_imported"].get<int>(), 5);
    // A stale record in OUT (another cell's key) is replaced by the matching imported one, not kept.
    const fs::path stale = dir.path() / "m3";
    writeText(stale / "cases" / "angle_eta23.9_rate60.json", R"({"key": "another cell", "result": {}})");
    r = test::runTrbc(base + " --out " + stale.string() + imports, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("0 run now"), std::string::npos) << r.out;
    EXPECT_EQ(nlohmann::json::parse(test::slurp(stale / "cases" / "angle_eta23.9_rate60.json"))["key"],
              nlohmann::json::parse(test::slurp(o2 / "cases" / "angle_eta23.9_rate60.json"))["key"]);
    // Another cell: the imported records do not match, so nothing is taken from them.
    const fs::path cfg2 = writeText(dir.path() / "tiny2.toml", test::slurp(cfg) + "[cell]\nsource = \"explicit\"\nv = 0.94\nmu_uN_per_m = 4.99\nkb_J = 2.10e-19\nb2 = 1.84\netam_Pa_s_um = 0.3\n");
    r = test::runTrbc("validate --config " + cfg2.string() + " --out " + (dir.path() / "m2").string() + imports + " --dry-run", dir.path());
    EXPECT_NE(r.err.find(": 0 finished (0 in --import directories), 0 failed and kept, 4 to run"), std::string::npos) << r.err;
    // Bad input: exit 2 naming the option.
    r = test::runTrbc(base + " --out " + merged.string() + " --shard 3/2", dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("--shard '3/2': expected K/N with 1 <= K <= N"), std::string::npos) << r.err;
    r = test::runTrbc(base + " --out " + merged.string() + " --import " + dir.path().string(), dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("not a validate output directory (no cases/ in it)"), std::string::npos) << r.err;
}

// A second validate on the same OUT is refused while the first runs; SIGTERM to validate reaches
// the `trbc flow` cases it started (their own process groups) and leaves none running.
TEST(ValidateCli, LockAndSignalForwarding) {
    using namespace std::chrono_literals;
    TempDir dir;
    const fs::path cfg = writeText(dir.path() / "slow.toml",
                                   "[run]\nlevel = 2\njobs = 2\n[shear]\nrotations = 1000\n"
                                   "[[shear.angle]]\neta_out = 23.9\nrate_min = 20\nrate_max = 60\ncount = 2\n"
                                   "[tube]\nenabled = false\n");
    const fs::path out = dir.path() / "o";
    const fs::path pidFile = dir.path() / "pid";
    ASSERT_EQ(std::system(("(" + test::shellQuote(TRBC_CLI) + " validate --only angle --config " + test::shellQuote(cfg.string()) +
                           " --out " + test::shellQuote(out.string()) + " > " + test::shellQuote((dir.path() / "log").string()) +
                           " 2>&1 & echo $! > " + test::shellQuote(pidFile.string()) + ")")
                              .c_str()),
              0);
    std::this_thread::sleep_for(200ms);
    const pid_t pid = std::stoi(test::slurp(pidFile));
    // Wait until both cases run (their logs exist).
    for (int i = 0; i < 300 && !(fs::exists(out / "cases" / "angle_eta23.9_rate20.log") && fs::exists(out / "cases" / "angle_eta23.9_rate60.log")); ++i)
        std::this_thread::sleep_for(50ms);
    ASSERT_TRUE(fs::exists(out / "cases" / "angle_eta23.9_rate60.log")) << test::slurp(dir.path() / "log");
    ASSERT_GE(test::processesMentioning((out / "cases" / "angle_eta23.9_rate").string()), 2);

    const test::CliRun second = test::runTrbc("validate --only angle --config " + cfg.string() + " --out " + out.string(), dir.path());
    EXPECT_EQ(second.status, 2);
    EXPECT_NE(second.err.find("another trbc process (pid " + std::to_string(pid) + ") is writing into"), std::string::npos) << second.err;

    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    int left = -1;
    for (int i = 0; i < 100; ++i) {
        std::this_thread::sleep_for(50ms);
        left = test::processesMentioning(out.string());
        if (left == 0) break;
    }
    EXPECT_EQ(left, 0) << "cases still running after SIGTERM to validate";
    EXPECT_FALSE(fs::exists(out / "cases" / "angle_eta23.9_rate20.json")) << test::slurp(out / "cases" / "angle_eta23.9_rate20.json");  // interrupted: runs again on resume
}

// A case interrupted by SIGTERM to validate keeps its snapshots (run.checkpoint_interval), and the
// next validate resumes it from them (flow --resume) to the result of an uninterrupted run.
TEST(ValidateCli, AnInterruptedCaseResumesFromItsSnapshots) {
    using namespace std::chrono_literals;
    TempDir dir;
    const fs::path cfg = writeText(dir.path() / "one.toml",
                                   "[run]\nlevel = 2\njobs = 1\ncheckpoint_interval = 0\n[shear]\nrotations = 2\n"
                                   "[[shear.angle]]\neta_out = 23.9\nrate_min = 40\nrate_max = 40\ncount = 1\n"
                                   "[tube]\nenabled = false\n");
    const std::string base = "validate --only angle --quiet --config " + cfg.string();
    const fs::path whole = dir.path() / "whole", out = dir.path() / "o";
    const std::string id = "angle_eta23.9_rate40";
    test::CliRun r = test::runTrbc(base + " --out " + whole.string(), dir.path());
    ASSERT_EQ(r.status, 0) << r.err;

    const fs::path pidFile = dir.path() / "pid";
    ASSERT_EQ(std::system(("(" + test::shellQuote(TRBC_CLI) + " " + base + " --out " + test::shellQuote(out.string()) +
                           " > /dev/null 2>&1 & echo $! > " + test::shellQuote(pidFile.string()) + ")")
                              .c_str()),
              0);
    std::this_thread::sleep_for(100ms);
    const pid_t pid = std::stoi(test::slurp(pidFile));
    const fs::path snapshot = out / "cases" / id / "checkpoint" / "main.bin";
    for (int i = 0; i < 6000 && !fs::exists(snapshot); ++i) std::this_thread::sleep_for(10ms);
    ASSERT_TRUE(fs::exists(snapshot));
    std::this_thread::sleep_for(200ms);
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    const std::string cases = (out / "cases").string();
    for (int i = 0; i < 200 && test::processesMentioning(cases) > 0; ++i) std::this_thread::sleep_for(25ms);
    ASSERT_EQ(test::processesMentioning(cases), 0);
    ASSERT_FALSE(fs::exists(out / "cases" / (id + ".json"))) << "the case finished before it could be interrupted";
    EXPECT_TRUE(fs::exists(snapshot));

    r = test::runTrbc(base + " --out " + out.string(), dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(test::slurp(out / "cases" / (id + ".log")).find("resuming"), std::string::npos);
    const nlohmann::json a = nlohmann::json::parse(test::slurp(whole / "cases" / (id + ".json")));
    const nlohmann::json b = nlohmann::json::parse(test::slurp(out / "cases" / (id + ".json")));
    EXPECT_EQ(a["key"], b["key"]);
    EXPECT_EQ(a["result"]["observables"], b["result"]["observables"]);
    EXPECT_EQ(a["result"]["diagnostics"]["steps"], b["result"]["diagnostics"]["steps"]);
    EXPECT_EQ(b["result"]["diagnostics"]["checkpoint"]["resumes"], 1);
    EXPECT_EQ(tableBody(whole / "cases" / id / "steps.csv"), tableBody(out / "cases" / id / "steps.csv"));
    EXPECT_FALSE(fs::exists(out / "cases" / id / "checkpoint"));
}

}  // namespace
}  // namespace trbc
