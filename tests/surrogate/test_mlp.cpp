// Network code of the surrogates (docs/CAMPAIGN_AND_SURROGATE.md): forward pass, back-propagation, scaling,
// seeded split and training determinism, learning a known function with the schedule of 3.4,
// JSON save/load.
#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <numbers>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>

#include "core/error.hpp"
#include "core/simd.hpp"
#include "surrogate/mlp.hpp"
#include "surrogate/network_io.hpp"
#include "surrogate/scaling.hpp"
#include "surrogate/training.hpp"

namespace trbc {
namespace {

/// Restores the OpenMP thread count of the calling thread on scope exit.
struct ThreadCount {
    int saved = omp_get_max_threads();
    ~ThreadCount() { omp_set_num_threads(saved); }
};

/// u ~ U[0, 1) from the top 53 bits.
double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

Eigen::MatrixXd randomMatrix(Eigen::Index rows, Eigen::Index cols, std::uint64_t seed, double lo = -1.0, double hi = 1.0) {
    std::mt19937_64 rng(seed);
    Eigen::MatrixXd A(rows, cols);
    for (Eigen::Index k = 0; k < A.size(); ++k) A.data()[k] = lo + (hi - lo) * uniform01(rng);
    return A;
}

/// Samples of g(x1, x2) = sin(pi x1) exp(x2) on [0, 1]^2 (SURROGATE 5.1.5).
void smoothFunctionData(int n, std::uint64_t seed, Eigen::MatrixXd& X, Eigen::MatrixXd& Y) {
    X = randomMatrix(2, n, seed, 0.0, 1.0);
    Y.resize(1, n);
    for (int i = 0; i < n; ++i) Y(0, i) = std::sin(std::numbers::pi * X(0, i)) * std::exp(X(1, i));
}

std::string tempPath(const std::string& name) {
    return (std::filesystem::temp_directory_path() /
            ("trbc_test_mlp_" + std::to_string(::getpid()) + "_" + name))
        .string();
}

// ---------------------------------------------------------------------------------------------
// Mlp

TEST(Mlp, ForwardOfHandSetTwoThreeOneNetworkMatchesHandComputation) {
    // SURROGATE 5.1.1: 2 -> 3 -> 1, hand-set weights
    Mlp net({2, 3, 1});
    net.weights(0) << 0.5, -1.0, 0.25, 0.75, -0.3, 0.2;
    net.biases(0) << 0.1, -0.2, 0.05;
    net.weights(1) << 1.0, -2.0, 0.5;
    net.biases(1) << 0.3;
    Eigen::MatrixXd X(2, 4);
    X << 0.0, 1.0, -0.7, 2.5,  //
        0.0, -0.5, 0.4, 1.5;
    const Eigen::MatrixXd Y = net.forward(X);
    ASSERT_EQ(Y.rows(), 1);
    ASSERT_EQ(Y.cols(), 4);
    for (int j = 0; j < 4; ++j) {
        const double x1 = X(0, j), x2 = X(1, j);
        const double h1 = std::tanh(0.5 * x1 - 1.0 * x2 + 0.1);
        const double h2 = std::tanh(0.25 * x1 + 0.75 * x2 - 0.2);
        const double h3 = std::tanh(-0.3 * x1 + 0.2 * x2 + 0.05);
        const double y = 1.0 * h1 - 2.0 * h2 + 0.5 * h3 + 0.3;
        EXPECT_NEAR(Y(0, j), y, 4e-16 * (1.0 + std::abs(y))) << "column " << j;
    }
}

TEST(Mlp, VectorisedTanhAgreesWithStdTanhToRoundOff) {
    std::mt19937_64 rng(3);
    std::vector<double> x;
    for (int i = 0; i < 200000; ++i)  // log-uniform magnitudes 1e-12 .. 30, both signs
        x.push_back((uniform01(rng) < 0.5 ? -1.0 : 1.0) * std::pow(10.0, -12.0 + 13.5 * uniform01(rng)));
    for (double s : {0.0, -0.0, 0.125, -0.125, std::nextafter(0.125, 0.0), 19.9, 20.0, 25.0, -700.0, 1e300})
        x.push_back(s);
    for (int i = 0; i < 20000; ++i) x.push_back(0.4 * uniform01(rng) - 0.2);  // around the k = 0 / 1 switch at 0.173
    std::vector<double> y = x;
    tanhInPlace(y.data(), static_cast<Eigen::Index>(y.size()));  // odd length: exercises the tail
    double worstUlp = 0.0;  // in units of the last place of the correctly rounded value
    for (std::size_t i = 0; i < x.size(); ++i) {
        const long double ref = std::tanh(static_cast<long double>(x[i]));
        const double r = static_cast<double>(ref);
        if (r == 0.0) {
            EXPECT_EQ(y[i], 0.0);
            continue;
        }
        const double ulp = std::nextafter(std::abs(r), INFINITY) - std::abs(r);
        worstUlp = std::max(worstUlp, static_cast<double>(std::abs(y[i] - ref)) / ulp);
    }
    std::cout << "tanh: worst error " << worstUlp << " ulp\n";
    EXPECT_LT(worstUlp, 2.5);
    double special[4] = {std::nan(""), std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(), -0.0};
    tanhInPlace(special, 4);
    EXPECT_TRUE(std::isnan(special[0]));
    EXPECT_EQ(special[1], 1.0);
    EXPECT_EQ(special[2], -1.0);
    EXPECT_TRUE(special[3] == 0.0 && std::signbit(special[3]));
}

TEST(Mlp, GlorotUniformInitialisationIsSeededAndBounded) {
    const std::vector<int> sizes{5, 32, 32, 32, 2};
    const Mlp a = Mlp::glorotUniform(sizes, 42), b = Mlp::glorotUniform(sizes, 42), c = Mlp::glorotUniform(sizes, 43);
    EXPECT_EQ(a.numParameters(), 5 * 32 + 32 + 2 * (32 * 32 + 32) + 32 * 2 + 2);
    EXPECT_TRUE(a.parameters() == b.parameters());  // bit-identical
    EXPECT_FALSE(a.parameters() == c.parameters());
    for (int l = 0; l < a.numLayers(); ++l) {
        const double bound = std::sqrt(6.0 / (sizes[l] + sizes[l + 1]));
        const auto W = a.weights(l);
        EXPECT_LE(W.cwiseAbs().maxCoeff(), bound);
        EXPECT_GT(W.cwiseAbs().maxCoeff(), 0.9 * bound);  // fills the interval
        EXPECT_NEAR(W.mean(), 0.0, 4.0 * bound / std::sqrt(3.0 * W.size()));  // 4 SD of the mean
        EXPECT_TRUE((a.biases(l).array() == 0.01).all());
    }
}

TEST(Mlp, BackpropagatedGradientMatchesCentralFiniteDifferences) {
    // SURROGATE 5.1.2: random weights (larger than Glorot, so the tanh layers are non-linear),
    // random batch, unequal widths, several outputs
    Mlp net({3, 7, 5, 2});
    net.mutableParameters() = randomMatrix(net.numParameters(), 1, 11, -0.8, 0.8);
    const Eigen::MatrixXd X = randomMatrix(3, 9, 12, -2.0, 2.0), Y = randomMatrix(2, 9, 13);
    MlpWorkspace ws;
    Eigen::VectorXd g;
    const double L = net.lossAndGradient(X, Y, g, ws);
    EXPECT_NEAR(L, net.loss(X, Y), 1e-15 * L);  // same loss (summation order may differ)
    ASSERT_EQ(g.size(), net.numParameters());

    Eigen::VectorXd fd(g.size());
    const double h = 1e-5;
    for (Eigen::Index k = 0; k < g.size(); ++k) {
        Mlp p = net, m = net;
        p.mutableParameters()[k] += h;
        m.mutableParameters()[k] -= h;
        fd[k] = (p.loss(X, Y) - m.loss(X, Y)) / (2.0 * h);
    }
    const double relNorm = (g - fd).norm() / g.norm();
    double worstComponent = 0.0;  // components above 1e-3 of the largest
    for (Eigen::Index k = 0; k < g.size(); ++k)
        if (std::abs(g[k]) > 1e-3 * g.cwiseAbs().maxCoeff())
            worstComponent = std::max(worstComponent, std::abs(g[k] - fd[k]) / std::abs(g[k]));
    std::cout << "gradient vs FD: relative error (norm) " << relNorm << ", worst component " << worstComponent << "\n";
    EXPECT_LT(relNorm, 1e-6);
    EXPECT_LT(worstComponent, 1e-6);
}

TEST(Mlp, BatchedForwardIsIndependentOfThreadCountAndBlocking) {
    const ThreadCount restore;
    const Mlp net = Mlp::glorotUniform({5, 32, 32, 32, 2}, 5);
    const Eigen::MatrixXd X = randomMatrix(5, 3 * Mlp::kBlockColumns + 37, 6, -2.0, 2.0);
    omp_set_num_threads(1);
    const Eigen::MatrixXd Y1 = net.forward(X);
    omp_set_num_threads(2);
    const Eigen::MatrixXd Y2 = net.forward(X);
    EXPECT_TRUE(Y1 == Y2);  // bit-identical
    // A small batch computes only the tiles it fills, with the same tile code: on every SIMD path the
    // CPU offers, its columns equal that path's full blocks to the bit, wherever they sit, and so
    // does a one-sample evaluation.
    const simd::Path saved = simd::active();
    for (const simd::Path p : {simd::Path::portable, simd::Path::avx2}) {
        if (!simd::cpuOffers(p)) continue;
        simd::force(p);
        const Eigen::MatrixXd full = net.forward(X);
        for (const Eigen::Index n : {Eigen::Index(1), Eigen::Index(16), Eigen::Index(25), Mlp::kBlockColumns - 1}) {
            const Eigen::Index c0 = Mlp::kBlockColumns - n / 2;  // spans the first block boundary (n >= 2)
            EXPECT_TRUE(net.forward(X.middleCols(c0, n)) == full.middleCols(c0, n)) << n << " columns, " << simd::name(p);
        }
        for (Eigen::Index j : {Eigen::Index(0), X.cols() / 2, X.cols() - 1})
            EXPECT_TRUE(net.forward(X.col(j)) == full.col(j)) << simd::name(p);
    }
    simd::force(saved);
    EXPECT_THROW(net.forward(Eigen::MatrixXd::Zero(4, 3)), std::invalid_argument);
}

TEST(Mlp, EverySimdPathTheCpuOffersAgreesWithThePortablePath) {
    // The forward kernels and the tanh (core/simd.hpp) forced one by one: each path agrees with the
    // portable one to the rounding (FMA or not), NaN and the saturation included, and a path other
    // than the portable one changes some last bits (it ran).
    const ThreadCount restore;
    omp_set_num_threads(1);
    const Mlp net = Mlp::glorotUniform({7, 32, 32, 30, 3}, 11);  // 30: a remainder of 2 rows per tile
    const Eigen::MatrixXd X = randomMatrix(7, 3 * Mlp::kBlockColumns + 37, 12, -3.0, 3.0);
    Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(1001, -25.0, 25.0);
    t(500) = std::numeric_limits<double>::quiet_NaN();
    const simd::Path saved = simd::active();
    simd::force(simd::Path::portable);
    const Eigen::MatrixXd Y0 = net.forward(X);
    Eigen::VectorXd t0 = t;
    tanhInPlace(t0.data(), t0.size());
    int tried = 0;
    for (const simd::Path p : {simd::Path::avx2}) {
        if (!simd::cpuOffers(p)) continue;
        ++tried;
        simd::force(p);
        const Eigen::MatrixXd Y = net.forward(X);
        EXPECT_LT((Y - Y0).cwiseAbs().maxCoeff(), 1e-13) << simd::name(p);
        EXPECT_GT((Y - Y0).cwiseAbs().maxCoeff(), 0.0) << simd::name(p);
        Eigen::VectorXd tp = t;
        tanhInPlace(tp.data(), tp.size());
        EXPECT_TRUE(std::isnan(tp(500))) << simd::name(p);
        tp(500) = t0(500) = 0.0;
        EXPECT_LT((tp - t0).cwiseAbs().maxCoeff(), 4e-16) << simd::name(p);
        EXPECT_EQ(tp(0), -1.0);
        EXPECT_EQ(tp(1000), 1.0);
    }
    simd::force(saved);
    if (tried == 0) GTEST_SKIP() << "this CPU offers the portable path only";
}

TEST(Mlp, TiledForwardMatchesPlainProductsForAnyLayerSizes) {
    // widths that are not multiples of the 4-row tile (remainders 1, 2, 3) and batches that end
    // inside a tile, against Eigen's products and std::tanh column by column
    const ThreadCount restore;
    omp_set_num_threads(1);
    for (const std::vector<int>& sizes : {std::vector<int>{3, 7, 5, 2}, {6, 33, 1}, {1, 4, 9, 10, 3}, {2, 1}}) {
        Mlp net(sizes);
        net.mutableParameters() = randomMatrix(net.numParameters(), 1, 31, -0.9, 0.9);
        const Eigen::MatrixXd X = randomMatrix(sizes.front(), Mlp::kBlockColumns + 13, 32, -2.0, 2.0);
        const Eigen::MatrixXd Y = net.forward(X);
        Eigen::MatrixXd a = X;
        for (int l = 0; l < net.numLayers(); ++l) {
            Eigen::MatrixXd z = net.weights(l) * a;
            z.colwise() += net.biases(l);
            if (l + 1 < net.numLayers()) z = z.unaryExpr([](double v) { return std::tanh(v); });
            a = z;
        }
        EXPECT_LT((Y - a).cwiseAbs().maxCoeff(), 1e-14 * (1.0 + a.cwiseAbs().maxCoeff())) << "layers " << sizes.size();
    }
}

TEST(Mlp, SinglePrecisionEvaluationAgreesWithDouble) {
    const ThreadCount restore;
    const Mlp net = Mlp::glorotUniform({5, 32, 32, 32, 2}, 9);
    const Eigen::MatrixXd X = randomMatrix(5, 2 * Mlp::kBlockColumns + 11, 10, -2.5, 2.5);
    const Eigen::MatrixXd Yd = net.forward(X), Ys = net.forward(X, Precision::Single);
    const double scale = Yd.cwiseAbs().maxCoeff();
    EXPECT_LT((Ys - Yd).cwiseAbs().maxCoeff(), 1e-5 * scale);
    EXPECT_FALSE(Ys == Yd);  // really computed in float
    omp_set_num_threads(2);
    EXPECT_TRUE(net.forward(X, Precision::Single) == Ys);
}

// ---------------------------------------------------------------------------------------------
// Scaling

TEST(Scaling, UsesPopulationStandardDeviationOverAllSamples) {
    Eigen::MatrixXd data(2, 4);
    data << 1.0, 2.0, 3.0, 4.0,  //
        10.0, 10.0, 10.0, 14.0;
    const Standardisation s = Standardisation::fit(data);
    EXPECT_DOUBLE_EQ(s.mean[0], 2.5);
    EXPECT_DOUBLE_EQ(s.sd[0], std::sqrt(1.25));  // divisor n = 4 (n - 1 would give sqrt(5/3))
    EXPECT_DOUBLE_EQ(s.mean[1], 11.0);
    EXPECT_DOUBLE_EQ(s.sd[1], std::sqrt(3.0));
    const Eigen::MatrixXd z = s.apply(data);
    EXPECT_NEAR(z.row(0).mean(), 0.0, 1e-15);
    EXPECT_NEAR(z.row(0).squaredNorm() / 4.0, 1.0, 1e-15);
}

TEST(Scaling, RoundTripReturnsTheDataToRoundOff) {
    Eigen::MatrixXd data = randomMatrix(3, 1000, 21);
    data.row(1) = data.row(1) * 300.0 + Eigen::RowVectorXd::Constant(1000, 500.0);  // e.g. FvK
    data.row(2) *= 1e-3;
    const Standardisation s = Standardisation::fit(data);
    const Eigen::MatrixXd back = s.invert(s.apply(data));
    for (Eigen::Index i = 0; i < data.rows(); ++i)
        EXPECT_LT((back.row(i) - data.row(i)).cwiseAbs().maxCoeff(), 4e-16 * data.row(i).cwiseAbs().maxCoeff() + 1e-300);
}

TEST(Scaling, ConstantOrNonFiniteVariableIsAnInputErrorNamingIt) {
    Eigen::MatrixXd data = randomMatrix(2, 10, 1);
    data.row(1).setConstant(3.0);
    try {
        Standardisation::fit(data, {"v", "FvK"});
        FAIL() << "no exception";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("'FvK'"), std::string::npos) << e.what();
    }
    data(1, 3) = std::nan("");
    EXPECT_THROW(Standardisation::fit(data), InputError);
}

// ---------------------------------------------------------------------------------------------
// Training: split and determinism

TEST(Training, SplitRoundsTheTrainingSetUpToFullBatches) {
    TrainingOptions o;
    EXPECT_EQ(trainingRowCount(50000, 128), 40064);  // ceil(40000 / 128) = 313 batches
    EXPECT_EQ(trainingRowCount(50000, 256), 40192);  // ceil(156.25) = 157
    EXPECT_EQ(trainingRowCount(1280, 128), 1024);    // exact: no rounding up
    o.batchSize = 128;
    const DataSplit s = splitRows(50000, o);
    EXPECT_EQ(s.train.size(), 40064u);
    EXPECT_EQ(s.validation.size(), 50000u - 40064u);
    EXPECT_TRUE(s.test.empty());
    std::set<Eigen::Index> all(s.train.begin(), s.train.end());
    all.insert(s.validation.begin(), s.validation.end());
    EXPECT_EQ(all.size(), 50000u);  // a partition of the rows
    EXPECT_EQ(*all.rbegin(), 49999);
}

TEST(Training, SplitIsSeededAndIndependentOfThreadCount) {
    const ThreadCount restore;
    TrainingOptions o;
    omp_set_num_threads(1);
    const DataSplit a = splitRows(10007, o);
    omp_set_num_threads(2);
    const DataSplit b = splitRows(10007, o);
    EXPECT_EQ(a.train, b.train);
    EXPECT_EQ(a.validation, b.validation);
    o.splitSeed = 12346;
    EXPECT_NE(splitRows(10007, o).train, a.train);
    EXPECT_EQ(seededPermutation(20, 7), seededPermutation(20, 7));
}

TEST(Training, TestRowsAreHeldOutIndependentlyOfBatchSizeAndSplitSeed) {
    TrainingOptions o;
    o.testFraction = 0.1;
    const DataSplit a = splitRows(5000, o);
    EXPECT_EQ(a.test.size(), 500u);
    EXPECT_EQ(a.train.size(), trainingRowCount(4500, 128));
    EXPECT_EQ(a.train.size() + a.validation.size() + a.test.size(), 5000u);
    std::set<Eigen::Index> all(a.train.begin(), a.train.end());
    all.insert(a.validation.begin(), a.validation.end());
    all.insert(a.test.begin(), a.test.end());
    EXPECT_EQ(all.size(), 5000u);
    o.batchSize = 256;
    o.splitSeed = 99;
    const DataSplit b = splitRows(5000, o);
    EXPECT_EQ(a.test, b.test);  // same test rows for all three networks
    EXPECT_NE(a.train, b.train);
}

TEST(Training, SameSeedGivesBitIdenticalTrainingAndThreadCountDoesNotMatter) {
    const ThreadCount restore;
    Eigen::MatrixXd X, Y;
    smoothFunctionData(1500, 8, X, Y);
    TrainingOptions o;
    o.maxEpochs = 12;
    o.seed = 77;
    omp_set_num_threads(1);
    const TrainingResult a = trainNetwork(X, Y, o);
    const TrainingResult b = trainNetwork(X, Y, o);
    omp_set_num_threads(2);
    const TrainingResult c = trainNetwork(X, Y, o);
    // initial weights are Glorot(seed) (see Mlp test); the mini-batch order shows in the per-epoch
    // training losses and the final weights
    EXPECT_EQ(a.split.train, b.split.train);
    EXPECT_EQ(a.network.history.trainLoss.size(), 13u);
    for (const TrainingResult* r : {&b, &c}) {
        EXPECT_TRUE(r->network.net.parameters() == a.network.net.parameters());
        for (std::size_t e = 0; e + 1 < a.network.history.trainLoss.size(); ++e) {
            EXPECT_EQ(r->network.history.trainLoss[e], a.network.history.trainLoss[e]) << "epoch " << e;
            EXPECT_EQ(r->network.history.validationLoss[e], a.network.history.validationLoss[e]) << "epoch " << e;
        }
    }
    o.seed = 78;  // other initial weights and batch order, same split
    const TrainingResult d = trainNetwork(X, Y, o);
    EXPECT_EQ(d.split.train, a.split.train);
    EXPECT_NE(d.network.history.validationLoss[0], a.network.history.validationLoss[0]);
    EXPECT_FALSE(d.network.net.parameters() == a.network.net.parameters());
}

// ---------------------------------------------------------------------------------------------
// Training: schedule of 3.4 on a known function

/// Replays the rules of SURROGATE 3.4 on the recorded validation losses and checks the recorded
/// reductions, learning rates, restores and the stopping point against them.
void expectScheduleFollowsSpec(const TrainingHistory& h, const TrainingOptions& o) {
    const std::size_t n = h.validationLoss.size();
    ASSERT_EQ(h.trainLoss.size(), n);
    ASSERT_EQ(h.learningRate.size(), n);
    double best = std::numeric_limits<double>::infinity(), lr = o.learningRate;
    int counter = 0, bestEpoch = -1;
    std::vector<int> reductions;
    for (std::size_t e = 0; e < n; ++e) {
        const double v = h.validationLoss[e];
        if (v < best) {
            best = v;
            bestEpoch = static_cast<int>(e);
            counter = 0;
        } else {
            ++counter;
        }
        if (counter > o.patience && static_cast<int>(e) < o.maxEpochs) {
            counter = 0;
            lr *= o.reductionFactor;
            reductions.push_back(static_cast<int>(e));
            // the weights were restored: their validation loss is the best so far, bit for bit
            ASSERT_LE(reductions.size(), h.restoredValidationLoss.size());
            EXPECT_EQ(h.restoredValidationLoss[reductions.size() - 1], best) << "restore at epoch " << e;
        }
        EXPECT_EQ(h.learningRate[e], lr) << "epoch " << e;
        const bool last = e + 1 == n;
        EXPECT_EQ(std::isnan(h.trainLoss[e]), last) << "epoch " << e;
    }
    EXPECT_EQ(h.reductionEpochs, reductions);
    EXPECT_EQ(h.bestEpoch, bestEpoch);
    EXPECT_EQ(h.bestValidationLoss, best);
    if (!h.hitEpochCap) {
        EXPECT_EQ(static_cast<int>(reductions.size()), o.maxReductions);
    }
}

TEST(Training, LearnsSmoothFunctionWithTheFullSchedule) {
    // SURROGATE 5.1.5 at reduced size (10 000 samples instead of 50 000, to keep the suite fast;
    // the 50 000-sample run is bench/bench_surrogate's BM_TrainSmoothFunction50k)
    Eigen::MatrixXd X, Y;
    smoothFunctionData(10000, 2024, X, Y);
    TrainingOptions o;
    o.testFraction = 0.1;
    int reductionsLogged = 0;
    o.progress = [&](const EpochRecord& r) {
        if (r.reduced) {
            ++reductionsLogged;
            std::cout << "epoch " << r.epoch << ": validation loss " << r.validationLoss << ", best "
                      << r.bestValidationLoss << " restored, learning rate -> " << r.learningRate << "\n";
        }
    };
    const TrainingResult res = trainNetwork(X, Y, o, {"x1", "x2"}, {"g"});
    const TrainingHistory& h = res.network.history;
    EXPECT_FALSE(h.hitEpochCap);
    EXPECT_EQ(reductionsLogged, 5);
    expectScheduleFollowsSpec(h, o);
    // rates 0.1, 0.01, ..., 1e-5 trained; the final 1e-6 is never used
    EXPECT_DOUBLE_EQ(h.learningRate.front(), 0.1);
    EXPECT_NEAR(h.learningRate.back(), 1e-6, 1e-20);
    // epoch 0 takes no optimiser step: epoch 1 starts from the initial weights
    EXPECT_EQ(h.validationLoss[1], h.validationLoss[0]);
    EXPECT_FALSE(h.trainLoss[1] == h.trainLoss[0]);  // same weights, reshuffled batches

    // the returned weights are the best ones: their validation loss is the recorded best
    Eigen::MatrixXd Xv(2, res.split.validation.size()), Yv(1, res.split.validation.size());
    for (std::size_t k = 0; k < res.split.validation.size(); ++k) {
        Xv.col(k) = res.network.inputScaling.apply(X.col(res.split.validation[k]));
        Yv.col(k) = res.network.outputScaling.apply(Y.col(res.split.validation[k]));
    }
    EXPECT_EQ(res.network.net.loss(Xv, Yv), h.bestValidationLoss);

    // held-out RMSE in physical units below 1 % of the output range
    Eigen::MatrixXd Xt(2, res.split.test.size()), Yt(1, res.split.test.size());
    for (std::size_t k = 0; k < res.split.test.size(); ++k) {
        Xt.col(k) = X.col(res.split.test[k]);
        Yt.col(k) = Y.col(res.split.test[k]);
    }
    const double rmse = std::sqrt((res.network.evaluate(Xt) - Yt).squaredNorm() / static_cast<double>(Yt.size()));
    const double range = Y.maxCoeff() - Y.minCoeff();
    std::cout << "passes " << h.passes() << ", best epoch " << h.bestEpoch << ", test RMSE " << rmse << " = "
              << 100.0 * rmse / range << " % of the range\n";
    EXPECT_LT(rmse, 0.01 * range);
    EXPECT_NEAR(h.testLoss, (rmse / res.network.outputScaling.sd[0]) * (rmse / res.network.outputScaling.sd[0]),
                1e-9 * h.testLoss);
}

TEST(Training, EpochCapReturnsTheBestWeightsAndSaysSo) {
    Eigen::MatrixXd X, Y;
    smoothFunctionData(2000, 4, X, Y);
    TrainingOptions o;
    o.maxEpochs = 15;
    const TrainingResult res = trainNetwork(X, Y, o);
    const TrainingHistory& h = res.network.history;
    EXPECT_TRUE(h.hitEpochCap);
    EXPECT_EQ(h.passes(), 15);
    EXPECT_EQ(h.validationLoss.size(), 16u);  // + the check of the weights after the last pass
    expectScheduleFollowsSpec(h, o);
    EXPECT_EQ(h.bestValidationLoss, *std::min_element(h.validationLoss.begin(), h.validationLoss.end()));
    Eigen::MatrixXd Xv(2, res.split.validation.size()), Yv(1, res.split.validation.size());
    for (std::size_t k = 0; k < res.split.validation.size(); ++k) {
        Xv.col(k) = res.network.inputScaling.apply(X.col(res.split.validation[k]));
        Yv.col(k) = res.network.outputScaling.apply(Y.col(res.split.validation[k]));
    }
    EXPECT_EQ(res.network.net.loss(Xv, Yv), h.bestValidationLoss);
}

TEST(Training, RejectsInconsistentData) {
    Eigen::MatrixXd X = randomMatrix(2, 100, 1), Y = randomMatrix(1, 99, 2);
    EXPECT_THROW(trainNetwork(X, Y, TrainingOptions{}), InputError);
    Y = randomMatrix(1, 100, 2);
    TrainingOptions o;
    o.batchSize = 128;  // 100 rows: ceil(80/128) 128 > 100, no validation rows
    EXPECT_THROW(trainNetwork(X, Y, o), InputError);
    o.batchSize = 0;
    EXPECT_THROW(trainNetwork(X, Y, o), InputError);
}

// ---------------------------------------------------------------------------------------------
// NetworkIo

TrainedNetwork smallTrainedNetwork() {
    Eigen::MatrixXd X, Y(2, 1000), Y1;
    smoothFunctionData(1000, 31, X, Y1);
    Y.row(0) = Y1.row(0);
    Y.row(1) = X.row(0).array().square() * 100.0;
    TrainingOptions o;
    o.hiddenLayers = {8, 6};
    o.maxEpochs = 4;
    o.testFraction = 0.1;
    TrainedNetwork tn = trainNetwork(X, Y, o, {"x1", "x2"}, {"g", "h"}).network;
    tn.dataHash = "sha256:0123abcd";
    tn.command = "trbc surrogate train --data d.csv";
    return tn;
}

TEST(NetworkIo, SaveLoadRoundTripGivesIdenticalOutputs) {
    const TrainedNetwork a = smallTrainedNetwork();
    const std::string path = tempPath("roundtrip.json");
    saveNetwork(a, path);
    const TrainedNetwork b = loadNetwork(path);
    std::filesystem::remove(path);
    EXPECT_EQ(b.net.layerSizes(), a.net.layerSizes());
    EXPECT_TRUE(b.net.parameters() == a.net.parameters());
    EXPECT_TRUE(b.inputScaling.mean == a.inputScaling.mean && b.inputScaling.sd == a.inputScaling.sd);
    EXPECT_TRUE(b.outputScaling.mean == a.outputScaling.mean && b.outputScaling.sd == a.outputScaling.sd);
    EXPECT_EQ(b.inputNames, a.inputNames);
    EXPECT_EQ(b.outputNames, a.outputNames);
    EXPECT_EQ(b.dataHash, a.dataHash);
    EXPECT_EQ(b.command, a.command);
    EXPECT_EQ(b.options.splitSeed, a.options.splitSeed);
    EXPECT_EQ(b.options.batchSize, a.options.batchSize);
    EXPECT_EQ(b.options.hiddenLayers, a.options.hiddenLayers);
    EXPECT_EQ(b.history.validationLoss, a.history.validationLoss);
    EXPECT_EQ(b.history.reductionEpochs, a.history.reductionEpochs);
    EXPECT_EQ(b.history.bestEpoch, a.history.bestEpoch);
    EXPECT_EQ(b.history.testLoss, a.history.testLoss);
    ASSERT_EQ(b.history.trainLoss.size(), a.history.trainLoss.size());
    EXPECT_TRUE(std::isnan(b.history.trainLoss.back()));  // null in the file
    const Eigen::MatrixXd X = randomMatrix(2, 777, 5, 0.0, 1.0);
    EXPECT_TRUE(a.evaluate(X) == b.evaluate(X));  // bit-identical
}

/// Saves a good file, applies `edit` to its JSON, and returns the InputError message of loading it.
std::string loadErrorAfter(const std::function<void(nlohmann::json&)>& edit, const std::string& name) {
    nlohmann::json j = networkToJson(smallTrainedNetwork());
    edit(j);
    const std::string path = tempPath(name);
    {
        std::ofstream(path) << j.dump();
    }
    std::string message;
    try {
        loadNetwork(path);
    } catch (const InputError& e) {
        message = e.what();
    }
    std::filesystem::remove(path);
    EXPECT_NE(message.find(path), std::string::npos) << "message does not name the file: " << message;
    return message;
}

TEST(NetworkIo, CorruptedFileIsAnInputErrorNamingFileAndKey) {
    const auto contains = [](const std::string& s, const std::string& part) {
        return s.find(part) != std::string::npos;
    };
    std::string m = loadErrorAfter([](nlohmann::json& j) { j.erase("biases"); }, "missing.json");
    EXPECT_TRUE(contains(m, "'biases'") && contains(m, "missing")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["history"].erase("validation_loss"); }, "missing_nested.json");
    EXPECT_TRUE(contains(m, "'history.validation_loss'")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["weights"][1][2].erase(0); }, "short_row.json");
    EXPECT_TRUE(contains(m, "'weights[1][2]'") && contains(m, "expected 8")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["weights"][0].erase(0); }, "few_rows.json");
    EXPECT_TRUE(contains(m, "'weights[0]'") && contains(m, "expected 8")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["layer_sizes"][1] = 9; }, "sizes.json");
    EXPECT_TRUE(contains(m, "'weights[0]'")) << m;  // the weights no longer fit the sizes
    m = loadErrorAfter([](nlohmann::json& j) { j["output_mean"].push_back(1.0); }, "scaling_size.json");
    EXPECT_TRUE(contains(m, "'output_mean'")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["input_sd"][1] = 0.0; }, "sd.json");
    EXPECT_TRUE(contains(m, "'input_sd[1]'")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["biases"][2][0] = "x"; }, "type.json");
    EXPECT_TRUE(contains(m, "'biases[2][0]'") && contains(m, "number")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["input_names"] = {"x1"}; }, "names.json");
    EXPECT_TRUE(contains(m, "'input_names'")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["split_seed"] = -3; }, "seed.json");
    EXPECT_TRUE(contains(m, "'split_seed'")) << m;
    m = loadErrorAfter([](nlohmann::json& j) { j["training"]["batch_size"] = 0; }, "batch.json");
    EXPECT_TRUE(contains(m, "'training.batch_size'")) << m;

    const std::string bad = tempPath("not_json.json");
    std::ofstream(bad) << "{ \"format\": ";
    try {
        loadNetwork(bad);
        ADD_FAILURE() << "no exception";
    } catch (const InputError& e) {
        EXPECT_TRUE(contains(e.what(), bad)) << e.what();
    }
    std::filesystem::remove(bad);
    EXPECT_THROW(loadNetwork(tempPath("does_not_exist.json")), InputError);
}


