// The flow networks against direct runs of the same draws (analysis/flow_cross_check.hpp): the
// comparison on hand-made outcomes with known answers, and `validate --surrogate --direct` on a
// tiny direct run at level 1 read back case by case, with its errors.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fmt/format.h>

#include <cmath>
#include <filesystem>

#include "analysis/flow_bands.hpp"
#include "analysis/flow_cross_check.hpp"
#include "core/csv.hpp"
#include "sampling/shear_campaign_table.hpp"
#include "surrogate/flow_surrogate.hpp"
#include "synthetic_shear_campaign.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

std::vector<DrawOutcome> values(const std::vector<double>& v) {
    std::vector<DrawOutcome> out;
    for (double x : v) out.push_back(std::isfinite(x) ? DrawOutcome{true, x, ""} : DrawOutcome{true, NAN, "no value (tumbling)"});
    return out;
}

TEST(FlowCrossCheck, PairsSharesAndQuantilesOnHandMadeOutcomes) {
    const ValidationCase c{"angle_eta23.9_rate40", "angle", 23.9, 40.0, 0.0};
    std::vector<double> direct, shifted, far;
    for (int k = 0; k < 16; ++k) direct.push_back(10.0 + k), shifted.push_back(10.5 + k), far.push_back(30.0 + k);
    // The networks 0.5 deg above every draw: mean and RMS difference 0.5, within the MC errors.
    FlowCrossCheckRow r = compareWithDirect(c, "inclination [deg]", values(direct), values(shifted), drawBand(values(shifted)));
    EXPECT_EQ(r.pairs, 16);
    EXPECT_EQ(r.pairsAlike, 16);
    EXPECT_EQ(r.paired, 16);
    EXPECT_DOUBLE_EQ(r.meanDifference, 0.5);
    EXPECT_DOUBLE_EQ(r.rmsDifference, 0.5);
    EXPECT_TRUE(r.agrees) << r.note;
    EXPECT_NE(r.note.find("lower bounds"), std::string::npos);  // 16 draws: the ends' errors are lower bounds

    // 20 deg above: the median and both ends differ, each by its number of combined errors.
    r = compareWithDirect(c, "inclination [deg]", values(direct), values(far), drawBand(values(far)));
    EXPECT_FALSE(r.agrees);
    EXPECT_DOUBLE_EQ(r.rmsDifference, 20.0);
    const DrawBand d = drawBand(values(direct)), n = drawBand(values(far));
    EXPECT_NE(r.note.find(fmt::format("median by 20 ({:.1f} errors)", 20.0 / std::hypot(d.medianMcse, n.medianMcse))), std::string::npos)
        << r.note;
    EXPECT_NE(r.note.find("ends not compared"), std::string::npos) << r.note;  // 16 values: lower bounds

    // 40 values: the ends are compared too. A band three times as wide about the same median
    // agrees in the median and differs at both ends.
    std::vector<double> many40, wide40;
    for (int k = 0; k < 40; ++k) many40.push_back(10.0 + 0.25 * k), wide40.push_back(14.875 + 3.0 * (0.25 * k - 4.875));
    r = compareWithDirect(c, "inclination [deg]", values(many40), values(wide40), drawBand(values(wide40)));
    EXPECT_FALSE(r.agrees);
    EXPECT_EQ(r.note.find("median"), std::string::npos) << r.note;
    EXPECT_NE(r.note.find("5 % by -"), std::string::npos) << r.note;
    EXPECT_NE(r.note.find("95 % by "), std::string::npos) << r.note;
    EXPECT_EQ(r.note.find("not compared"), std::string::npos) << r.note;

    // Half of 1000 network draws tumble where every direct draw tank-treads: pooled share 516/1016,
    // error sqrt(p (1 - p) (1/16 + 1/1000)) = 0.1261, 0.5 / 0.1261 = 3.97 errors.
    std::vector<double> many;
    for (int k = 0; k < 1000; ++k) many.push_back(k % 2 ? 10.0 + 15.0 * k / 999.0 : NAN);
    r = compareWithDirect(c, "inclination [deg]", values(direct), values(shifted), drawBand(values(many)));
    EXPECT_FALSE(r.agrees);
    EXPECT_NE(r.note.find("share with a value 0.50 against 1.00 (4.0 errors)"), std::string::npos) << r.note;

    // Two draws of the pair disagree on the regime, one failed: 15 pairs, 13 alike, 13 with a value in both.
    std::vector<DrawOutcome> a = values(direct), b = values(shifted);
    a[0].value = NAN, b[1].value = NAN, a[2] = {false, NAN, "diverged"};
    r = compareWithDirect(c, "inclination [deg]", a, b, drawBand(b));
    EXPECT_EQ(r.pairs, 15);
    EXPECT_EQ(r.pairsAlike, 13);
    EXPECT_EQ(r.paired, 13);
    EXPECT_EQ(r.direct.finished, 15);
    EXPECT_EQ(r.networkPaired.finished, 15);  // the networks' band of the same draws leaves the failed one out
    EXPECT_EQ(r.networkPaired.withValue, 14);

    // No value in either (a cell that tumbles in both): only the shares are compared, and agree.
    const std::vector<double> none(8, NAN);
    r = compareWithDirect(c, "inclination [deg]", values(none), values(none), drawBand(values(std::vector<double>(100, NAN))));
    EXPECT_TRUE(r.agrees) << r.note;
    EXPECT_EQ(r.paired, 0);
    EXPECT_TRUE(std::isnan(r.rmsDifference));
    const std::string md = flowCrossCheckMarkdown({r});
    EXPECT_NE(md.find("| angle | 1 | 1 |"), std::string::npos) << md;
    EXPECT_NE(flowCrossCheckCsv({r}).find("angle_eta23.9_rate40,angle,inclination [deg],23.9,40,8,0,"), std::string::npos);
}

