// trbc validate over draws of a theta_new posterior: the seeded choice of the draws, the median
// and 5-95 % band with the band verdict, the tilted shear start, the reference-cell
// configuration, and a tiny banded set run end to end and resumed.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <filesystem>
#include <fstream>
#include <random>

#include "analysis/validation.hpp"
#include "analysis/validation_draws.hpp"
#include "inference/rbc_problem.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "flow/shear_case.hpp"
#include "inference/statistics.hpp"
#include "mesh/io.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::TempDir;
using test::writeText;

using test::tableBody;

const fs::path kRepo = test::sourceRoot();
const fs::path kExperiments = test::experimentsDir();

/// A theta_new samples.csv of `rows` samples inside the prior box, each row distinct.
fs::path writeFakePosterior(const fs::path& dir, int rows) {
    // b2 runs past the single-cell prior's [0, 4] from the fourth row on, as a population's draws do.
    std::string csv = "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n";
    for (int k = 0; k < rows; ++k)
        csv += fmt::format("{},{},{},{},{}\n", 0.92 + 0.004 * k, 4.5 + 0.1 * k, 2.0e-19 + 1e-21 * k, 2.9 + 0.4 * k, 0.5 + 0.02 * k);
    writeText(dir / "samples.csv", csv);
    return dir;
}

// The columns read from a theta_new table are those the inference writes.
TEST(ValidationDraws, ThetaNewColumnsAreTheInferencesParameters) {
    const std::vector<std::string>& names = RbcPriorBox::parameterNames();
    ASSERT_EQ(names.size(), kThetaNewColumns.size());
    for (std::size_t k = 0; k < names.size(); ++k) EXPECT_EQ(names[k], kThetaNewColumns[k]);
}

TEST(ValidationDraws, ChoiceIsSeededReproducibleAndNested) {
    TempDir dir;
    const NumericTable t = readNumericTable(writeFakePosterior(dir.path() / "post", 20) / "samples.csv");
    const std::vector<PosteriorDraw> a = selectPosteriorDraws(t, 5, 7), b = selectPosteriorDraws(t, 5, 7);
    ASSERT_EQ(a.size(), 5u);
    std::vector<long> sa, sb, sc, big;
    for (const PosteriorDraw& d : a) sa.push_back(d.sample);
    for (const PosteriorDraw& d : b) sb.push_back(d.sample);
    for (const PosteriorDraw& d : selectPosteriorDraws(t, 5, 8)) sc.push_back(d.sample);
    for (const PosteriorDraw& d : selectPosteriorDraws(t, 12, 7)) big.push_back(d.sample);
    EXPECT_EQ(sa, sb);  // same seed, same draws
    EXPECT_NE(sa, sc);  // another seed, others
    EXPECT_TRUE(std::is_sorted(sa.begin(), sa.end()));
    EXPECT_EQ(std::adjacent_find(sa.begin(), sa.end()), sa.end());  // distinct
    for (long s : sa) EXPECT_NE(std::find(big.begin(), big.end(), s), big.end()) << s;  // more draws keep these
    for (const PosteriorDraw& d : a) {  // each draw is its sample's row
        EXPECT_DOUBLE_EQ(d.v, t.values(d.sample, 0));
        EXPECT_DOUBLE_EQ(d.mu, t.values(d.sample, 1));
        EXPECT_DOUBLE_EQ(d.kbJ, t.values(d.sample, 2));
        EXPECT_DOUBLE_EQ(d.b2, t.values(d.sample, 3));
        EXPECT_DOUBLE_EQ(d.etam, t.values(d.sample, 4));
    }
    EXPECT_EQ(selectPosteriorDraws(t, 20, 3).size(), 20u);
    std::string e = test::inputError([&] { selectPosteriorDraws(t, 21, 7); });
    EXPECT_NE(e.find("--draws 21: out of range: valid range [1, 20]"), std::string::npos) << e;
    e = test::inputError([&] { selectPosteriorDraws(t, 0, 7); });
    EXPECT_NE(e.find("--draws 0: out of range"), std::string::npos) << e;

    const std::vector<ValidationCase> cases = casesWithDraws({{"angle_eta23.9_rate20", "angle", 23.9, 20.0, 0.0}}, {a[0], a[1]});
    ASSERT_EQ(cases.size(), 3u);
    EXPECT_EQ(cases[0].sample, -1);
    EXPECT_EQ(cases[2].id, fmt::format("angle_eta23.9_rate20_sample{}", a[1].sample));
    EXPECT_EQ(cases[2].sample, a[1].sample);
    EXPECT_DOUBLE_EQ(cases[2].rate, 20.0);
}

