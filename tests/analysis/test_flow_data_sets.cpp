// The shear-flow data as data sets of the red-cell model: one per donor, the TTF and the critical
// stresses, with the networks' errors from their training.json; and the --datasets choice of them.
#include "analysis/flow_data_sets.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>

#include "core/error.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

const fs::path kValidationData = test::experimentsDir() / "validation";
const FlowNetworkErrors kErrors{0.99, 0.062, std::log(1.5), 0.095};

TEST(FlowDataSets, ADonorIsOneColumnOfEveryViscositysFile) {
    const std::vector<FlowDataSet> sets = flowDataSets(kValidationData, kErrors, 12.0);
    ASSERT_EQ(sets.size(), 10u);
    for (int k = 0; k < 7; ++k) EXPECT_EQ(sets[k].name, "fischer_2015_donor" + std::to_string(k + 1));
    EXPECT_EQ(sets[7].name, "fischer_ttf_donors12");
    EXPECT_EQ(sets[8].name, "fischer_2013_critical_stress");
    EXPECT_EQ(sets[9].name, "abkarian_2007_critical_stress");
    // Donor 3 ("angle3"): at 10.7 mPa s three points (82.824: 8.6066, 122.01: 8.0164, 179.77: 7.7213),
    // at 23.9 its first point is 2.5942: 12.053; it has points at all four viscosities.
    const FlowDataSet& d3 = sets[2];
    ASSERT_EQ(d3.curves.size(), 4u);
    EXPECT_DOUBLE_EQ(d3.curves[0].etaOutMPaS, 10.7);
    ASSERT_EQ(d3.curves[0].value.size(), 3);
    EXPECT_DOUBLE_EQ(d3.curves[0].rate[0], 82.824);
    EXPECT_DOUBLE_EQ(d3.curves[0].value[2], 7.7213);
    EXPECT_DOUBLE_EQ(d3.curves[1].etaOutMPaS, 23.9);
    EXPECT_DOUBLE_EQ(d3.curves[1].rate[0], 2.5942);
    EXPECT_DOUBLE_EQ(d3.curves[1].value[0], 12.053);
    EXPECT_EQ(d3.observable, FlowObservable::Inclination);
    EXPECT_DOUBLE_EQ(d3.modelErrorSd, 0.99);
    EXPECT_DOUBLE_EQ(d3.regimeErrorRate, 0.095);
    EXPECT_DOUBLE_EQ(d3.etaInMPaS, 12.0);
    EXPECT_DOUBLE_EQ(d3.etamRange[0], 0.03);  // the flow campaign's eta_m range
    EXPECT_DOUBLE_EQ(d3.etamRange[1], 3.0);
    ASSERT_EQ(d3.files.size(), 4u);  // provenance: the four viscosities' files
    EXPECT_EQ(d3.files[1].filename(), "Fisher2015_eta_23.9_mPa_s.csv");
    EXPECT_EQ(sets[5].files.size(), 3u);  // donor 6: no point at 10.7 mPa s
    const RbcDataSet r3 = flowRbcDataSet(d3);
    EXPECT_EQ(r3.file.filename(), "inclination_angle");
    EXPECT_EQ(r3.contentHash.size(), 16u);
    EXPECT_EQ(flowRbcDataSet(sets[8]).file.filename(), "Fischer2013.csv");
    // Every donor's points: the files' non-blank cells of its column.
    long points = 0;
    for (int k = 0; k < 7; ++k)
        for (const FlowCurve& c : sets[k].curves) points += c.value.size();
    EXPECT_EQ(points, 272);

    const FlowDataSet& ttf = sets[7];
    ASSERT_EQ(ttf.curves.size(), 1u);
    EXPECT_DOUBLE_EQ(ttf.curves[0].etaOutMPaS, 28.9);
    EXPECT_EQ(ttf.curves[0].value.size(), 225);
    EXPECT_NEAR(ttf.curves[0].value[0], 4.0 * std::numbers::pi * 0.062906, 1e-12);  // f / rate to 4 pi f / rate
    EXPECT_DOUBLE_EQ(ttf.modelErrorSd, 0.062);

    const FlowDataSet& f13 = sets[8];
    EXPECT_EQ(f13.observable, FlowObservable::CriticalStress);
    EXPECT_DOUBLE_EQ(f13.curves.front().etaOutMPaS, 10.7);
    EXPECT_EQ(f13.curves.front().value.size(), 3);  // 0.92060, 0.79105, 0.58407
    EXPECT_EQ(f13.curves.front().rate.size(), 0);
    EXPECT_DOUBLE_EQ(f13.modelErrorSd, std::log(1.5));
    EXPECT_DOUBLE_EQ(f13.regimeErrorRate, 0.0);
    EXPECT_DOUBLE_EQ(sets[9].curves.front().etaOutMPaS, 31.0);
}

