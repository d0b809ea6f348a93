// The flow networks (surrogate/flow_surrogate.hpp) on a synthetic campaign with known answers: a
// regime boundary at a known critical capillary number and smooth tank-treading observables. The
// networks must learn them, find the boundary, honour the exact cytosol-viscosity rescaling, and
// read back bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>

#include "analysis/flow_bands.hpp"
#include "analysis/flow_sobol.hpp"
#include "core/error.hpp"
#include "sampling/shear_campaign_table.hpp"
#include "surrogate/flow_surrogate.hpp"
#include "synthetic_shear_campaign.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

/// Ca = eta_out rate R_A / mu with R_A = 3.2776 um, mu in uN/m.
double capillary(const ShearCampaignPoint& q) { return q.etaOut * 1e-3 * q.shearRate * 3.2776 / q.cell.mu; }
/// The synthetic critical capillary number: higher for a more viscous membrane.
double criticalCa(const ShearCampaignPoint& q) { return 0.05 * std::sqrt(q.cell.etam / 0.5); }

/// The critical stress of criticalCa, Ca = eta_out rate R_A / mu.
std::vector<ShearCampaignRow> syntheticCampaign(long n) {
    return test::syntheticShearCampaign(n, 11, [](const ShearCampaignPoint& q) { return criticalCa(q) * q.cell.mu / 3.2776; });
}

/// Two restarts averaged: one training's trajectory depends on the rounding of the build's
/// instruction set, and the pair keeps the accuracy below off the luck of one of them.
FlowSurrogateTrainingReport syntheticNetworks(const std::vector<ShearCampaignRow>& rows) {
    FlowSurrogateTrainingOptions opt;
    opt.restarts = 2;
    opt.ensemble = true;
    opt.network.hiddenLayers = {24, 24};
    opt.network.maxEpochs = 400;
    return trainFlowSurrogate(rows, opt);
}

/// One small network, one restart: for tests of the bookkeeping, not of the fit.
FlowSurrogateTrainingOptions quickOptions(int epochs) {
    FlowSurrogateTrainingOptions opt;
    opt.restarts = 1;
    opt.ensemble = false;
    opt.network.hiddenLayers = {8};
    opt.network.maxEpochs = epochs;
    return opt;
}

// The flow networks' own default architecture (docs/FLOW_NETWORKS.md), not the cell surrogates'
// 32-32-32, and the mean of 16 restarts; their schedule is the cell surrogates'.
TEST(FlowSurrogate, TrainsOneHiddenLayerOf32ByDefault) {
    const FlowSurrogateTrainingOptions flow;
    EXPECT_EQ(flow.network.hiddenLayers, std::vector<int>{32});
    EXPECT_EQ(flow.restarts, 16);
    EXPECT_TRUE(flow.ensemble);
    const TrainingOptions cell;
    EXPECT_NE(cell.hiddenLayers, flow.network.hiddenLayers);
    EXPECT_EQ(flow.network.batchSize, cell.batchSize);
    EXPECT_EQ(flow.network.learningRate, cell.learningRate);
    EXPECT_EQ(flow.network.patience, cell.patience);
    EXPECT_EQ(flow.network.reductionFactor, cell.reductionFactor);
    EXPECT_EQ(flow.network.maxReductions, cell.maxReductions);
    EXPECT_EQ(flow.network.maxEpochs, cell.maxEpochs);
    EXPECT_EQ(flow.network.trainFraction, cell.trainFraction);
    EXPECT_EQ(flow.network.seed, cell.seed);
}

