// The three-network surrogate (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training): training from a campaign table, the held-out
// test set of whole cells, invariances, save/load, the training-box flag, and the surrogate and
// sobol commands on bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "core/error.hpp"
#include "sampling/campaign_table.hpp"
#include "sampling/design.hpp"
#include "surrogate/network_io.hpp"
#include "surrogate/surrogate.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::runTrbc;
using test::shellQuote;
using test::TempDir;

// Smooth stand-ins for the forward model with the dependences of SURROGATE 1.2.
double fakeD(const CellParameters& p) { return 7.0 + 1.5 * (p.v - 0.8) - 0.2 * std::log10(p.FvK); }
double fakeD0(const CellParameters& p, double F) { return fakeD(p) - 0.012 * F / (1.0 + 0.1 * p.mu) * (1.0 - 0.05 * p.b2); }
double fakeD1(const CellParameters& p, double F) { return fakeD(p) + 0.03 * F / (1.0 + 0.2 * p.mu) * (1.0 - 0.04 * p.b2); }
double fakeTc(const CellParameters& p) { return p.etam / p.mu * (0.8 + 0.3 * p.v + 0.05 * p.b2); }

std::vector<CampaignRow> fakeCampaign(long samples, int perCell, long failedCell = -1) {
    std::vector<CampaignRow> rows;
    for (const CampaignPoint& q : campaignDesign(DesignKind::LatinHypercube, samples, perCell, 3)) {
        CampaignRow r;
        r.point = q;
        r.seed = 3;
        r.D = fakeD(q.p), r.hmin = 0.8 + 0.5 * (1.0 - q.p.v), r.hmax = 2.6 - 0.3 * (1.0 - q.p.v);
        r.D0 = fakeD0(q.p, q.fext), r.D1 = fakeD1(q.p, q.fext), r.tc = fakeTc(q.p);
        if (q.cellId == failedCell) {
            r.tc = NAN;
            r.status = "failed";
            r.reason = "relaxation: test";
        }
        rows.push_back(r);
    }
    return rows;
}

SurrogateTrainingOptions quickOptions() {
    SurrogateTrainingOptions o;
    o.network.maxEpochs = 400;
    o.testFraction = 0.1;
    o.restarts = 4;
    return o;
}

struct TrainedFixture : ::testing::Test {
    static void SetUpTestSuite() {
        report = new SurrogateTrainingReport(trainSurrogate(fakeCampaign(2400, 8, 5), quickOptions()));
    }
    static void TearDownTestSuite() { delete report; }
    static SurrogateTrainingReport* report;
};
SurrogateTrainingReport* TrainedFixture::report = nullptr;

TEST_F(TrainedFixture, TestSetIsWholeCellsAndAccurate) {
    const auto& r = *report;
    EXPECT_EQ(r.cells, 300);
    EXPECT_EQ(r.testCells, 30);
    EXPECT_EQ(r.testInputs.cols(), 30 * 8);
    // The failed cell's relaxation row is dropped (and its stretching rows kept) unless it is a test cell.
    EXPECT_LE(r.dropped[2], 1);
    EXPECT_EQ(r.dropped[1], 0);
    EXPECT_EQ(r.used[0] + r.dropped[0], 270);
    ASSERT_EQ(r.test.size(), 6u);
    // Smooth functions, 270 cells: measured relative RMSE 0.1-0.6 %, R^2 >= 0.97 (D varies by
    // only +-0.5 um, with a log(FvK) bend at small FvK).
    for (const OutputAccuracy& a : r.test) {
        EXPECT_LT(a.relativeRmse, a.name == "tc_s" ? 0.03 : 0.01) << a.name;
        EXPECT_GT(a.r2, 0.95) << a.name;
    }
}