// ---------------------------------------------------------------------------------------------
// Log-transformed variables

/// y = 0.3 x1^1.5 / x2 on [0.1, 10]^2: a power law over two decades, linear in log space.
void powerLawData(int n, std::uint64_t seed, Eigen::MatrixXd& X, Eigen::MatrixXd& Y) {
    X = randomMatrix(2, n, seed, std::log(0.1), std::log(10.0)).array().exp().matrix();
    Y = (0.3 * X.row(0).array().pow(1.5) / X.row(1).array()).matrix();
}

double relativeRmse(const Eigen::MatrixXd& predicted, const Eigen::MatrixXd& truth) {
    return std::sqrt((predicted.array() / truth.array() - 1.0).square().mean());
}

TEST(Training, LogVariablesAreAppliedInsideEvaluateAndLearnAPowerLaw) {
    Eigen::MatrixXd X, Y, Xt, Yt;
    powerLawData(2000, 41, X, Y);
    powerLawData(500, 42, Xt, Yt);
    TrainingOptions o;
    o.hiddenLayers = {8};
    o.maxEpochs = 1000;
    const TrainingResult plain = trainNetwork(X, Y, o, {"a", "b"}, {"y"});
    o.inputTransforms = {VariableTransform::Log, VariableTransform::Log};
    o.outputTransforms = {VariableTransform::Log};
    const TrainingResult logged = trainNetwork(X, Y, o, {"a", "b"}, {"y"});
    const TrainedNetwork& tn = logged.network;
    EXPECT_EQ(tn.inputTransforms, o.inputTransforms);
    EXPECT_EQ(tn.outputTransforms, o.outputTransforms);
    // evaluate = exp(s_y NN((log x - m_x) / s_x) + m_y) (to round-off: Eigen's vectorised log/exp)
    Eigen::MatrixXd manual = tn.net.forward(tn.inputScaling.apply(Xt.array().log().matrix()));
    tn.outputScaling.invertInPlace(manual);
    EXPECT_TRUE(tn.evaluate(Xt).isApprox(manual.array().exp().matrix(), 1e-13));
    // the scaling is of the log variables: mean of log x over the data
    EXPECT_NEAR(tn.inputScaling.mean[0], X.row(0).array().log().mean(), 1e-12);
    // In log space the power law is linear: measured relative RMSE 2.4 % with logs (8 tanh units,
    // the default schedule) against 1000 % on the raw variables, where y spans 4 decades and the
    // small values get no weight in the MSE.
    const double eLog = relativeRmse(tn.evaluate(Xt), Yt), ePlain = relativeRmse(plain.network.evaluate(Xt), Yt);
    std::cout << "relative RMSE: log variables " << eLog << ", raw variables " << ePlain << "\n";
    EXPECT_LT(eLog, 0.05);
    EXPECT_GT(ePlain, 10.0 * eLog);

    // a non-positive value of a log variable is an InputError naming it
    Eigen::MatrixXd Xbad = X;
    Xbad(1, 17) = 0.0;
    try {
        trainNetwork(Xbad, Y, o, {"a", "b"}, {"y"});
        ADD_FAILURE() << "trained log(b) with b = 0";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("'b'"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("sample 17"), std::string::npos) << e.what();
    }
    o.inputTransforms = {VariableTransform::Log};  // one transform for two inputs
    EXPECT_THROW(trainNetwork(X, Y, o), InputError);
}