TEST(FlowSurrogate, LearnsASyntheticCampaignAndFindsItsBoundary) {
    const auto rows = syntheticCampaign(2048);
    const FlowSurrogateTrainingReport rep = syntheticNetworks(rows);
    EXPECT_EQ(rep.used, 2048);
    EXPECT_EQ(rep.testCases, 205);  // round(0.1 x 2048)
    EXPECT_EQ(rep.regimeRows, 2048 - 205);
    EXPECT_LT(rep.test.inclinationRmseDeg, 0.5) << "the angle spans ~25 deg";
    EXPECT_LT(rep.test.ttfRelativeRmse, 0.01);
    EXPECT_LT(rep.test.swingRmseDeg, 0.05);
    EXPECT_LE(rep.test.farMisclassified, 1) << "of " << rep.test.far;
    EXPECT_GT(rep.test.far, rep.test.near);

    // The classifier's critical stress against the synthetic one, eta_out * rate = Ca_c mu / R_A.
    std::vector<const ShearCampaignRow*> some;
    for (std::size_t k = 0; k < rows.size(); k += 37) some.push_back(&rows[k]);
    const Eigen::MatrixXd x = flowInputs(some);
    const Eigen::VectorXd tc = rep.model.criticalStressPa(x);
    int found = 0;
    double sumAbsLog = 0.0;
    for (std::size_t k = 0; k < some.size(); ++k) {
        const double truth = criticalCa(some[k]->point) * some[k]->point.cell.mu / 3.2776;
        if (truth < 0.02 || truth > 10.0) continue;  // crossings too close to the box's ends
        ASSERT_TRUE(std::isfinite(tc(Eigen::Index(k)))) << "case " << some[k]->point.caseId;
        // Within one bracket step of the threshold scans (a factor 1.5 in stress): a step in 7 inputs
        // seen through ~1,800 cases is resolved to about the spacing of the cases near it.
        EXPECT_NEAR(std::log(tc(Eigen::Index(k)) / truth), 0.0, std::log(1.5)) << "case " << some[k]->point.caseId;
        sumAbsLog += std::abs(std::log(tc(Eigen::Index(k)) / truth));
        ++found;
    }
    EXPECT_GT(found, 15);
    EXPECT_LT(sumAbsLog / found, std::log(1.2));

    // The exact rescaling: a cell in a cytosol of 5 mPa s is the campaign's cell with every
    // viscosity doubled and the rate halved.
    Eigen::MatrixXd scaled = x;
    scaled.row(4) *= 0.5, scaled.row(5) *= 0.5, scaled.row(6) *= 2.0;
    const FlowPrediction a = rep.model.predict(x), b = rep.model.predict(scaled, Eigen::VectorXd::Constant(x.cols(), 5.0));
    for (Eigen::Index j = 0; j < x.cols(); ++j) {
        EXPECT_NEAR(a.pTankTreading(j), b.pTankTreading(j), 1e-12);
        EXPECT_NEAR(a.inclinationDeg(j), b.inclinationDeg(j), 1e-9);
        EXPECT_FALSE(a.outsideBox[std::size_t(j)]);
    }
    // The networks see the groups: a cell with every modulus and the rate three times larger is the
    // same flow (tests/flow/test_shear_case.cpp), and the same prediction.
    Eigen::MatrixXd stiffer = x;
    stiffer.row(1) *= 3.0, stiffer.row(6) *= 3.0;
    const FlowPrediction same = rep.model.predict(stiffer);
    for (Eigen::Index j = 0; j < x.cols(); ++j) {
        EXPECT_NEAR(a.pTankTreading(j), same.pTankTreading(j), 1e-12);
        EXPECT_NEAR(a.inclinationDeg(j), same.inclinationDeg(j), 1e-9);
        EXPECT_NEAR(a.ttf(j), same.ttf(j), 1e-12);
    }
    EXPECT_TRUE((a.pTankTreading.array() >= 0.0).all() && (a.pTankTreading.array() <= 1.0).all());
    Eigen::MatrixXd outside = x.leftCols(1);
    outside(5, 0) = 200.0;  // eta_out beyond the box
    EXPECT_TRUE(rep.model.predict(outside).outsideBox[0]);

    // The steady cases' RMSE is the RMSE of the steady cases alone; the campaign's own
    // uncertainty is the RMS of the rows' standard errors.
    std::vector<ShearCampaignRow> marked(rows.begin(), rows.begin() + 200);
    std::vector<const ShearCampaignRow*> all, steadyOnly;
    for (ShearCampaignRow& r : marked) {
        r.steady = r.point.caseId % 3 == 0;
        r.inclinationSeDeg = r.steady ? 0.1 : 0.3;
        r.ttfSe = 0.02 * r.ttf;
        all.push_back(&r);
        if (r.steady) steadyOnly.push_back(&r);
    }
    const FlowAccuracy whole = flowAccuracy(rep.model, all, 1.5), part = flowAccuracy(rep.model, steadyOnly, 1.5);
    EXPECT_EQ(whole.steady, part.tankTreading);
    EXPECT_GT(whole.steady, 20);
    EXPECT_NEAR(whole.inclinationRmseSteadyDeg, part.inclinationRmseDeg, 1e-12);
    EXPECT_NEAR(whole.ttfRelativeRmseSteady, part.ttfRelativeRmse, 1e-12);
    EXPECT_NEAR(part.inclinationNoiseDeg, 0.1, 1e-12);
    EXPECT_NEAR(whole.ttfRelativeNoise, 0.02, 1e-12);
    EXPECT_GT(whole.inclinationNoiseDeg, 0.1);
    EXPECT_LT(whole.inclinationNoiseDeg, 0.3);

    test::TempDir tmp;
    rep.model.save(tmp.path() / "m");
    const FlowSurrogate back = FlowSurrogate::load(tmp.path() / "m");
    const FlowPrediction c = back.predict(x);
    EXPECT_EQ(c.pTankTreading, a.pTankTreading);
    EXPECT_EQ(c.ttf, a.ttf);
    EXPECT_EQ(back.etaIn, 10.0);
    EXPECT_EQ(back.start, "random");
    EXPECT_EQ(flowSurrogateProtocol(back), "ensemble");
}

// Multi-level networks: many cases of a coarse level whose angle is 1.5 deg low, a few of the
// fine level. The networks answer at the fine level, learn the offset from the paired cases, are
// scored on held-out fine cases only, and read back with their levels.
TEST(FlowSurrogate, MultiLevelNetworksAnswerAtTheFinestLevel) {
    std::vector<ShearCampaignRow> rows = syntheticCampaign(768);
    for (ShearCampaignRow& r : rows) {
        r.meshLevel = 2;
        if (r.tankTreading()) r.inclinationDeg -= 1.5;
    }
    std::vector<ShearCampaignRow> fine = syntheticCampaign(160);
    for (ShearCampaignRow& r : fine) r.meshLevel = 3;
    rows.insert(rows.end(), fine.begin(), fine.end());
    const FlowSurrogateTrainingReport rep = syntheticNetworks(rows);
    EXPECT_TRUE(rep.model.multiLevel());
    EXPECT_EQ(rep.model.level, 3);
    EXPECT_EQ(rep.model.levels, (std::vector<int>{2, 3}));
    EXPECT_EQ(rep.testCases, 16);  // 10 % of the fine cases
    EXPECT_EQ(rep.regimeRows, 768 + 160 - 16);
    EXPECT_EQ(rep.model.regime.net.numInputs(), 7);  // the six groups and the level
    EXPECT_LT(rep.test.inclinationRmseDeg, 0.75) << "the fine level's angle, not the coarse level's (1.5 deg off)";

    std::vector<const ShearCampaignRow*> some;
    for (const ShearCampaignRow& r : fine)
        if (r.tankTreading()) some.push_back(&r);
    const Eigen::MatrixXd x = flowInputs(some);
    FlowSurrogate coarse = rep.model;
    coarse.level = 2;
    const Eigen::VectorXd offset = rep.model.predict(x).inclinationDeg - coarse.predict(x).inclinationDeg;
    EXPECT_NEAR(offset.mean(), 1.5, 0.4);

    test::TempDir tmp;
    rep.model.save(tmp.path() / "m");
    const FlowSurrogate back = FlowSurrogate::load(tmp.path() / "m");
    EXPECT_EQ(back.levels, rep.model.levels);
    EXPECT_EQ(back.level, 3);
    EXPECT_EQ(back.predict(x).inclinationDeg, rep.model.predict(x).inclinationDeg);

    // Refused: a case given twice (the same campaign named twice), campaigns of two cytosols, and
    // rows of several campaigns, one without a recorded level.
    std::vector<ShearCampaignRow> twice = rows;
    twice.push_back(fine.front());
    EXPECT_THROW(syntheticNetworks(twice), InputError);
    std::vector<ShearCampaignRow> cytosols = rows;
    cytosols.back().point.etaIn = 5.0;
    EXPECT_THROW(syntheticNetworks(cytosols), InputError);
    rows.back().meshLevel = 0;
    EXPECT_THROW(syntheticNetworks(rows), InputError);
}