TEST(ValidationDraws, MedianBandAndBandVerdictOnHandMadeNumbers) {
    std::vector<DrawOutcome> o;
    for (int k = 21; k >= 1; --k) o.push_back({true, static_cast<double>(k), ""});
    o.push_back({false, NAN, "exit 1 without a result"});
    o.push_back({true, NAN, "no value (tumbling)"});
    o.push_back({true, NAN, "no value (tumbling)"});
    const DrawBand b = drawBand(o);
    EXPECT_EQ(b.draws, 24);
    EXPECT_EQ(b.finished, 23);
    EXPECT_EQ(b.failed, 1);
    EXPECT_EQ(b.withValue, 21);
    EXPECT_DOUBLE_EQ(b.median, 11.0);  // type 7 on 1..21: h = 20 p
    EXPECT_DOUBLE_EQ(b.lo, 2.0);
    EXPECT_DOUBLE_EQ(b.hi, 20.0);
    EXPECT_EQ(drawReasonsText(b), "1 x exit 1 without a result; 2 x no value (tumbling)");
    ScatterComparison s;
    s.points = 4, s.lo = 19.5, s.hi = 30.0;
    EXPECT_EQ(bandVerdict(b, s), "overlap");
    s.lo = 20.5;
    EXPECT_EQ(bandVerdict(b, s), "no overlap");
    s.lo = -5.0, s.hi = 1.5;
    EXPECT_EQ(bandVerdict(b, s), "no overlap");
    s.hi = 2.0;
    EXPECT_EQ(bandVerdict(b, s), "overlap");  // the band's ends count
    s.points = 0;
    EXPECT_EQ(bandVerdict(b, s), "no data");
    s.points = 3;
    EXPECT_EQ(bandVerdict(drawBand({{false, NAN, "x"}}), s), "no prediction");
    EXPECT_EQ(bandVerdict(drawBand({{true, NAN, "no value (tumbling)"}}), s), "no overlap");
    EXPECT_EQ(bandVerdict(drawBand({{true, NAN, "not bracketed"}}), s, false), "no prediction");
    const DrawBand one = drawBand({{true, 3.0, ""}});
    EXPECT_DOUBLE_EQ(one.lo, 3.0);
    EXPECT_DOUBLE_EQ(one.hi, 3.0);
    EXPECT_DOUBLE_EQ(one.loMcse, 0.0);
    EXPECT_TRUE(std::isnan(drawBand({}).median));
    EXPECT_TRUE(std::isnan(drawBand({}).medianMcse));
}