TEST(NetworkIo, TransformsRoundTripAndOlderFilesMeanIdentity) {
    Eigen::MatrixXd X, Y;
    powerLawData(400, 43, X, Y);
    TrainingOptions o;
    o.hiddenLayers = {4};
    o.maxEpochs = 3;
    o.inputTransforms = {VariableTransform::Sqrt, VariableTransform::Log};
    o.outputTransforms = {VariableTransform::Log};
    const TrainedNetwork a = trainNetwork(X, Y, o, {"a", "b"}, {"y"}).network;
    const std::string path = tempPath("transforms.json");
    saveNetwork(a, path);
    const TrainedNetwork b = loadNetwork(path);
    EXPECT_EQ(b.inputTransforms, a.inputTransforms);
    EXPECT_EQ(b.outputTransforms, a.outputTransforms);
    EXPECT_TRUE(b.evaluate(X) == a.evaluate(X));
    // a file written before the transforms existed has no keys: identity
    nlohmann::json j = networkToJson(a);
    EXPECT_EQ(j["input_transform"], nlohmann::json({"sqrt", "log"}));
    j.erase("input_transform");
    j.erase("output_transform");
    std::ofstream(path) << j.dump();
    const TrainedNetwork c = loadNetwork(path);
    EXPECT_TRUE(c.inputTransforms.empty() && c.outputTransforms.empty());
    Eigen::MatrixXd raw = c.net.forward(c.inputScaling.apply(X));
    c.outputScaling.invertInPlace(raw);
    EXPECT_TRUE(c.evaluate(X) == raw);
    std::filesystem::remove(path);
    const std::string m = loadErrorAfter([](nlohmann::json& j) { j["input_transform"] = {"cbrt", "log"}; }, "bad_transform.json");
    EXPECT_NE(m.find("'input_transform'"), std::string::npos) << m;
    EXPECT_NE(m.find("cbrt"), std::string::npos) << m;
}