// The network input of a hand-computed case: v, FvK, b2, Ca = tau R_A / mu, eta_in / eta_out and
// Bq = eta_m / (eta_out R_A), R_A = 3.27765 um.
TEST(FlowSurrogate, NetworkInputsAreTheFlowsDimensionlessGroups) {
    const CellParameters cell{0.9, 4.0, 200.0, 1.5, 0.7};
    const Eigen::Matrix<double, 7, 1> x = flowInput(cell, 30.0, 50.0);  // tau = 1.5 Pa
    const Eigen::Matrix<double, 6, 1> g = flowNetworkInput(x, 10.0);
    EXPECT_DOUBLE_EQ(g(0), 0.9);
    EXPECT_DOUBLE_EQ(g(1), 200.0);
    EXPECT_DOUBLE_EQ(g(2), 1.5);
    EXPECT_NEAR(g(3), 1.5 * 3.2776457 / 4.0, 1e-6);
    EXPECT_NEAR(g(4), 1.0 / 3.0, 1e-15);
    EXPECT_NEAR(g(5), 0.7 / (0.030 * 3.2776457), 1e-5);
    EXPECT_EQ(flowNetworkInputNames().size(), 6u);

    // Networks of other inputs (a physical one in place of a group) are refused by name, not evaluated.
    const FlowSurrogateTrainingReport rep = trainFlowSurrogate(syntheticCampaign(256), quickOptions(5));
    test::TempDir tmp;
    rep.model.save(tmp.path() / "m");
    auto regime = nlohmann::json::parse(test::slurp(tmp.path() / "m" / "flow_regime.json"));
    regime["input_names"][3] = "mu_uN_per_m";
    test::writeText(tmp.path() / "m" / "flow_regime.json", regime.dump());
    try {
        FlowSurrogate::load(tmp.path() / "m");
        ADD_FAILURE() << "networks of other inputs must be refused";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("take the 6 inputs v, FvK, b2, Ca, eta_in_over_eta_out, Bq"), std::string::npos) << e.what();
    }

    // A campaign in another cytosol: its viscosity ratio is eta_in / eta_out of that cytosol, in
    // training, in the saved model and in every prediction.
    std::vector<ShearCampaignRow> thick = syntheticCampaign(256);
    for (ShearCampaignRow& r : thick) r.point.etaIn = 20.0;
    const FlowSurrogateTrainingReport at20 = trainFlowSurrogate(thick, quickOptions(5));
    EXPECT_EQ(at20.model.etaIn, 20.0);
    rep.model.save(tmp.path() / "ten");
    at20.model.save(tmp.path() / "twenty");
    const FlowSurrogate loaded = FlowSurrogate::load(tmp.path() / "twenty");
    EXPECT_EQ(loaded.etaIn, 20.0);
    std::vector<const ShearCampaignRow*> some;
    for (std::size_t k = 0; k < thick.size(); k += 51) some.push_back(&thick[k]);
    const Eigen::MatrixXd x7 = flowInputs(some);
    const Eigen::MatrixXd z = loaded.networkInputs(x7);
    for (Eigen::Index j = 0; j < x7.cols(); ++j) EXPECT_DOUBLE_EQ(z(4, j), 20.0 / x7(5, j));
    const FlowPrediction byDefault = loaded.predict(x7), named = loaded.predict(x7, Eigen::VectorXd::Constant(x7.cols(), 20.0));
    EXPECT_EQ(byDefault.inclinationDeg, named.inclinationDeg);
    EXPECT_EQ(byDefault.pTankTreading, named.pTankTreading);
    // The same inputs read by the campaign-at-10 networks see half the ratio.
    EXPECT_NEAR(FlowSurrogate::load(tmp.path() / "ten").networkInputs(x7)(4, 0), 10.0 / x7(5, 0), 1e-15);
    // And so did training: on the same rows the scaler's mean of log(eta_in / eta_out) is log 2 higher,
    // every other input's the same.
    for (const char* net : {"flow_regime.json", "flow_tank_treading.json"}) {
        const auto ten = nlohmann::json::parse(test::slurp(tmp.path() / "ten" / net)).at("input_mean");
        const auto twenty = nlohmann::json::parse(test::slurp(tmp.path() / "twenty" / net)).at("input_mean");
        for (int i = 0; i < 6; ++i)
            EXPECT_NEAR(twenty[i].get<double>() - ten[i].get<double>(), i == 4 ? std::log(2.0) : 0.0, 1e-12) << net << " input " << i;
    }
}