TEST(FlowDataSets, TheErrorsComeFromTheShippedNetworksCrossValidation) {
    const FlowNetworkErrors e = flowNetworkErrors(fs::path(TRBC_SOURCE_DIR) / "data/surrogates/flow");
    EXPECT_NEAR(e.inclinationDeg, 0.99, 0.005);
    EXPECT_NEAR(e.ttfRelative, 0.0615, 0.0005);
    EXPECT_NEAR(e.regimeErrorRate, 25.0 / 262.0, 1e-12);
    EXPECT_NEAR(e.criticalStressLog, std::log(1.5), 1e-12);
}

// The distilled networks that `trbc infer` uses by default carry the ensemble's cross-validation and
// their own error against it, which adds: in quadrature to the angle and TTF, to the regime's rate.
TEST(FlowDataSets, ADistilledNetworksErrorAddsToTheEnsembles) {
    test::TempDir dir;
    test::writeText(dir.path() / "training.json", R"({"boundary_factor": 1.5,
        "cross_validation": {"pooled": {"inclination_rmse_deg": 0.8, "ttf_relative_rmse": 0.05, "far_misclassified": 10, "far_cases": 200}},
        "distillation": {"check": {"inclination_rmse_deg": 0.6, "ttf_relative_rmse": 0.12, "regime_disagreement": 0.01}}})");
    const FlowNetworkErrors e = flowNetworkErrors(dir.path());
    EXPECT_NEAR(e.inclinationDeg, 1.0, 1e-12);
    EXPECT_NEAR(e.ttfRelative, 0.13, 1e-12);
    EXPECT_NEAR(e.regimeErrorRate, 0.06, 1e-12);
    EXPECT_NEAR(e.criticalStressLog, std::log(1.5), 1e-12);

    const FlowNetworkErrors shipped = flowNetworkErrors(fs::path(TRBC_SOURCE_DIR) / "data/surrogates/flow_distilled");
    const FlowNetworkErrors ensemble = flowNetworkErrors(fs::path(TRBC_SOURCE_DIR) / "data/surrogates/flow");
    EXPECT_GT(shipped.inclinationDeg, ensemble.inclinationDeg);
    EXPECT_LT(shipped.inclinationDeg, 1.01 * ensemble.inclinationDeg) << "the student adds little to the ensemble's error";
    EXPECT_LT(shipped.ttfRelative, 1.01 * ensemble.ttfRelative);

    test::writeText(dir.path() / "training.json", R"({"boundary_factor": 1.5,
        "cross_validation": {"pooled": {"inclination_rmse_deg": 0.8, "ttf_relative_rmse": 0.05, "far_misclassified": 10, "far_cases": 200}},
        "distillation": {"check": {"inclination_rmse_deg": 0.6}}})");
    try {
        flowNetworkErrors(dir.path());
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("distillation.check: "), std::string::npos) << e.what();
    }
    test::writeText(dir.path() / "training.json", R"({"boundary_factor": 1.5,
        "cross_validation": {"pooled": {"inclination_rmse_deg": 0.8, "ttf_relative_rmse": 0.05, "far_misclassified": 10, "far_cases": 200}},
        "distillation": {"check": {"inclination_rmse_deg": -0.6, "ttf_relative_rmse": 0.12, "regime_disagreement": 0.01}}})");
    try {
        flowNetworkErrors(dir.path());
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("an angle error -0.6"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("must be >= 0"), std::string::npos) << e.what();
    }
}