TEST_F(TrainedFixture, InvariancesOfSurrogate52) {
    const Surrogate& s = report->model;
    Eigen::MatrixXd x(6, 2);
    x.col(0) << 0.9, 2.0, 300.0, 1.0, 0.3, 50.0;
    x.col(1) << 0.9, 8.0, 300.0, 3.0, 0.9, 50.0;  // other mu, b2, etam
    const Eigen::MatrixXd y = s.evaluate(x);
    EXPECT_EQ(y.block(0, 0, 3, 1), y.block(0, 1, 3, 1));  // equilibrium ignores mu, b2, etam
    // Relaxation: exactly etam / mu times the network output (which itself takes etam and mu,
    // for the reference's vertex inertia).
    Eigen::MatrixXd r(5, 2);
    r.col(0) << 0.9, 4.0, 300.0, 1.0, 0.2;
    r.col(1) << 0.7, 6.0, 30.0, 2.0, 0.8;
    const Eigen::VectorXd tc = s.relaxationTime(r);
    const Eigen::MatrixXd net = s.relaxation.evaluate(r);
    EXPECT_EQ(tc(0), net(0, 0) * 0.2 / 4.0);
    EXPECT_EQ(tc(1), net(0, 1) * 0.8 / 6.0);
    // And in the training data tc mu / etam is what the network learns: with the fake model's
    // tc = etam / mu g(v, b2), doubling etam doubles tc within the fit error.
    Eigen::MatrixXd r2 = r;
    r2(4, 0) = 0.4;
    EXPECT_NEAR(s.relaxationTime(r2)(0) / tc(0), 2.0, 0.05);
}

TEST_F(TrainedFixture, SaveLoadGivesIdenticalOutputs) {
    TempDir tmp;
    report->model.save(tmp.path() / "m");
    const Surrogate loaded = Surrogate::load(tmp.path() / "m");
    EXPECT_EQ(loaded.evaluate(report->testInputs), report->model.evaluate(report->testInputs));
    EXPECT_EQ(loaded.stretching.dataHash, report->dataHash);
    fs::remove(tmp.path() / "m" / "relaxation.json");
    try {
        Surrogate::load(tmp.path() / "m");
        ADD_FAILURE() << "loaded a model without its relaxation network";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("relaxation.json"), std::string::npos) << e.what();
    }
}