TEST(FlowSurrogate, CrossValidationPoolsEveryCaseOnceAndRefusesTooFewCases) {
    const auto rows = syntheticCampaign(200);
    FlowSurrogateTrainingOptions opt = quickOptions(30);
    const FlowCrossValidation cv = crossValidateFlowSurrogate(rows, opt, 4);
    ASSERT_EQ(cv.perFold.size(), 4u);
    EXPECT_EQ(cv.pooled.cases, 200);
    long tt = 0;
    for (const auto& r : rows) tt += r.tankTreading();
    EXPECT_EQ(cv.pooled.tankTreading, tt);
    EXPECT_EQ(cv.pooled.far + cv.pooled.near, 200);
    for (const FlowAccuracy& f : cv.perFold) EXPECT_EQ(f.cases, 50);
    // Every row is predicted once, by its fold; the pooled RMSE is that of these predictions.
    ASSERT_EQ(cv.predictions.size(), 200u);
    std::map<long, int> seen;
    double sq = 0.0;
    for (const FlowHeldOutPrediction& e : cv.predictions) {
        ++seen[e.row.point.caseId];
        EXPECT_TRUE(std::isfinite(e.pTankTreading));
        if (e.row.tankTreading()) sq += std::pow(e.inclinationDeg - e.row.inclinationDeg, 2);
        else EXPECT_TRUE(std::isfinite(e.inclinationDeg)) << "the regressors extrapolate";
    }
    EXPECT_EQ(seen.size(), 200u);
    EXPECT_NEAR(std::sqrt(sq / double(tt)), cv.pooled.inclinationRmseDeg, 1e-12);
    const std::string csv = flowCrossValidationCsv(cv);
    EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 201);
    EXPECT_EQ(csv.rfind("case_id,start,fold,v,", 0), 0u);

    std::vector<ShearCampaignRow> few(rows.begin(), rows.begin() + 19);
    EXPECT_THROW(trainFlowSurrogate(few, opt), InputError);
    std::vector<ShearCampaignRow> failed = rows;
    for (std::size_t k = 0; k < 190; ++k) failed[k].status = "failed";  // failed cases are not training data
    EXPECT_THROW(trainFlowSurrogate(failed, opt), InputError);
    opt.folds = 3, opt.fold = 3;
    EXPECT_THROW(trainFlowSurrogate(rows, opt), InputError);
    // A table without its campaign.json has no known start: it mixes with no other.
    opt = FlowSurrogateTrainingOptions{};
    std::vector<ShearCampaignRow> mixed = rows;
    mixed[7].start = "";
    const std::string unknown = test::inputError([&] { trainFlowSurrogate(mixed, opt); });
    EXPECT_NE(unknown.find("the starts 'not recorded (a table without campaign.json)' and 'random'"), std::string::npos) << unknown;
}

// compareFlowSurrogates against known differences: a model against itself is exact, and a student
// whose angle output is shifted by a constant is off by that constant wherever the teacher
// tank-treads, and nowhere else.
TEST(FlowDistillation, ComparisonMeasuresKnownDifferences) {
    const FlowSurrogateTrainingReport rep = trainFlowSurrogate(syntheticCampaign(300), quickOptions(60));
    const Eigen::MatrixXd x = flowDesignInputs(DesignKind::Uniform, 2000, 5, 10.0);
    const FlowDistillationCheck same = compareFlowSurrogates(rep.model, rep.model, x);
    EXPECT_EQ(same.points, 2000);
    EXPECT_GT(same.tankTreading, 200);
    EXPECT_LT(same.tankTreading, 1800);
    EXPECT_EQ(same.probabilityRmse, 0.0);
    EXPECT_EQ(same.regimeDisagreement, 0.0);
    EXPECT_EQ(same.inclinationRmseDeg, 0.0);
    EXPECT_EQ(same.ttfRelativeRmse, 0.0);

    FlowSurrogate shifted = rep.model;
    ASSERT_TRUE(shifted.tankTreading.outputTransforms.empty() ||
                shifted.tankTreading.outputTransforms[0] == VariableTransform::Identity);
    shifted.tankTreading.outputScaling.mean(0) += 0.7;  // y = m + s y': the angle moves by 0.7 deg
    const FlowDistillationCheck d = compareFlowSurrogates(shifted, rep.model, x);
    EXPECT_NEAR(d.inclinationRmseDeg, 0.7, 1e-9);
    EXPECT_EQ(d.swingRmseDeg, 0.0);
    EXPECT_EQ(d.regimeDisagreement, 0.0);
    EXPECT_EQ(d.tankTreading, same.tankTreading);
}