TEST(Training, SqrtVariablesAreAppliedInsideEvaluate) {
    Eigen::MatrixXd X, Y;
    powerLawData(400, 44, X, Y);
    TrainingOptions o;
    o.hiddenLayers = {4};
    o.maxEpochs = 3;
    o.inputTransforms = {VariableTransform::Sqrt, VariableTransform::Identity};
    o.outputTransforms = {VariableTransform::Sqrt};
    const TrainedNetwork tn = trainNetwork(X, Y, o, {"a", "b"}, {"y"}).network;
    // evaluate = (s_y NN((T x - m_x) / s_x) + m_y)^2 with T = (sqrt, identity)
    Eigen::MatrixXd Tx = X;
    Tx.row(0) = X.row(0).array().sqrt().matrix();
    Eigen::MatrixXd manual = tn.net.forward(tn.inputScaling.apply(Tx));
    tn.outputScaling.invertInPlace(manual);
    EXPECT_TRUE(tn.evaluate(X).isApprox(manual.array().max(0.0).square().matrix(), 1e-13));
    EXPECT_NEAR(tn.inputScaling.mean[0], X.row(0).array().sqrt().mean(), 1e-12);
    EXPECT_NEAR(tn.outputScaling.mean[0], Y.row(0).array().sqrt().mean(), 1e-12);
    // zero is allowed, a negative value is an InputError naming the variable and the sample
    Eigen::MatrixXd X0 = X;
    X0(0, 3) = 0.0;
    EXPECT_NO_THROW(trainNetwork(X0, Y, o, {"a", "b"}, {"y"}));
    X0(0, 5) = -1e-3;
    try {
        trainNetwork(X0, Y, o, {"a", "b"}, {"y"});
        ADD_FAILURE() << "trained sqrt(a) with a < 0";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("sqrt(a)"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("sample 5"), std::string::npos) << e.what();
    }
}