/// Networks of a synthetic campaign: tank-treading above a stress proportional to mu, an angle
/// falling with the stress. Small and quick: the test is of the bookkeeping, not of the fit.
FlowSurrogate syntheticModel() {
    const std::vector<ShearCampaignRow> rows =
        test::syntheticShearCampaign(256, 3, [](const ShearCampaignPoint& q) { return 0.02 * q.cell.mu; }, {25.0, 3.0, 0.0});
    FlowSurrogateTrainingOptions opt;
    opt.restarts = 1;
    opt.network.hiddenLayers = {8};
    opt.network.maxEpochs = 60;
    return trainFlowSurrogate(rows, opt).model;
}

TEST(ValidateCli, SurrogateAgainstADirectRunOfTheSameDraws) {
    test::TempDir dir;
    std::string csv = "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n";
    for (int k = 0; k < 8; ++k) csv += fmt::format("{},{},{},{},{}\n", 0.92 + 0.004 * k, 4.5 + 0.1 * k, 2.0e-19 + 1e-21 * k, 1.9 + 0.2 * k, 0.5 + 0.02 * k);
    test::writeText(dir.path() / "post" / "samples.csv", csv);
    const fs::path cfg = test::writeText(dir.path() / "tiny.toml",
                                         "[run]\nlevel = 1\njobs = 2\n[shear]\nrotations = 4\nthreshold_refinements = 1\n"
                                         "threshold_protocol = \"in-plane\"\n"
                                         "[[shear.angle]]\neta_out = 23.9\nrate_min = 40\nrate_max = 40\ncount = 1\n"
                                         "[[shear.threshold]]\neta_out = 23.9\nrate_min = 1\nrate_max = 12\ncount = 2\n"
                                         "[tube]\nenabled = false\n");
    const fs::path direct = dir.path() / "direct", out = dir.path() / "nets", model = dir.path() / "model";
    syntheticModel().save(model);
    const std::string base = "validate --config " + cfg.string() + " --posterior " + (dir.path() / "post").string();
    test::CliRun r = test::runTrbc(base + " --out " + direct.string() + " --draws 2 --seed 5 --quiet", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;

    r = test::runTrbc(base + " --out " + out.string() + " --draws 6 --seed 5 --surrogate " + model.string() + " --direct " + direct.string(),
                      dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("# The flow networks against direct runs"), std::string::npos) << r.out;
    // The synthetic networks' angles are of random starts, the direct run's of the in-plane one.
    EXPECT_NE(r.out.find("The direct angles and TTF start in-plane, the networks' from random starts."), std::string::npos) << r.out;
    EXPECT_NE(test::slurp(out / "surrogate_bands.md").find("The angles and TTF are the tank-treading state's from random starts."),
              std::string::npos);
    const nlohmann::json run = nlohmann::json::parse(test::slurp(direct / "validation.json"));
    const nlohmann::json bands = nlohmann::json::parse(test::slurp(out / "surrogate_bands.json"));
    EXPECT_EQ(bands["cross_check"]["compared"].get<int>(), 2);  // the angle case and the threshold viscosity
    EXPECT_EQ(bands["cross_check"]["direct_draws"].get<int>(), 2);
    EXPECT_EQ(bands["cross_check"]["direct_runs_missing"].get<int>(), 0);
    // The direct band is the direct run's own; the networks' band over the 6 draws is surrogate_bands'.
    const NumericTable table = readNumericTable(out / "surrogate_cross_check.csv",
                                                {"direct_draws", "direct_with_value", "direct_median", "paired_network_with_value",
                                                 "network_draws", "network_with_value", "network_median"},
                                                {"direct_median", "network_median"});
    const NumericTable surrogate = readNumericTable(out / "surrogate_bands.csv", {"with_value", "median"}, {"median"});
    ASSERT_EQ(table.values.rows(), 2);
    for (const nlohmann::json& b : run["draws"]["bands"]) {
        const int row = b["case"] == "angle_eta23.9_rate40" ? 0 : 1;
        if (row == 0) {
            EXPECT_EQ(b["with_value"].get<int>(), 2);  // both draws tank-tread at 40/s
        }
        EXPECT_EQ(table.column("direct_draws")(row), 2);
        EXPECT_EQ(table.column("direct_with_value")(row), b["with_value"].get<int>());
        if (b["median"].is_number()) {
            EXPECT_NEAR(table.column("direct_median")(row), b["median"].get<double>(), 1e-5 * std::abs(b["median"].get<double>()));  // 6 digits
        }
        EXPECT_EQ(table.column("network_draws")(row), 6);
    }
    EXPECT_DOUBLE_EQ(table.column("network_with_value")(0), surrogate.column("with_value")(0));
    EXPECT_GT(surrogate.column("with_value")(0), 0);  // the synthetic cell tank-treads far above its critical stress
    EXPECT_DOUBLE_EQ(table.column("network_median")(0), surrogate.column("median")(0));
    // The paired networks are the model at the direct draws.
    const std::vector<PosteriorDraw> draws = selectPosteriorDraws(readNumericTable(dir.path() / "post" / "samples.csv"), 2, 5);
    const ValidationCase angle{"angle_eta23.9_rate40", "angle", 23.9, 40.0, 0.0};
    const DrawBand paired = drawBand(networkDrawOutcomes(FlowSurrogate::load(model), draws, angle, 10.0));
    EXPECT_EQ(table.column("paired_network_with_value")(0), paired.withValue);

    // A direct run that lost one threshold run of a draw: that draw leaves the threshold's row, the
    // angle keeps both.
    fs::remove(direct / "cases" / fmt::format("threshold_eta23.9_rate1_sample{}.json", draws[0].sample));
    r = test::runTrbc(base + " --out " + out.string() + " --draws 6 --seed 5 --surrogate " + model.string() + " --direct " + direct.string(),
                      dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_GE(nlohmann::json::parse(test::slurp(out / "surrogate_bands.json"))["cross_check"]["direct_runs_missing"].get<int>(), 1);
    const NumericTable partial = readNumericTable(out / "surrogate_cross_check.csv", {"direct_draws"});
    EXPECT_EQ(partial.column("direct_draws")(0), 2);
    EXPECT_EQ(partial.column("direct_draws")(1), 1);
    // Without --direct no cross-check of the earlier run stays beside the new bands.
    r = test::runTrbc(base + " --out " + out.string() + " --draws 6 --seed 5 --surrogate " + model.string(), dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_FALSE(fs::exists(out / "surrogate_cross_check.csv"));

    // Errors: --direct without --surrogate; a folder that is not a direct run of draws; draws of another posterior.
    r = test::runTrbc(base + " --out " + out.string() + " --draws 6 --direct " + direct.string(), dir.path());
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.err.find("give --surrogate MODEL"), std::string::npos) << r.err;
    r = test::runTrbc(base + " --out " + out.string() + " --draws 6 --surrogate " + model.string() + " --direct " + model.string(), dir.path());
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.err.find("no validation.json with posterior draws"), std::string::npos) << r.err;
    std::string other = "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n";
    for (int k = 0; k < 8; ++k) other += fmt::format("0.95,{},2e-19,2,0.6\n", 5.0 + 0.1 * k);
    test::writeText(dir.path() / "other" / "samples.csv", other);
    r = test::runTrbc("validate --config " + cfg.string() + " --posterior " + (dir.path() / "other").string() + " --out " +
                          (dir.path() / "other_out").string() +
                          " --draws 6 --seed 5 --surrogate " + model.string() + " --direct " + direct.string(),
                      dir.path());
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.err.find("has a finished draw there"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir.path() / "other_out" / "surrogate_bands.csv"));  // nothing that looks like a result
}

}  // namespace
}  // namespace trbc