// A student distilled from an ensemble: one network per output, recorded as distilled from it,
// close to the teacher at points it never saw (an untrained network is tens of degrees off), its
// check reproducible from the design of seed + 1; the JSON record keeps the teacher's accuracy.
TEST(FlowDistillation, OneNetworkLearnsTheEnsemblesMean) {
    FlowSurrogateTrainingOptions o = quickOptions(150);
    o.restarts = 3;
    o.ensemble = true;
    const FlowSurrogateTrainingReport rep = trainFlowSurrogate(syntheticCampaign(400), o);
    ASSERT_EQ(rep.model.tankTreading.ensemble.size(), 2u);
    FlowDistillationOptions opt;
    opt.samples = 20000;
    opt.checkSamples = 3000;
    opt.hiddenLayers = {16};
    opt.command = "trbc flow distill --model M";
    const FlowDistillation d = distillFlowSurrogate(rep.model, opt);
    EXPECT_EQ(d.model.regime.command, opt.command);
    EXPECT_EQ(d.model.tankTreading.command, opt.command);
    EXPECT_TRUE(d.model.tankTreading.ensemble.empty());
    EXPECT_TRUE(d.model.regime.ensemble.empty());
    EXPECT_EQ(d.model.tankTreading.distillation.members, 3);
    EXPECT_EQ(d.model.tankTreading.distillation.samples, 20000);
    EXPECT_EQ(d.model.tankTreading.net.layerSizes(), (std::vector<int>{6, 16, 3}));
    EXPECT_EQ(d.model.start, rep.model.start);
    EXPECT_EQ(d.check.points, 3000);
    EXPECT_LT(d.check.inclinationRmseDeg, 1.0);
    EXPECT_LT(d.check.ttfRelativeRmse, 0.03);
    EXPECT_LT(d.check.regimeDisagreement, 0.05);
    const FlowDistillationCheck again =
        compareFlowSurrogates(d.model, rep.model, flowDesignInputs(DesignKind::Uniform, 3000, opt.seed + 1, 10.0));
    EXPECT_EQ(again.inclinationRmseDeg, d.check.inclinationRmseDeg);

    const nlohmann::json teacher = {{"cross_validation", {{"pooled", {{"inclination_rmse_deg", 0.99}}}}}};
    const nlohmann::json j = flowDistillationJson(teacher, opt, d, "TEACHER", "trbc flow distill");
    EXPECT_EQ(j["cross_validation"], teacher["cross_validation"]);
    EXPECT_EQ(j["distillation"]["teacher"], "TEACHER");
    EXPECT_EQ(j["distillation"]["check"]["inclination_rmse_deg"].get<double>(), d.check.inclinationRmseDeg);

    FlowDistillationOptions bad = opt;
    bad.samples = 999;
    EXPECT_THROW(distillFlowSurrogate(rep.model, bad), InputError);
    bad = opt;
    bad.hiddenLayers.clear();
    EXPECT_THROW(distillFlowSurrogate(rep.model, bad), InputError);
    FlowSurrogate multi = rep.model;
    multi.levels = {2, 3};
    EXPECT_THROW(distillFlowSurrogate(multi, opt), InputError);
    // A student is not distilled again (its error against the ensemble would be lost), and a single
    // network has nothing to distil; either would write networks that do not load.
    EXPECT_THROW(distillFlowSurrogate(d.model, opt), InputError);
    FlowSurrogate single = rep.model;
    single.tankTreading.ensemble.clear();
    EXPECT_THROW(distillFlowSurrogate(single, opt), InputError);
}

// The same design from random and from in-plane starts: the random rows tumble below a critical Ca
// twice the in-plane rows' and carry an angle 3 deg high. The regime network must follow the random
// rows, the regressors the in-plane ones; a held-out case is out of both; the starts read back.
TEST(FlowSurrogate, RandomStartsTrainTheRegimeAndInPlaneStartsTheAngle) {
    std::vector<ShearCampaignRow> rows = syntheticCampaign(1024), inPlane = rows;
    for (ShearCampaignRow& r : rows) {
        if (capillary(r.point) < 2.0 * criticalCa(r.point)) r.regime = "tumbling";
        if (r.tankTreading()) r.inclinationDeg += 3.0;
    }
    for (ShearCampaignRow& r : inPlane) r.start = "in-plane";
    long inPlaneTt = 0;
    for (const ShearCampaignRow& r : inPlane) inPlaneTt += r.tankTreading();
    rows.insert(rows.end(), inPlane.begin(), inPlane.end());
    const FlowSurrogateTrainingReport rep = syntheticNetworks(rows);
    EXPECT_EQ(rep.model.start, "random");
    EXPECT_EQ(rep.model.tankTreadingStart, "in-plane");
    EXPECT_EQ(rep.testCases, 102);  // round(0.1 x 1024) case ids
    EXPECT_EQ(rep.regimeRows, 1024 - 102);
    EXPECT_EQ(rep.test.cases, 102);
    EXPECT_LT(rep.test.inclinationRmseDeg, 0.6) << "the in-plane angle, not the random starts' (3 deg off)";

    std::vector<const ShearCampaignRow*> some;
    for (std::size_t k = 0; k < inPlane.size(); k += 29)
        if (inPlane[k].tankTreading()) some.push_back(&inPlane[k]);
    const Eigen::MatrixXd x = flowInputs(some);
    const FlowPrediction p = rep.model.predict(x);
    double offset = 0.0;
    for (std::size_t k = 0; k < some.size(); ++k) offset += p.inclinationDeg(Eigen::Index(k)) - some[k]->inclinationDeg;
    EXPECT_NEAR(offset / double(some.size()), 0.0, 0.4);
    // The regime's boundary is the random rows' (2 Ca_c), not the in-plane rows' (Ca_c).
    const Eigen::VectorXd tc = rep.model.criticalStressPa(x);
    int found = 0;
    double sumLog = 0.0;
    for (std::size_t k = 0; k < some.size(); ++k) {
        const double truth = 2.0 * criticalCa(some[k]->point) * some[k]->point.cell.mu / 3.2776;
        if (truth < 0.02 || truth > 10.0 || !std::isfinite(tc(Eigen::Index(k)))) continue;
        sumLog += std::log(tc(Eigen::Index(k)) / truth);
        ++found;
    }
    ASSERT_GT(found, 5);
    EXPECT_NEAR(sumLog / found, 0.0, std::log(1.3)) << "a factor 2 would be the in-plane boundary";

    // Cross-validation scores the regime on the random rows and the angle on the in-plane rows.
    FlowSurrogateTrainingOptions quick = quickOptions(20);
    const FlowCrossValidation cv = crossValidateFlowSurrogate(rows, quick, 4);
    EXPECT_EQ(cv.pooled.cases, 1024);
    EXPECT_EQ(cv.pooled.tankTreading, inPlaneTt);
    ASSERT_EQ(cv.predictions.size(), 2048u);  // each start's row of every case
    for (const FlowHeldOutPrediction& e : cv.predictions)
        EXPECT_EQ(std::isfinite(e.pTankTreading), e.row.start == "random") << e.row.point.caseId;
    // A learning-curve point holds both starts of its first cases.
    EXPECT_EQ(flowLearningCurveRows(rows, 0, 10).size(), 20u);

    test::TempDir tmp;
    rep.model.save(tmp.path() / "m");
    const FlowSurrogate back = FlowSurrogate::load(tmp.path() / "m");
    EXPECT_EQ(back.start, "random");
    EXPECT_EQ(back.tankTreadingStart, "in-plane");

    // Each network needs every level of the model.
    std::vector<ShearCampaignRow> levels = rows;
    for (ShearCampaignRow& r : levels) r.meshLevel = 3;
    for (ShearCampaignRow r : syntheticCampaign(64)) {
        r.meshLevel = 2;
        levels.push_back(r);
    }
    const std::string missing = test::inputError([&] { trainFlowSurrogate(levels, quick); });
    EXPECT_NE(missing.find("the random starts' campaigns are of the levels [2, 3], the in-plane ones' of [3]"), std::string::npos) << missing;
}