TEST(NetworkEnsemble, PredictsTheMeanOfItsMembersInTheTransformedSpace) {
    Eigen::MatrixXd X, Y, Xt, Yt;
    powerLawData(600, 44, X, Y);
    powerLawData(300, 45, Xt, Yt);
    TrainingOptions o;
    o.hiddenLayers = {6};
    o.maxEpochs = 40;  // short trainings: members that differ
    o.inputTransforms = {VariableTransform::Log, VariableTransform::Log};
    o.outputTransforms = {VariableTransform::Log};
    std::vector<TrainedNetwork> singles;
    for (std::uint64_t seed = 1; seed <= 4; ++seed) {
        o.seed = seed;
        singles.push_back(trainNetwork(X, Y, o, {"a", "b"}, {"y"}).network);
    }
    TrainedNetwork ens = singles[0];
    for (std::size_t k = 1; k < singles.size(); ++k)
        ens.ensemble.push_back({singles[k].net, singles[k].options.seed, singles[k].history.bestValidationLoss});
    // log output: the geometric mean of the members' predictions
    Eigen::ArrayXXd logMean = Eigen::ArrayXXd::Zero(1, Xt.cols());
    for (const TrainedNetwork& s : singles) logMean += s.evaluate(Xt).array().log();
    logMean /= double(singles.size());
    const Eigen::MatrixXd pe = ens.evaluate(Xt);
    EXPECT_TRUE(pe.isApprox(logMean.exp().matrix(), 1e-12));
    EXPECT_FALSE(pe.isApprox(singles[0].evaluate(Xt), 1e-6));  // the members do differ
    const auto logMse = [&](const Eigen::MatrixXd& p) { return (p.array().log() - Yt.array().log()).square().mean(); };
    double memberMean = 0;
    for (const TrainedNetwork& s : singles) memberMean += logMse(s.evaluate(Xt)) / double(singles.size());
    std::cout << "log-space MSE: ensemble " << logMse(pe) << ", members' mean " << memberMean << "\n";
    // identity output: the arithmetic mean
    TrainedNetwork lin = ens;
    lin.outputTransforms.clear();
    Eigen::MatrixXd mean = Eigen::MatrixXd::Zero(1, Xt.cols());
    for (const TrainedNetwork& s : singles) {
        TrainedNetwork t = s;
        t.outputTransforms.clear();
        mean += t.evaluate(Xt) / double(singles.size());
    }
    EXPECT_TRUE(lin.evaluate(Xt).isApprox(mean, 1e-12));

    // the members travel with the file and give bit-identical outputs
    const std::string path = tempPath("ensemble.json");
    saveNetwork(ens, path);
    const TrainedNetwork back = loadNetwork(path);
    ASSERT_EQ(back.ensemble.size(), 3u);
    EXPECT_EQ(back.ensemble[1].seed, 3u);
    EXPECT_EQ(back.ensemble[1].bestValidationLoss, singles[2].history.bestValidationLoss);
    EXPECT_TRUE(back.evaluate(Xt) == pe);
    std::filesystem::remove(path);
    // format version 2, so that a reader of version 1 rejects the file instead of using one member
    EXPECT_EQ(networkToJson(ens)["version"], 2);
    EXPECT_EQ(networkToJson(singles[0])["version"], 1);
    std::string m = loadErrorAfter(
        [&](nlohmann::json& j) {
            j = networkToJson(ens);
            j["ensemble"][1]["biases"][0].erase(0);
        },
        "bad_ensemble.json");
    EXPECT_NE(m.find("'ensemble[1].biases[0]'"), std::string::npos) << m;
    m = loadErrorAfter(
        [&](nlohmann::json& j) {
            j = networkToJson(ens);
            j["version"] = 1;
        },
        "ensemble_v1.json");
    EXPECT_NE(m.find("'ensemble'"), std::string::npos) << m;
    // members must have the network's layer sizes (the file stores one set)
    TrainedNetwork odd = ens;
    odd.ensemble[0].net = Mlp::glorotUniform({2, 7, 1}, 3);
    EXPECT_THROW(networkToJson(odd), std::invalid_argument);
}

}  // namespace
}  // namespace trbc