TEST(ValidationDraws, QuantileMcseOnHandMadeNumbers) {
    // Values 1..21: the type-7 quantile is 1 + 20 p inside [0, 1], so the MCSE is
    // 20 sqrt(p (1 - p) / 21) while p -+ that spread stays inside [0, 1].
    std::vector<DrawOutcome> o;
    for (int k = 1; k <= 21; ++k) o.push_back({true, static_cast<double>(k), ""});
    const DrawBand b = drawBand(o);
    const auto spread = [](double p) { return 20.0 * std::sqrt(p * (1.0 - p) / 21.0); };
    EXPECT_NEAR(b.medianMcse, spread(0.5), 1e-12);
    EXPECT_NEAR(b.loMcse, spread(0.05), 1e-12);
    EXPECT_NEAR(b.hiMcse, spread(0.95), 1e-12);
    // Three draws: 0.05 -+ 0.126 is clamped at 0, so the lower end's spread is one-sided.
    const DrawBand three = drawBand({{true, 0.0, ""}, {true, 1.0, ""}, {true, 2.0, ""}});
    const double se = std::sqrt(0.05 * 0.95 / 3.0);
    EXPECT_NEAR(three.loMcse, 0.5 * 2.0 * (0.05 + se), 1e-12);
    EXPECT_TRUE(three.endsMcseIsLowerBound);
    EXPECT_FALSE(b.endsMcseIsLowerBound);  // 21 draws: the levels stay inside [0, 1]
    // The edge: sqrt(0.05 0.95 / 19) = 0.05 exactly, so 19 draws reach level 0 without clamping.
    for (const double p : {0.05, 0.95}) {
        EXPECT_TRUE(quantileMcseIsLowerBound(p, 18.0)) << p;
        EXPECT_FALSE(quantileMcseIsLowerBound(p, 19.0)) << p;
    }
}

TEST(ValidationDraws, QuantileMcseMatchesTheSpreadOfRepeatedBands) {
    // 2000 bands of 32 independent standard-normal draws: the root-mean-square MCSE against the
    // actual SD of the estimates over the repeats (seeded). For n = 32 the estimate is about 1.05x
    // at the median and 1.16x at the 5 and 95 % ends (the SD itself to 1.6 % with 2000 repeats);
    // the bounds catch a factor of sqrt(2) either way.
    std::mt19937_64 rng(7);
    std::normal_distribution<double> normal;
    const int repeats = 2000, n = 32;
    std::array<double, 3> sum{}, sumSq{}, mcseSq{};
    for (int r = 0; r < repeats; ++r) {
        std::vector<DrawOutcome> o;
        for (int k = 0; k < n; ++k) o.push_back({true, normal(rng), ""});
        const DrawBand b = drawBand(o);
        const std::array<double, 3> est{b.median, b.lo, b.hi}, err{b.medianMcse, b.loMcse, b.hiMcse};
        for (int i = 0; i < 3; ++i) sum[i] += est[i], sumSq[i] += est[i] * est[i], mcseSq[i] += err[i] * err[i];
    }
    for (int i = 0; i < 3; ++i) {
        const double mean = sum[i] / repeats, sd = std::sqrt(sumSq[i] / repeats - mean * mean);
        const double ratio = std::sqrt(mcseSq[i] / repeats) / sd;
        EXPECT_GT(ratio, 0.8) << "quantile " << i;
        EXPECT_LT(ratio, 1.4) << "quantile " << i;
    }
}

TEST(ValidationDraws, BandVerdictWithinMcseOnHandMadeNumbers) {
    DrawBand b;
    b.withValue = 20, b.finished = 20, b.draws = 20;
    b.lo = 2.0, b.hi = 10.0, b.loMcse = 0.5, b.hiMcse = 1.0;
    ScatterComparison s;
    s.points = 3, s.lo = 9.5, s.hi = 12.0;  // overlap by 0.5 at the top, hi's MCSE 1.0
    EXPECT_EQ(bandVerdict(b, s), "overlap");
    EXPECT_TRUE(bandVerdictWithinMcse(b, s));
    s.lo = 8.0;  // overlap by 2.0
    EXPECT_FALSE(bandVerdictWithinMcse(b, s));
    s.lo = 10.8;  // no overlap, gap 0.8 below hi's MCSE
    EXPECT_EQ(bandVerdict(b, s), "no overlap");
    EXPECT_TRUE(bandVerdictWithinMcse(b, s));
    s.lo = 11.5;  // gap 1.5
    EXPECT_FALSE(bandVerdictWithinMcse(b, s));
    s.lo = -3.0, s.hi = 1.6;  // band above the scatter, gap 0.4 below lo's MCSE
    EXPECT_TRUE(bandVerdictWithinMcse(b, s));
    s.hi = 1.0;  // gap 1.0
    EXPECT_FALSE(bandVerdictWithinMcse(b, s));
    s.lo = 0.0, s.hi = 20.0;  // the scatter holds the band
    EXPECT_FALSE(bandVerdictWithinMcse(b, s));
    b.endsMcseIsLowerBound = true;  // few draws: the ends' errors are lower bounds
    EXPECT_TRUE(bandVerdictWithinMcse(b, s));
    s.points = 0;
    EXPECT_FALSE(bandVerdictWithinMcse(b, s));
}