// validate --surrogate and flow sobol on the shipped validation config: one row per angle, TTF and
// threshold case; draws of one cell give a band of zero width at the networks' own predictions.
TEST(FlowSurrogate, BandsAndSobolIndicesOfTheValidationSet) {
    const FlowSurrogate model = syntheticNetworks(syntheticCampaign(1024)).model;
    const ValidationConfig cfg = readValidationConfig(test::sourceRoot() / "configs" / "validation.toml", test::experimentsDir());
    PosteriorDraw d;
    d.v = 0.93, d.mu = 4.6, d.kbJ = 2.3e-19, d.b2 = 2.0, d.etam = 0.7;
    std::vector<PosteriorDraw> draws(40, d);
    for (std::size_t k = 0; k < draws.size(); ++k) draws[k].sample = long(k);
    ValidationEvidence evidence(cfg.dataDir);
    const auto rows = surrogateShearBands(cfg, model, draws, evidence);
    std::map<std::string, int> kinds;
    for (const SurrogateBandRow& r : rows) {
        ++kinds[r.c.kind];
        EXPECT_EQ(r.band.draws, 40);
        EXPECT_EQ(r.outsideBox, 0) << r.c.id;
        if (r.band.withValue == 0) continue;
        EXPECT_EQ(r.band.withValue, 40);
        EXPECT_EQ(r.band.lo, r.band.hi);
        Eigen::MatrixXd x(7, 1);
        x << d.v, d.mu, CellParameters::fvkFromKb(d.mu, d.kbJ), d.b2, d.etam, r.c.etaOut, r.c.kind == "threshold" ? 1.0 : r.c.rate;
        const double expected = r.c.kind == "threshold" ? model.criticalStressPa(x)(0)
                                : r.c.kind == "angle"   ? model.predict(x).inclinationDeg(0)
                                                        : model.predict(x).ttf(0);
        EXPECT_NEAR(r.band.median, expected, 1e-9 * std::abs(expected)) << r.c.id;
    }
    EXPECT_EQ(kinds["angle"], 56);
    EXPECT_EQ(kinds["ttf"], 6);
    EXPECT_EQ(kinds["threshold"], 8);
    EXPECT_NE(surrogateBandsMarkdown(rows).find("| angle | 56 |"), std::string::npos);

    const auto outputs = flowSobolOutputs(cfg);
    ASSERT_EQ(outputs.size(), 4u + 1u + 8u);  // four angle sweeps, one TTF sweep, eight threshold viscosities
    Eigen::MatrixXd X(2, 5);
    X << 0.9, 4.0, 200.0, 1.0, 0.5, 0.9, 8.0, 200.0, 1.0, 0.5;
    const Eigen::MatrixXd Y = flowSobolModel(model, outputs, 10.0, X);
    ASSERT_EQ(Y.rows(), 2);
    EXPECT_TRUE(Y.allFinite());
    // The synthetic critical stress is proportional to mu: log10 2 between the two cells.
    EXPECT_NEAR(Y(1, 12) - Y(0, 12), std::log10(2.0), 0.15);
}