TEST_F(TrainedFixture, SurrogateTestOnTheHeldOutCellsReproducesTheTrainingReport) {
    const auto rows = fakeCampaign(2400, 8, 5);
    const std::set<long> testCells(report->testCellIds.begin(), report->testCellIds.end());
    std::vector<CampaignRow> held;
    for (const CampaignRow& r : rows)
        if (testCells.count(r.point.cellId)) held.push_back(r);
    std::vector<const CampaignRow*> ptrs;
    for (auto it = held.rbegin(); it != held.rend(); ++it) ptrs.push_back(&*it);  // any order: sorted by cell and sample
    const SurrogateTest t = testSurrogate(report->model, ptrs);
    EXPECT_EQ(t.predicted, report->testPredicted);
    ASSERT_EQ(t.accuracy.size(), 6u);
    for (std::size_t k = 0; k < 6; ++k) {
        EXPECT_EQ(t.accuracy[k].n, report->test[k].n) << t.accuracy[k].name;
        EXPECT_EQ(t.accuracy[k].rmse, report->test[k].rmse) << t.accuracy[k].name;
    }
    EXPECT_EQ(t.accuracy[5].n, 30);  // tc once per cell

    // The CLI: the same numbers from files; the training table itself is named as such.
    TempDir tmp;
    report->model.save(tmp.path() / "m");
    auto writeTable = [&](const fs::path& p, const std::vector<CampaignRow>& table) {
        std::ofstream out(p);
        out << campaignCsvHeader() << '\n';
        for (const CampaignRow& r : table) out << formatCampaignRow(r) << '\n';
    };
    writeTable(tmp.path() / "held.csv", held);
    writeTable(tmp.path() / "all.csv", rows);
    const std::string model = " --model " + shellQuote((tmp.path() / "m").string());
    auto data = [&](const char* name) { return " --data " + shellQuote((tmp.path() / name).string()); };
    auto r = runTrbc("surrogate test" + model + data("held.csv") + " --out " + shellQuote((tmp.path() / "t").string()), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    nlohmann::json j;
    {
        std::ifstream in(tmp.path() / "t" / "test.json");
        j = nlohmann::json::parse(in);
    }
    EXPECT_EQ(j["test"][5]["output"], "tc_s");
    EXPECT_EQ(j["test"][5]["relative_rmse"].get<double>(), report->test[5].relativeRmse);
    EXPECT_FALSE(j["trained_on_these_data"].get<bool>());
    EXPECT_TRUE(fs::exists(tmp.path() / "t" / "test_predictions.csv"));
    r = runTrbc("surrogate test" + model + data("all.csv"), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find("trained on these rows"), std::string::npos) << r.err;
    EXPECT_NE(r.out.find("not a test"), std::string::npos) << r.out;
    r = runTrbc("surrogate test" + model + data("missing.csv"), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("missing.csv"), std::string::npos) << r.err;
}

TEST(SurrogateBox, OutsideTrainingBoxIsFlagged) {
    Eigen::MatrixXd x(6, 3);
    x.col(0) << 0.9, 4.0, 300.0, 1.0, 0.5, 100.0;
    x.col(1) << 0.9, 4.0, 300.0, 1.0, 1.5, 100.0;  // etam above 1 (INFERENCE 3.3 does this)
    x.col(2) << 0.9, 4.0, 300.0, 1.0, 0.5, 250.0;
    const auto out = outsideTrainingBox(x);
    EXPECT_EQ(out, (std::vector<bool>{false, true, true}));
}

TEST(SurrogateTraining, DataHashIgnoresWallTimeAndTracksValues) {
    auto rows = fakeCampaign(200, 4);
    auto opt = quickOptions();
    opt.network.maxEpochs = 2;
    const std::string h1 = trainSurrogate(rows, opt).dataHash;
    rows[7].wallSeconds = 99.0;
    EXPECT_EQ(trainSurrogate(rows, opt).dataHash, h1);
    rows[7].D0 += 1e-9;
    EXPECT_NE(trainSurrogate(rows, opt).dataHash, h1);
    rows.resize(20);  // 5 cells
    EXPECT_THROW(trainSurrogate(rows, opt), InputError);
}

TEST_F(TrainedFixture, RelaxationAndStretchingNetworksWorkOnTransformedParameters) {
    using T = VariableTransform;
    EXPECT_EQ(report->model.relaxation.inputTransforms, (std::vector<T>{T::Identity, T::Log, T::Log, T::Identity, T::Log}));
    EXPECT_EQ(report->model.relaxation.outputTransforms, (std::vector<T>{T::Log}));
    EXPECT_EQ(report->model.stretching.inputTransforms, (std::vector<T>{T::Identity, T::Identity, T::Identity, T::Sqrt, T::Identity}));
    EXPECT_TRUE(report->model.stretching.outputTransforms.empty());
    EXPECT_TRUE(report->model.equilibrium.inputTransforms.empty());
    auto opt = quickOptions();
    opt.logRelaxation = false;
    opt.sqrtB2Stretching = false;
    opt.network.maxEpochs = 2;
    const auto linear = trainSurrogate(fakeCampaign(400, 8), opt);
    EXPECT_TRUE(linear.model.relaxation.inputTransforms.empty() && linear.model.relaxation.outputTransforms.empty());
    EXPECT_TRUE(linear.model.stretching.inputTransforms.empty());
}

TEST_F(TrainedFixture, RelaxationNetworkAveragesAllItsRestarts) {
    // restarts 4 (quickOptions): the best network plus the other three as ensemble members;
    // the equilibrium and stretching networks keep only their best restart.
    const TrainedNetwork& rx = report->model.relaxation;
    ASSERT_EQ(rx.ensemble.size(), 3u);
    std::vector<std::uint64_t> seeds{rx.options.seed};
    for (const EnsembleMember& m : rx.ensemble) {
        seeds.push_back(m.seed);
        EXPECT_GE(m.bestValidationLoss, rx.history.bestValidationLoss);  // the kept network is the best
        EXPECT_EQ(m.net.layerSizes(), rx.net.layerSizes());
    }
    std::sort(seeds.begin(), seeds.end());
    EXPECT_EQ(seeds, (std::vector<std::uint64_t>{1, 2, 3, 4}));
    EXPECT_TRUE(report->model.equilibrium.ensemble.empty());
    EXPECT_TRUE(report->model.stretching.ensemble.empty());
    // the tc of the model is the ensemble's: not the best member's alone
    TrainedNetwork best = rx;
    best.ensemble.clear();
    const Eigen::MatrixXd x = report->testInputs.topRows(5);
    EXPECT_FALSE(rx.evaluate(x).isApprox(best.evaluate(x), 1e-9));
    // and it is saved with the model
    TempDir tmp;
    report->model.save(tmp.path() / "m");
    const Surrogate back = Surrogate::load(tmp.path() / "m");
    EXPECT_EQ(back.relaxation.ensemble.size(), 3u);
    EXPECT_TRUE(back.evaluate(report->testInputs) == report->model.evaluate(report->testInputs));
    // ensemble off: a single network
    auto opt = quickOptions();
    opt.ensemble[2] = false;
    opt.network.maxEpochs = 2;
    EXPECT_TRUE(trainSurrogate(fakeCampaign(400, 8), opt).model.relaxation.ensemble.empty());
    // the command line rejects "none" together with a network, and an unknown network, before reading data
    auto r = runTrbc("surrogate train --data missing.csv --out m --ensemble none,relaxation", tmp.path());
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.err.find("--ensemble none cannot be combined"), std::string::npos) << r.err;
    r = runTrbc("surrogate train --data missing.csv --out m --ensemble relaxaton", tmp.path());
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.err.find("relaxaton"), std::string::npos) << r.err;
}