TEST(ValidationDraws, CriticalStressOfADrawIsTheBracketsLogCentre) {
    const DrawOutcome a = criticalStressOutcome({{1.0, "tumbling"}, {4.0, "tank-treading"}, {8.0, "tank-treading"}}, 10.0);
    EXPECT_TRUE(a.finished);
    EXPECT_NEAR(a.value, std::sqrt(0.01 * 0.04), 1e-15);  // tau = eta gamma: 10 mPa s x 1/s and 4/s
    DrawOutcome b = criticalStressOutcome({{1.0, "tumbling"}, {2.0, "tumbling"}}, 10.0);
    EXPECT_TRUE(b.finished);
    EXPECT_TRUE(std::isnan(b.value));
    EXPECT_EQ(b.reason, "not bracketed");
    b = criticalStressOutcome({{4.0, "tumbling"}, {2.0, "tank-treading"}}, 10.0);
    EXPECT_EQ(b.reason, "not monotone");
    b = criticalStressOutcome({{1.0, ""}, {2.0, ""}}, 10.0);
    EXPECT_FALSE(b.finished);
    EXPECT_EQ(b.reason, "every threshold case failed");
}

TEST(ShearTilt, TurnsTheStartAboutTheFlowAxisAndChecksItsRange) {
    // A flat disc-like cloud with its symmetry axis along the gradient direction y.
    Vertices X(3, 4);
    X << 1, -1, 0, 0, /**/ 0.2, 0.2, 0.2, 0.2, /**/ 0, 0, 1, -1;
    const Vertices Y = tiltAboutFlowAxis(X, 30.0);
    const double c = std::cos(M_PI / 6), s = std::sin(M_PI / 6);
    EXPECT_NEAR((Y.rowwise().mean() - X.rowwise().mean()).norm(), 0.0, 1e-15);  // about the centroid
    EXPECT_NEAR((Y.row(0) - X.row(0)).norm(), 0.0, 1e-15);                      // x unchanged
    // The point (0, 0.2, 1) relative to the centroid (0, 0.2, 0) is (0, 0, 1) -> (0, -sin, cos).
    EXPECT_NEAR(Y(1, 2) - 0.2, -s, 1e-14);
    EXPECT_NEAR(Y(2, 2), c, 1e-14);
    EXPECT_NEAR((tiltAboutFlowAxis(X, 0.0) - X).norm(), 0.0, 0.0);

    ShearCaseOptions o;
    o.etaOut = 23.9;
    o.shearRate = 20.0;
    o.tiltDeg = 90.0;
    EXPECT_NO_THROW(validateShearCaseOptions(o));
    for (double bad : {-1.0, 90.5, std::numeric_limits<double>::quiet_NaN()}) {
        o.tiltDeg = bad;
        const std::string e = test::inputError([&] { validateShearCaseOptions(o); });
        EXPECT_NE(e.find("parameter tilt_deg"), std::string::npos) << e;
        EXPECT_NE(e.find("(valid: [0, 90] deg)"), std::string::npos) << e;
    }
    TempDir dir;
    const test::CliRun r = test::runTrbc("flow shear --eta-out 23.9 --shear-rate 20 --tilt-deg 91", dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("--tilt-deg"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("[0, 90] deg"), std::string::npos) << r.err;
}

/// The disc's normal: the principal axis of least spread of the vertices.
Eigen::Vector3d discNormal(const Vertices& X) {
    const Vertices d = X.colwise() - X.rowwise().mean();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(d * d.transpose());
    return eig.eigenvectors().col(0);  // ascending eigenvalues
}

TEST(ShearTilt, FlowShearStartsFromTheTiltedCell) {
    TempDir dir;
    const std::string base = "flow shear --eta-out 23.9 --shear-rate 40 --level 1 --rotations 1 --no-cache --out ";
    test::CliRun r = test::runTrbc(base + (dir.path() / "t").string() + " --tilt-deg 30", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(test::slurp(dir.path() / "t" / "flow.json"));
    EXPECT_DOUBLE_EQ(j["parameters"]["tilt_deg"].get<double>(), 30.0);
    const Eigen::Vector3d n = discNormal(readMesh((dir.path() / "t" / "initial.vtk").string()).X);
    EXPECT_NEAR(std::abs(n.x()), 0.0, 1e-6);
    EXPECT_NEAR(std::abs(n.y()), std::cos(M_PI / 6), 1e-6);
    EXPECT_NEAR(std::abs(n.z()), std::sin(M_PI / 6), 1e-6);
}

TEST(ValidationConfig, ReferenceCellConfigOverridesTheCellOfItsBase) {
    const ValidationConfig base = readValidationConfig(kRepo / "configs" / "validation.toml", kExperiments);
    const ValidationConfig c = readValidationConfig(kRepo / "configs" / "validation_reference_cell.toml", kExperiments);
    EXPECT_EQ(c.cellSource, "explicit");
    EXPECT_DOUBLE_EQ(c.v, 0.95);
    EXPECT_DOUBLE_EQ(c.etam, 0.42);
    EXPECT_DOUBLE_EQ(c.mu, 4.99);
    EXPECT_DOUBLE_EQ(c.kbJ, 2.10e-19);
    EXPECT_DOUBLE_EQ(c.b2, 1.84);
    ASSERT_EQ(c.bases.size(), 1u);
    EXPECT_EQ(c.bases[0].filename(), "validation.toml");
    EXPECT_EQ(initialValidationCases(c).size(), initialValidationCases(base).size());
    EXPECT_EQ(c.dataDir, base.dataDir);
    EXPECT_DOUBLE_EQ(c.tiltDeg, 0.0);
    TempDir dir;
    const fs::path bad = writeText(dir.path() / "v.toml", "[shear]\ntilt_deg = 100\n");
    const std::string e = test::inputError([&] { readValidationConfig(bad, kExperiments); });
    EXPECT_NE(e.find("v.toml:2: 'shear.tilt_deg' = 100 is out of range: valid range [0, 90]"), std::string::npos) << e;
    const fs::path tilted = writeText(dir.path() / "t.toml", "base = \"" + (kRepo / "configs" / "validation.toml").string() +
                                                                 "\"\n[shear]\ntilt_deg = 5\n");
    EXPECT_DOUBLE_EQ(readValidationConfig(tilted, kExperiments).tiltDeg, 5.0);
}

// Two draws of a fake posterior on a tiny set (level 1, four rotations): every case runs for the
// configured cell and for each draw; the tables carry the bands; the configured cell's tables are
// those of a run without draws; a lost (case, draw) record runs again alone; bad input is named.
TEST(ValidateCli, TinySetWithTwoDrawsBandsAndResumes) {
    TempDir dir;
    const fs::path post = writeFakePosterior(dir.path() / "post", 6);
    const fs::path cfg = writeText(dir.path() / "tiny.toml",
                                   "[run]\nlevel = 1\njobs = 2\n[shear]\nrotations = 4\nthreshold_refinements = 0\nthreshold_protocol = \"in-plane\"\n"
                                   "[[shear.angle]]\neta_out = 23.9\nrate_min = 40\nrate_max = 40\ncount = 1\n"
                                   "[[shear.threshold]]\neta_out = 23.9\nrate_min = 1\nrate_max = 12\ncount = 2\n"
                                   "[tube]\nenabled = false\n");
    const fs::path out = dir.path() / "o", plain = dir.path() / "p";
    const std::string base = "validate --config " + cfg.string() + " --posterior " + post.string();
    test::CliRun r = test::runTrbc(base + " --out " + out.string() + " --draws 2 --seed 5", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("posterior draws: 2 (seed 5), 6 runs (0 failed)"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("9 run now"), std::string::npos) << r.out;  // 3 cases x (cell + 2 draws)
    // The figures draw the bands without an error (where matplotlib is installed).
    const std::string plotLog = test::slurp(out / "plot.log");
    EXPECT_EQ(plotLog.find("error while drawing"), std::string::npos) << plotLog;
    if (plotLog.find("Error") == std::string::npos) {
        EXPECT_TRUE(fs::exists(out / "figures" / "angle_vs_shear_rate.png")) << plotLog;
    }
    const std::vector<PosteriorDraw> draws = selectPosteriorDraws(readNumericTable(post / "samples.csv"), 2, 5);
    // A draw outside the single-cell prior box runs all the same.
    EXPECT_TRUE(std::any_of(draws.begin(), draws.end(), [](const PosteriorDraw& d) { return d.b2 > 4.0; }));
    const nlohmann::json j = nlohmann::json::parse(test::slurp(out / "validation.json"));
    EXPECT_EQ(j["draws"]["seed"].get<int>(), 5);
    EXPECT_EQ(j["draws"]["samples"], nlohmann::json({draws[0].sample, draws[1].sample}));
    EXPECT_EQ(j["summary"]["cases"].get<int>(), 3);
    EXPECT_EQ(j["summary"]["draws"]["kinds"]["threshold"]["compared"].get<int>(), 1);
    const std::string id = fmt::format("angle_eta23.9_rate40_sample{}", draws[1].sample);
    const nlohmann::json rec = nlohmann::json::parse(test::slurp(out / "cases" / (id + ".json")));
    EXPECT_EQ(rec["draw"]["seed"].get<int>(), 5);
    EXPECT_DOUBLE_EQ(rec["result"]["parameters"]["cell"]["etam_Pa_s_um"].get<double>(), draws[1].etam);
    const std::string bands = test::slurp(out / "bands.csv"), md = test::slurp(out / "validation.md");
    EXPECT_NE(bands.find("angle_eta23.9_rate40,angle,inclination [deg],"), std::string::npos) << bands;
    EXPECT_NE(bands.find("threshold_eta23.9,threshold,critical stress [Pa],"), std::string::npos) << bands;
    EXPECT_NE(md.find("## Posterior draws"), std::string::npos) << md;
    EXPECT_NE(md.find("| kind | compared | mean cell inside | band overlaps | band verdicts within MC error |"), std::string::npos)
        << md;
    EXPECT_NE(test::slurp(out / "draws.csv").find(id + ",angle_eta23.9_rate40,angle,"), std::string::npos);
    // The angle's band is that of the two draws' records (both tank-tread at 40/s).
    std::vector<DrawOutcome> angles;
    for (const PosteriorDraw& d : draws) {
        const nlohmann::json x = nlohmann::json::parse(test::slurp(out / "cases" / fmt::format("angle_eta23.9_rate40_sample{}.json", d.sample)));
        ASSERT_EQ(x["result"]["observables"]["regime"], "tank-treading") << x.dump();
        angles.push_back({true, x["result"]["observables"]["inclination_deg"].get<double>(), ""});
    }
    const DrawBand expected = drawBand(angles);
    const nlohmann::json angleRow = j["draws"]["bands"][0];
    EXPECT_EQ(angleRow["case"], "angle_eta23.9_rate40");
    EXPECT_EQ(angleRow["with_value"].get<int>(), 2);
    EXPECT_DOUBLE_EQ(angleRow["median"].get<double>(), expected.median);
    EXPECT_DOUBLE_EQ(angleRow["q05"].get<double>(), expected.lo);
    EXPECT_DOUBLE_EQ(angleRow["q95"].get<double>(), expected.hi);
    EXPECT_DOUBLE_EQ(angleRow["q05_mcse"].get<double>(), expected.loMcse);
    EXPECT_LT(expected.lo, expected.hi);  // two different cells
    ScatterComparison scatter;
    scatter.lo = angleRow["scatter_lo"].get<double>(), scatter.hi = angleRow["scatter_hi"].get<double>();
    scatter.points = angleRow["points"].get<int>();
    EXPECT_GT(scatter.points, 0);
    EXPECT_EQ(angleRow["band_verdict"], bandVerdict(expected, scatter));
    EXPECT_EQ(angleRow["band_verdict_within_mcse"].get<bool>(), bandVerdictWithinMcse(expected, scatter));

    // Without --draws: the configured cell's outputs as before, the same as the banded run's.
    r = test::runTrbc(base + " --out " + plain.string(), dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(tableBody(plain / "comparison.csv"), tableBody(out / "comparison.csv"));
    EXPECT_EQ(md.rfind(test::slurp(plain / "validation.md"), 0), 0u);
    EXPECT_FALSE(fs::exists(plain / "bands.csv"));
    EXPECT_FALSE(nlohmann::json::parse(test::slurp(plain / "validation.json")).contains("draws"));

    // Resume: nothing again; a lost (case, draw) record runs again alone, with the same result.
    r = test::runTrbc(base + " --out " + out.string() + " --draws 2 --seed 5", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("0 run now"), std::string::npos) << r.out;
    fs::remove(out / "cases" / (id + ".json"));
    r = test::runTrbc(base + " --out " + out.string() + " --draws 2 --seed 5", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("1 run now"), std::string::npos) << r.out;
    EXPECT_EQ(nlohmann::json::parse(test::slurp(out / "cases" / (id + ".json")))["result"]["observables"], rec["result"]["observables"]);
    EXPECT_EQ(test::slurp(out / "bands.csv"), bands);
    // Importable: another OUT takes every (case, draw) from this one.
    r = test::runTrbc(base + " --out " + (dir.path() / "m").string() + " --draws 2 --seed 5 --dry-run --import " + out.string(),
                      dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find(": 9 finished (9 in --import directories), 0 failed and kept, 0 to run"), std::string::npos) << r.err;
    // Another seed draws other samples: a sample drawn before is finished, the others are to run.
    r = test::runTrbc(base + " --out " + out.string() + " --draws 2 --seed 6 --dry-run", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("angle_eta23.9_rate40 [finished]"), std::string::npos) << r.out;
    int fresh = 0;
    for (const PosteriorDraw& d : selectPosteriorDraws(readNumericTable(post / "samples.csv"), 2, 6)) {
        const bool before = d.sample == draws[0].sample || d.sample == draws[1].sample;
        fresh += !before;
        const std::string line = fmt::format("angle_eta23.9_rate40_sample{}{}: trbc flow shear", d.sample, before ? " [finished]" : "");
        EXPECT_NE(r.out.find(line), std::string::npos) << line << "\n" << r.out;
    }
    EXPECT_GT(fresh, 0);
    // Bad input: exit 2 naming the option and the range.
    r = test::runTrbc(base + " --out " + out.string() + " --draws 7", dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("--draws 7: out of range: valid range [1, 6]"), std::string::npos) << r.err;
    r = test::runTrbc("validate --config " + cfg.string() + " --out " + out.string() + " --draws 2", dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("--draws 2: draws are taken from a theta_new posterior; give --posterior DIR"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace trbc