// Campaigns trained together share every setting but level, size and injected failures.
TEST(FlowTrainingReport, CampaignsMustMatchButTheirLevelSizeAndStart) {
    test::TempDir tmp;
    const auto campaign = [&](const std::string& name, const std::string& settings) {
        test::writeText(tmp.path() / name / "campaign.json", R"({"settings": )" + settings + "}");
        return tmp.path() / name;
    };
    const fs::path a = campaign("a", R"({"design": "sobol", "cases": 64, "seed": 7, "eta_in_mPa_s": 10.0, "level": 3, "start": "random"})");
    const fs::path b = campaign("b", R"({"design": "sobol", "cases": 4096, "seed": 7, "eta_in_mPa_s": 10.0, "level": 2, "start": "random",
                                        "inject_failures": "3"})");
    const fs::path c = campaign("c", R"({"design": "sobol", "cases": 64, "seed": 7, "eta_in_mPa_s": 10.0, "level": 2, "start": "in-plane"})");
    const fs::path d = campaign("d", R"({"design": "sobol", "cases": 64, "seed": 8, "eta_in_mPa_s": 10.0, "level": 2, "start": "random"})");
    test::writeText(b / "cases.csv", shearCampaignCsvHeader() + "\n");
    EXPECT_NO_THROW(checkShearCampaignsMatch({a, b}));
    EXPECT_NO_THROW(checkShearCampaignsMatch({a, b / "cases.csv"}));  // a campaign's cases.csv stands for it
    EXPECT_NO_THROW(checkShearCampaignsMatch({c}));                   // one campaign: nothing to compare
    const auto refusal = [](const std::vector<fs::path>& campaigns) {
        return test::inputError([&] { checkShearCampaignsMatch(campaigns); });
    };
    EXPECT_NO_THROW(checkShearCampaignsMatch({a, b, c}));  // the training judges the mix of starts
    const std::string seed = refusal({d, a});
    EXPECT_NE(seed.find("--campaign " + a.string() + ": its setting 'seed' (7) differs from the first campaign's (8)"), std::string::npos)
        << seed;
    const fs::path e = campaign("e", R"({"design": "sobol", "cases": 64, "seed": 7, "eta_in_mPa_s": 10.0, "level": 1, "start": "random",
                                        "box": "wide"})");
    const std::string box = refusal({a, e});
    EXPECT_NE(box.find("its setting 'box' (\"wide\") differs from the first campaign's (absent)"), std::string::npos) << box;
    const std::string lacks = refusal({e, a});
    EXPECT_NE(lacks.find("--campaign " + a.string() + ": it lacks the first campaign's setting 'box' (\"wide\")"), std::string::npos)
        << lacks;
    test::writeText(tmp.path() / "f" / "campaign.json", "{\"settings\": ");
    const std::string bad = refusal({a, tmp.path() / "f"});
    EXPECT_NE(bad.find("campaign.json is not a campaign description"), std::string::npos) << bad;
}

// A learning-curve point: the first n finest-level cases by case id, every coarser case kept; the
// curve cross-validates those rows at each size the campaign holds and lists the sizes it does not.
TEST(FlowTrainingReport, LearningCurveRowsArePrefixesOfTheFinestLevel) {
    std::vector<ShearCampaignRow> rows;
    for (long id : {5L, 1L, 4L, 0L, 2L}) {
        ShearCampaignRow r;
        r.point.caseId = id;
        r.meshLevel = 3;
        rows.push_back(r);
    }
    for (long id : {7L, 0L}) {
        ShearCampaignRow r;
        r.point.caseId = id;
        r.meshLevel = 2;
        rows.push_back(r);
    }
    const std::vector<ShearCampaignRow> p = flowLearningCurveRows(rows, 3, 3);
    ASSERT_EQ(p.size(), 5u);
    const std::vector<std::pair<int, long>> expected = {{3, 0}, {3, 1}, {3, 2}, {2, 7}, {2, 0}};
    for (std::size_t k = 0; k < p.size(); ++k) {
        EXPECT_EQ(p[k].meshLevel, expected[k].first) << k;
        EXPECT_EQ(p[k].point.caseId, expected[k].second) << k;
    }
    EXPECT_EQ(flowLearningCurveRows(rows, 3, 5).size(), 7u);
    EXPECT_THROW(flowLearningCurveRows(rows, 3, 6), InputError);

    std::vector<ShearCampaignRow> campaign = syntheticCampaign(60);
    std::reverse(campaign.begin(), campaign.end());
    FlowSurrogateTrainingOptions opt = quickOptions(20);
    const FlowLearningCurve curve = flowLearningCurve(campaign, 0, {48, 100, 60, 61}, opt, 2);
    EXPECT_EQ(curve.available, 60);
    EXPECT_EQ(curve.skipped, (std::vector<long>{100, 61}));
    ASSERT_EQ(curve.points.size(), 2u);
    EXPECT_EQ(curve.points[0].cases, 48);
    EXPECT_EQ(curve.points[1].cases, 60);
    for (const FlowLearningCurvePoint& q : curve.points) EXPECT_EQ(q.pooled.cases, q.cases);  // every case held out once
    const FlowCrossValidation first = crossValidateFlowSurrogate(flowLearningCurveRows(campaign, 0, 48), opt, 2);
    EXPECT_EQ(flowAccuracyJson(curve.points[0].pooled), flowAccuracyJson(first.pooled));
    EXPECT_TRUE(flowLearningCurve(campaign, 0, {}, opt, 2).points.empty());
}

FlowAccuracy handMadeAccuracy() {
    FlowAccuracy a;
    a.cases = 40;
    a.tankTreading = 25;
    a.inclinationRmseDeg = 1.23456;
    a.swingRmseDeg = 0.5;
    a.ttfRelativeRmse = 0.0345;
    a.steady = 12;
    a.inclinationRmseSteadyDeg = 0.8;
    a.ttfRelativeRmseSteady = 0.021;
    a.inclinationNoiseDeg = 0.25;
    a.ttfRelativeNoise = 0.01;
    a.brier = 0.04567;
    a.far = 30, a.farMisclassified = 3;
    a.near = 10, a.nearMisclassified = 0;
    return a;
}