TEST_F(TrainedFixture, DistilledRelaxationNetworkReproducesItsEnsemble) {
    // Same data, options and seeds as the fixture, so the teacher is the fixture's 4-member ensemble.
    auto opt = quickOptions();
    opt.distill[2] = true;
    opt.distillSamples = 6000;
    const SurrogateTrainingReport rep = trainSurrogate(fakeCampaign(2400, 8, 5), opt);
    const TrainedNetwork& student = rep.model.relaxation;
    const TrainedNetwork& teacher = report->model.relaxation;
    ASSERT_EQ(teacher.ensemble.size(), 3u);
    EXPECT_TRUE(student.ensemble.empty());  // one network pass per evaluation
    EXPECT_EQ(student.distillation.members, 4);
    EXPECT_EQ(student.distillation.samples, 6000);
    EXPECT_EQ(student.distillation.teacherValidationLoss, teacher.history.bestValidationLoss);
    EXPECT_EQ(student.inputTransforms, teacher.inputTransforms);
    // the other networks are untouched
    EXPECT_TRUE(rep.model.stretching.net.layerSizes() == report->model.stretching.net.layerSizes());
    EXPECT_TRUE(rep.model.evaluate(report->testInputs).topRows(5) == report->model.evaluate(report->testInputs).topRows(5));
    // On the held-out cells the student follows the teacher (relative difference of tc) and is as
    // close to the truth as the teacher, within a small fraction of the teacher's own error.
    const Eigen::VectorXd tS = rep.model.evaluate(report->testInputs).row(5).transpose();
    const Eigen::VectorXd tT = report->model.evaluate(report->testInputs).row(5).transpose();
    const Eigen::VectorXd truth = report->testTruth.row(5).transpose();
    double dST = 0, eS = 0, eT = 0;
    long n = 0;
    for (Eigen::Index j = 0; j < truth.size(); ++j) {
        if (!std::isfinite(truth(j))) continue;
        dST += std::pow(tS(j) / tT(j) - 1, 2), eS += std::pow(tS(j) / truth(j) - 1, 2), eT += std::pow(tT(j) / truth(j) - 1, 2);
        ++n;
    }
    ASSERT_GT(n, 100);
    dST = std::sqrt(dST / n), eS = std::sqrt(eS / n), eT = std::sqrt(eT / n);
    EXPECT_LT(dST, 0.01) << "student vs teacher";
    EXPECT_LT(eS, eT + 0.5 * dST + 1e-3) << "student " << eS << " teacher " << eT;
    // saved and loaded with its provenance
    TempDir tmp;
    rep.model.save(tmp.path() / "m");
    const Surrogate back = Surrogate::load(tmp.path() / "m");
    EXPECT_EQ(back.relaxation.distillation.members, 4);
    EXPECT_EQ(back.relaxation.distillation.seed, opt.distillSeed);
    EXPECT_TRUE(back.evaluate(report->testInputs) == rep.model.evaluate(report->testInputs));
    // nothing to distill from without an ensemble; too few box samples
    auto r = runTrbc("surrogate train --data missing.csv --out m --ensemble none --distill relaxation", tmp.path());
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.err.find("--distill relaxation needs relaxation in --ensemble"), std::string::npos) << r.err;
    opt.distillSamples = 10;
    opt.network.maxEpochs = 2;
    EXPECT_THROW(trainSurrogate(fakeCampaign(400, 8), opt), InputError);
}