TEST(FlowDataSets, ANetworkDirectoryWithoutCrossValidationIsNamed) {
    test::TempDir dir;
    test::writeText(dir.path() / "training.json", R"({"boundary_factor": 1.5, "test": {}})");
    try {
        flowNetworkErrors(dir.path());
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("training.json"), std::string::npos);
        EXPECT_NE(std::string(e.what()).find("--folds"), std::string::npos);
    }
    for (const bool absent : {true, false}) {
        if (!absent) test::writeText(dir.path() / "training.json", "{not json");
        const fs::path where = absent ? dir.path() / "absent" : dir.path();
        try {
            flowNetworkErrors(where);
            FAIL() << "no error";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find((where / "training.json").string()), std::string::npos) << e.what();
        }
    }
}

RbcDataSet namedSet(const std::string& name) {
    RbcDataSet d;
    d.name = name;
    return d;
}

TEST(DataSetChoice, KeywordsAreWholeValuesAndNamesKeepTheirOrder) {
    const std::vector<RbcDataSet> single{namedSet("mills_2004"), namedSet("evans_1976")};
    const std::vector<RbcDataSet> flow{namedSet("fischer_2015_donor1"), namedSet("abkarian_2007_critical_stress")};
    using Kind = DataSetChoice::Kind;
    EXPECT_EQ(DataSetChoice::parse("paper").kind, Kind::Paper);
    EXPECT_EQ(DataSetChoice::parse(" all ").kind, Kind::All);
    EXPECT_EQ(DataSetChoice::parse("list").kind, Kind::List);
    EXPECT_FALSE(DataSetChoice::parse("paper").mayChooseFlow(single));
    EXPECT_TRUE(DataSetChoice::parse("all").mayChooseFlow(single));
    EXPECT_TRUE(DataSetChoice::parse("list").mayChooseFlow(single));
    EXPECT_FALSE(DataSetChoice::parse("evans_1976, mills_2004").mayChooseFlow(single));
    EXPECT_TRUE(DataSetChoice::parse("mills_2004,fischer_2015_donor1").mayChooseFlow(single));

    auto names = [](const std::vector<RbcDataSet>& sets) {
        std::vector<std::string> n;
        for (const RbcDataSet& d : sets) n.push_back(d.name);
        return n;
    };
    using V = std::vector<std::string>;
    EXPECT_EQ(names(selectDataSets(DataSetChoice::parse("paper"), single, flow)), (V{"mills_2004", "evans_1976"}));
    const V every{"mills_2004", "evans_1976", "fischer_2015_donor1", "abkarian_2007_critical_stress"};
    EXPECT_EQ(names(selectDataSets(DataSetChoice::parse("all"), single, flow)), every);
    EXPECT_EQ(names(selectDataSets(DataSetChoice::parse("list"), single, flow)), every);
    EXPECT_EQ(names(selectDataSets(DataSetChoice::parse("abkarian_2007_critical_stress,evans_1976"), single, flow)),
              (V{"abkarian_2007_critical_stress", "evans_1976"}));
}

TEST(DataSetChoice, BadValuesNameTheItem) {
    const std::vector<RbcDataSet> single{namedSet("mills_2004")};
    const std::vector<std::pair<std::string, std::string>> cases{
        {"mills_2004,mills_2004", "'mills_2004' is given twice"},
        {"mills_2005,mills_2005", "'mills_2005' is given twice"},  // before the names are looked up
        {"mills_2004,", "an empty name"},
        {"", "an empty name"},
        {"paper,fischer_2015_donor1", "the keyword 'paper' stands alone"},
        {"mills_2004, all", "the keyword 'all' stands alone"},
    };
    for (const auto& [spec, expect] : cases) {
        try {
            DataSetChoice::parse(spec);
            ADD_FAILURE() << spec << ": no error";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << spec << ": " << e.what();
        }
    }
    try {
        selectDataSets(DataSetChoice::parse("mills_2005"), single, {});
        ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("'mills_2005' is not a data set; give paper, all, list or names from: mills_2004"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace
}  // namespace trbc