TEST(FlowTrainingReport, AccuracyRowAndJsonOfAHandMadeAccuracy) {
    const FlowAccuracy a = handMadeAccuracy();
    EXPECT_EQ(flowAccuracyRow("held out (10 %)", a),
              "| held out (10 %) | 40 | 1.235 | 0.500 | 3.45 % | 0.800 / 2.10 % (12) | 0.250 / 1.00 % | 10.0 % (3/30) | 0.0 % (0/10) | 0.0457 |");
    const nlohmann::json j = flowAccuracyJson(a);
    EXPECT_EQ(j.size(), 15u);
    EXPECT_EQ(j.at("cases"), 40);
    EXPECT_EQ(j.at("tank_treading_cases"), 25);
    EXPECT_DOUBLE_EQ(j.at("inclination_rmse_deg").get<double>(), 1.23456);
    EXPECT_DOUBLE_EQ(j.at("ttf_relative_rmse").get<double>(), 0.0345);
    EXPECT_EQ(j.at("steady_cases"), 12);
    EXPECT_DOUBLE_EQ(j.at("campaign_ttf_relative_se_rms").get<double>(), 0.01);
    EXPECT_DOUBLE_EQ(j.at("brier").get<double>(), 0.04567);
    EXPECT_EQ(j.at("far_misclassified"), 3);
    EXPECT_EQ(j.at("near_cases"), 10);

    const FlowAccuracy none;  // no cases: the statistics are NaN, null in the record, "-" for a share
    const nlohmann::json n = flowAccuracyJson(none);
    EXPECT_TRUE(n.at("inclination_rmse_deg").is_null());
    EXPECT_TRUE(n.at("brier").is_null());
    EXPECT_EQ(n.at("cases"), 0);
    EXPECT_EQ(flowAccuracyRow("N = 20", none), "| N = 20 | 0 | nan | nan | nan % | nan / nan % (0) | nan / nan % | - | - | nan |");
}

TEST(FlowTrainingReport, TrainingJsonAndAccuracyMarkdown) {
    FlowTrainingSummary s;
    s.sources = {{"L3", 64, 3, true}, {"L2", 500, 2, false}};
    s.options.command = "trbc flow train";
    s.options.restarts = 2;
    s.options.testFraction = 0.2;
    s.training.model.levels = {2, 3};
    s.training.model.level = 3;
    s.training.dataHash = "abc";
    s.training.rows = 570;
    s.training.used = 560;
    s.training.test = handMadeAccuracy();
    s.crossValidation.emplace();
    s.crossValidation->folds = 4;
    s.crossValidation->pooled = handMadeAccuracy();
    s.learningCurveFolds = 5;
    s.learningCurve = std::vector<FlowLearningCurvePoint>{{20, handMadeAccuracy()}};
    s.options.network.hiddenLayers = {16};
    s.training.model.start = "random";
    s.training.model.tankTreadingStart = "in-plane";

    const nlohmann::json j = flowTrainingJson(s);
    EXPECT_EQ(j.at("hidden_layers"), nlohmann::json({16}));
    EXPECT_EQ(j.at("start"), "random");
    EXPECT_EQ(j.at("tank_treading_start"), "in-plane");
    EXPECT_EQ(j.at("command"), "trbc flow train");
    EXPECT_EQ(j.at("campaigns").size(), 2u);
    EXPECT_EQ(j.at("campaigns")[1], nlohmann::json({{"campaign", "L2"}, {"cases", 500}, {"level", 2}, {"complete", false}}));
    EXPECT_EQ(j.at("levels"), nlohmann::json({2, 3}));
    EXPECT_EQ(j.at("predicts_level"), 3);
    EXPECT_EQ(j.at("finished_rows"), 560);
    EXPECT_EQ(j.at("restarts"), 2);
    EXPECT_EQ(j.at("test"), flowAccuracyJson(s.training.test));
    EXPECT_EQ(j.at("cross_validation").at("folds"), 4);
    EXPECT_EQ(j.at("learning_curve")[0].at("cases"), 20);
    EXPECT_TRUE(j.contains("version") && j.contains("revision") && j.contains("build"));
    EXPECT_EQ(j.at("goals"), nlohmann::json({{"inclination_rmse_deg", 0.3}, {"ttf_relative_rmse", 0.02}, {"far_misclassified_fraction", 0.03}}));

    const std::string row = flowAccuracyRow("x", handMadeAccuracy()).substr(3);  // " | 40 | ...": the row after its label
    const std::string md = flowAccuracyMarkdown(s);
    EXPECT_EQ(md.rfind("Multi-level networks (the mesh level an input); every accuracy below is on held-out level-3 cases", 0), 0u) << md;
    EXPECT_NE(md.find("Flow networks from L3 (64 cases, level 3) and L2 (500 cases, level 2, not complete); command: `trbc flow train`"),
              std::string::npos) << md;
    EXPECT_NE(md.find("The regime network learns from the random starts, the tank-treading network from the in-plane starts of the same "
                      "design; a held-out case is out of both."), std::string::npos) << md;
    EXPECT_NE(md.find("Goals: angle RMSE ≤ 0.3°, TTF RMSE ≤ 2 %, misclassified far from the boundary ≤ 3 %."), std::string::npos) << md;
    EXPECT_NE(md.find("| held out (20 %)" + row + "\n| 4-fold CV" + row + "\n"), std::string::npos) << md;
    EXPECT_NE(md.find("\nLearning curve (5-fold CV on the first N cases of the design)\n\n| set | cases |"), std::string::npos) << md;
    EXPECT_NE(md.find("| N = 20" + row + "\n"), std::string::npos) << md;

    s.crossValidation.reset();
    s.learningCurve.reset();
    s.training.model.levels.clear();
    s.training.model.tankTreadingStart = "random";
    const nlohmann::json plain = flowTrainingJson(s);
    EXPECT_FALSE(plain.contains("cross_validation") || plain.contains("learning_curve"));
    const std::string plainMd = flowAccuracyMarkdown(s);
    EXPECT_EQ(plainMd.rfind("Flow networks from", 0), 0u) << plainMd;
    EXPECT_EQ(plainMd.find("CV"), std::string::npos) << plainMd;
    EXPECT_EQ(plainMd.find("The regime network learns"), std::string::npos) << "one start";

    test::TempDir tmp;
    EXPECT_EQ(writeFlowTrainingReport(tmp.path(), s), plainMd);
    EXPECT_EQ(test::slurp(tmp.path() / "accuracy.md"), plainMd);
    EXPECT_EQ(nlohmann::json::parse(test::slurp(tmp.path() / "training.json")), plain);
}

}  // namespace
}  // namespace trbc