// The command's default: the relaxation ensemble is distilled into one network; with
// --ensemble none and no --distill there is nothing to distill and training goes on without it.
TEST(SurrogateTrainCli, DistillsTheRelaxationEnsembleByDefault) {
    TempDir tmp;
    {
        std::ofstream out(tmp.path() / "c.csv");
        out << campaignCsvHeader() << '\n';
        for (const CampaignRow& r : fakeCampaign(320, 8)) out << formatCampaignRow(r) << '\n';
    }
    const std::string common = "surrogate train --data " + shellQuote((tmp.path() / "c.csv").string()) +
                               " --restarts 2 --max-epochs 3 --distill-samples 1000 --threads 1 --out ";
    auto relaxationJson = [&](const char* dir) {
        std::ifstream in(tmp.path() / dir / "relaxation.json");
        return nlohmann::json::parse(in);
    };
    auto r = runTrbc(common + shellQuote((tmp.path() / "d").string()), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const Surrogate d = Surrogate::load(tmp.path() / "d");
    EXPECT_TRUE(d.relaxation.ensemble.empty());
    EXPECT_EQ(d.relaxation.distillation.members, 2);
    EXPECT_EQ(d.relaxation.distillation.samples, 1000);
    EXPECT_FALSE(relaxationJson("d")["command"].get<std::string>().empty());

    r = runTrbc(common + shellQuote((tmp.path() / "e").string()) + " --ensemble none", tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const Surrogate e = Surrogate::load(tmp.path() / "e");
    EXPECT_TRUE(e.relaxation.ensemble.empty());
    EXPECT_EQ(e.relaxation.distillation.members, 0);

    r = runTrbc(common + shellQuote((tmp.path() / "f").string()) + " --distill none", tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(Surrogate::load(tmp.path() / "f").relaxation.ensemble.size(), 1u);  // the 2 restarts, kept
}

TEST(SurrogateTraining, CrossValidationPredictsEveryCellOnceWithoutIt) {
    const auto rows = fakeCampaign(480, 8, 3);  // 60 cells, one failed relaxation
    auto opt = quickOptions();
    opt.network.maxEpochs = 30;
    opt.restarts = 1;
    // One fold: its test cells are the positions p % 4 == 1 of the seeded permutation.
    opt.folds = 4;
    opt.fold = 1;
    const auto one = trainSurrogate(rows, opt);
    EXPECT_EQ(one.testCells, 15);
    EXPECT_EQ(one.used[1], (60 - 15) * 8);

    const CrossValidationReport cv = crossValidateSurrogate(rows, opt, 4);
    ASSERT_EQ(cv.perFold.size(), 4u);
    EXPECT_EQ(cv.cellIds.size(), rows.size());  // every row exactly once
    std::map<long, int> seen;
    for (long id : cv.cellIds) ++seen[id];
    EXPECT_EQ(seen.size(), 60u);
    for (const auto& [id, n] : seen) EXPECT_EQ(n, 8) << "cell " << id;
    // fold 1 of the pooled set is the single-fold run above, prediction for prediction
    const Eigen::Index start = cv.perFold[0][0].n * 8;
    EXPECT_TRUE(cv.predicted.middleCols(start, one.testPredicted.cols()) == one.testPredicted);
    // pooled accuracy: per cell for tc (the failed relaxation skipped), per row for D1
    EXPECT_EQ(cv.pooled[5].n, 59);
    EXPECT_EQ(cv.pooled[4].n, 480);
    double ss = 0;
    long n = 0;
    for (Eigen::Index j = 0; j < cv.truth.cols(); ++j)
        if (j == 0 || cv.cellIds[j] != cv.cellIds[j - 1])
            if (std::isfinite(cv.truth(5, j))) ss += std::pow(cv.predicted(5, j) / cv.truth(5, j) - 1, 2), ++n;
    EXPECT_NEAR(cv.pooled[5].relativeRmse, std::sqrt(ss / n), 1e-12);
    EXPECT_THROW(crossValidateSurrogate(rows, opt, 1), InputError);
    opt.fold = 4;
    EXPECT_THROW(trainSurrogate(rows, opt), InputError);
}

// A campaign whose lowest-energy equilibrium jumps to another branch above a line in (v, FvK), as
// near v = 1 (docs/FORWARD_MODEL.md): hmin jumps by 1.5 um, tc and D1 by 20 % and 0.5 um there.
bool fakeKicked(const CellParameters& p) { return p.v > 0.955 + 0.02 * (p.FvK - 10.0) / 990.0; }

std::vector<CampaignRow> fakeBranchedCampaign(long samples, int perCell, std::map<long, int>& branch) {
    std::vector<CampaignRow> rows = fakeCampaign(samples, perCell);
    for (CampaignRow& r : rows) {
        const bool kicked = fakeKicked(r.point.p);
        branch[r.point.cellId] = kicked;
        if (!kicked) continue;
        r.hmin += 1.5;
        r.D1 += 0.5;
        r.tc *= 0.8;
    }
    return rows;
}

// A smooth network smears the jump over the switch; the branched surrogate (classifier + branch input)
// keeps it: near the switch its hmin error is a fraction of the single network's.
TEST(SurrogateTraining, BranchedSurrogateFollowsAJumpAcrossTheSwitchLine) {
    std::map<long, int> branch;
    const auto rows = fakeBranchedCampaign(4000, 8, branch);
    auto opt = quickOptions();
    opt.restarts = 2;
    const SurrogateTrainingReport single = trainSurrogate(rows, opt);
    opt.cellBranch = branch;
    opt.distill[2] = true;  // as the CLI's default: the relaxation ensemble distilled on classified box points
    opt.distillSamples = 2000;
    const SurrogateTrainingReport rep = trainSurrogate(rows, opt);
    EXPECT_FALSE(single.model.branched);
    ASSERT_TRUE(rep.model.branched);
    EXPECT_EQ(rep.model.equilibrium.inputNames.back(), kBranchInputName);
    EXPECT_EQ(rep.model.relaxation.distillation.members, 2);
    EXPECT_EQ(rep.model.relaxation.inputNames.back(), kBranchInputName);
    EXPECT_EQ(rep.model.relaxation.net.numInputs(), 6);

    // Held-out cells near the switch (the same test cells for both; measured: 11 cells, 6 kicked, none
    // misclassified, hmin RMSE 0.0010 um branched against 0.22 um for the single network).
    const SwitchAccuracy a = switchAccuracy(rep.testCellIds, rep.testInputs, rep.testTruth, rep.testPredicted, branch,
                                            &rep.testBranch, &rep.cellLabel);
    const SwitchAccuracy b = switchAccuracy(single.testCellIds, single.testInputs, single.testTruth, single.testPredicted, branch,
                                            nullptr, nullptr);
    ASSERT_GT(a.kickedCells, 2);
    EXPECT_GT(a.cells, a.kickedCells);
    EXPECT_EQ(b.misclassified, -1);
    EXPECT_LE(a.misclassified, 1);
    EXPECT_LT(a.nearSwitch[1].rmse, 0.4 * b.nearSwitch[1].rmse) << a.nearSwitch[1].rmse << " vs " << b.nearSwitch[1].rmse;
    EXPECT_LT(a.kicked[1].rmse, 0.1);

    // The classifier decides the branch input of all three networks.
    Eigen::MatrixXd x(6, 2);
    x.col(0) << 0.80, 4.0, 300.0, 1.0, 0.5, 50.0;   // disc
    x.col(1) << 0.995, 4.0, 300.0, 1.0, 0.5, 50.0;  // kicked
    const Eigen::RowVectorXd bx = rep.model.branchIndicator((Eigen::MatrixXd(2, 2) << 0.80, 0.995, 300.0, 300.0).finished());
    EXPECT_EQ(bx(0), 0.0);
    EXPECT_EQ(bx(1), 1.0);
    const Eigen::MatrixXd y = rep.model.evaluate(x);
    Eigen::MatrixXd eqIn(3, 2);
    eqIn << x.row(0), x.row(2), bx;
    EXPECT_EQ(y.topRows(3), rep.model.equilibrium.evaluate(eqIn));
    EXPECT_EQ(y.topRows(3), rep.model.equilibriumOutputs(eqIn.topRows(2)));
    EXPECT_NEAR(y(1, 1) - y(1, 0), 1.5 + 0.5 * (0.80 - 0.995), 0.1);

    // Away from the switch the gradient is the branch network's: central differences in v and FvK.
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(6, 1);
    w(1, 0) = 1.0, w(5, 0) = 10.0;
    const Eigen::MatrixXd x1 = x.col(1);
    const Eigen::MatrixXd g = rep.model.inputGradient(x1, w);
    for (int k : {0, 2}) {
        const double h = k == 0 ? 1e-5 : 1e-2;
        Eigen::MatrixXd xp = x1, xm = x1;
        xp(k, 0) += h, xm(k, 0) -= h;
        const double fd = (w.col(0).dot(rep.model.evaluate(xp).col(0)) - w.col(0).dot(rep.model.evaluate(xm).col(0))) / (2 * h);
        EXPECT_NEAR(g(k, 0), fd, 1e-4 * std::max(1.0, std::abs(fd))) << "input " << k;
    }

    // Save and load keep the classifier; an unbranched model saved over it removes branch.json.
    TempDir tmp;
    rep.model.save(tmp.path() / "m");
    ASSERT_TRUE(fs::exists(tmp.path() / "m" / "branch.json"));
    const Surrogate loaded = Surrogate::load(tmp.path() / "m");
    EXPECT_TRUE(loaded.branched);
    EXPECT_EQ(loaded.evaluate(rep.testInputs), rep.model.evaluate(rep.testInputs));
    single.model.save(tmp.path() / "m");
    EXPECT_FALSE(fs::exists(tmp.path() / "m" / "branch.json"));
    EXPECT_FALSE(Surrogate::load(tmp.path() / "m").branched);
    // A branch.json beside networks without the branch input is refused, naming the file.
    saveNetwork(rep.model.branch, (tmp.path() / "m" / "branch.json").string());
    try {
        Surrogate::load(tmp.path() / "m");
        ADD_FAILURE() << "loaded networks without the branch input beside a branch classifier";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("branch input"), std::string::npos) << e.what();
    }
}

TEST(SurrogateTraining, SwitchAccuracySeparatesTheMisclassifiedCells) {
    // Four cells, one row each: a disc far from the switch, a disc and two cups near it (the switch
    // at v 0.985, the smaller cup v), one cup classified as a disc. hmin is output 1.
    const std::vector<long> ids{1, 2, 3, 4};
    Eigen::MatrixXd in = Eigen::MatrixXd::Zero(6, 4), truth = Eigen::MatrixXd::Constant(6, 4, 1.0), pred = truth;
    in.row(0) << 0.80, 0.97, 0.99, 0.985;
    truth.row(1) << 0.9, 0.6, 2.0, 2.0;
    pred.row(1) << 0.9, 0.62, 1.97, 0.8;
    const std::map<long, int> branch{{1, 0}, {2, 0}, {3, 1}, {4, 1}}, labels = branch;
    const Eigen::RowVectorXd predicted = (Eigen::RowVectorXd(4) << 0, 0, 1, 0).finished();
    const SwitchAccuracy a = switchAccuracy(ids, in, truth, pred, branch, &predicted, &labels);
    EXPECT_DOUBLE_EQ(a.vSwitch, 0.985);
    EXPECT_EQ(a.cells, 3);
    EXPECT_EQ(a.misclassified, 1);
    EXPECT_EQ(a.rightBranchCells, 2);
    EXPECT_NEAR(a.rightBranch[1].rmse, std::sqrt((0.02 * 0.02 + 0.03 * 0.03) / 2), 1e-12);
    EXPECT_NEAR(a.nearSwitch[1].rmse, std::sqrt((0.02 * 0.02 + 0.03 * 0.03 + 1.2 * 1.2) / 3), 1e-12);
    // The jump bound of one misclassified cell: RMSE >= 1.2 / sqrt(3).
    EXPECT_GE(a.nearSwitch[1].rmse, 1.2 / std::sqrt(3.0));
    // Without a classifier nothing is split off.
    const SwitchAccuracy b = switchAccuracy(ids, in, truth, pred, branch, nullptr, nullptr);
    EXPECT_EQ(b.misclassified, -1);
    EXPECT_TRUE(b.rightBranch.empty());
}

TEST_F(TrainedFixture, EvalCliWritesOutputsAndFlagsExtrapolation) {
    TempDir tmp;
    report->model.save(tmp.path() / "m");
    const fs::path in = tmp.path() / "in.csv", out = tmp.path() / "out.csv";
    std::ofstream(in) << "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um,Fext_pN,comment\n0.9,4,1.8e-19,1,0.5,100,a\n0.9,4,1.8e-19,1,1.5,100,b\n";
    const std::string model = " --model " + shellQuote((tmp.path() / "m").string());
    auto r = runTrbc("surrogate eval" + model + " --in " + shellQuote(in.string()) + " --out " + shellQuote(out.string()), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find("1 outside the training box"), std::string::npos) << r.err;
    std::ifstream res(out);
    std::string header, l1, l2;
    do std::getline(res, header);  // past the provenance line
    while (!header.empty() && header[0] == '#');
    std::getline(res, l1), std::getline(res, l2);
    EXPECT_EQ(header, "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN,D_um,hmin_um,hmax_um,D0_um,D1_um,tc_s,outside_training_box");
    EXPECT_EQ(l1.back(), '0');
    EXPECT_EQ(l2.back(), '1');

    std::ofstream(in) << "v,mu_uN_per_m,FvK,b2,Fext_pN\n0.9,4,250,1,100\n";
    r = runTrbc("surrogate eval" + model + " --in " + shellQuote(in.string()) + " --out " + shellQuote(out.string()), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("missing column 'etam_Pa_s_um'"), std::string::npos) << r.err;
    std::ofstream(in) << "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN\n0.9,4,250,1,0.5,100\n0.9,four,250,1,0.5,100\n";
    r = runTrbc("surrogate eval" + model + " --in " + shellQuote(in.string()) + " --out " + shellQuote(out.string()), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("in.csv:3: column 'mu_uN_per_m': 'four' is not a finite number"), std::string::npos) << r.err;
    r = runTrbc("surrogate eval --model " + shellQuote((tmp.path() / "none").string()) + " --in " + shellQuote(in.string()) +
                    " --out " + shellQuote(out.string()),
                tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("missing"), std::string::npos) << r.err;
}

TEST_F(TrainedFixture, SobolOfTheSurrogateHasTheStructureOfItsNetworks) {
    TempDir tmp;
    report->model.save(tmp.path() / "m");
    const auto r = runTrbc("sobol --no-plot --samples 512 --forces 3 --resamples 20 --seed 2 --model " +
                               shellQuote((tmp.path() / "m").string()) + " --out " + shellQuote((tmp.path() / "s").string()),
                           tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    std::ifstream in(tmp.path() / "s" / "sobol_indices.csv");
    std::string line;
    do std::getline(in, line);  // past the provenance line
    while (!line.empty() && line[0] == '#');
    EXPECT_EQ(line, "output,input,S1,S1_ci,ST,ST_ci");
    int checked = 0;
    while (std::getline(in, line)) {
        std::stringstream ss(line);
        std::string output, input, s1, s1ci, st;
        std::getline(ss, output, ','), std::getline(ss, input, ','), std::getline(ss, s1, ','), std::getline(ss, s1ci, ','),
            std::getline(ss, st, ',');
        const bool eq = output == "D_um" || output == "hmin_um" || output == "hmax_um";
        const bool stretch = output.rfind("D0_um@", 0) == 0 || output.rfind("D1_um@", 0) == 0;
        const bool inert = (eq && input != "v" && input != "FvK") || (stretch && input == "etam_Pa_s_um");
        if (inert) {  // a network input that is not there: exactly zero
            EXPECT_EQ(std::stod(s1), 0.0) << line;
            EXPECT_EQ(std::stod(st), 0.0) << line;
            ++checked;
        }
        EXPECT_LE(std::stod(s1), std::stod(st) + 0.05) << line;
    }
    EXPECT_EQ(checked, 3 * 3 + 6);
}

}  // namespace
}  // namespace trbc
