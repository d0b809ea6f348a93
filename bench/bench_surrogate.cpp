// Surrogate networks (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training): batched evaluation throughput of the 3 x 32 network,
// the tanh kernel, one training epoch at the paper's data size, and the complete training schedule
// of 3.4 on the known function of 5.1.5 with 50 000 samples (reports the held-out RMSE).
//
// Times are CPU time of the calling thread unless a benchmark says UseRealTime (the threaded
// evaluation); on a shared machine CPU time is the meaningful per-core figure.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cstdlib>
#include <ctime>
#include <cmath>
#include <numbers>
#include <random>

#include "experiments/parameters.hpp"
#include "surrogate/mlp.hpp"
#include "surrogate/surrogate.hpp"
#include "surrogate/training.hpp"

namespace {

using namespace trbc;

double threadCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

Eigen::MatrixXd uniformMatrix(Eigen::Index rows, Eigen::Index cols, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    Eigen::MatrixXd A(rows, cols);
    for (Eigen::Index k = 0; k < A.size(); ++k) A.data()[k] = static_cast<double>(rng() >> 11) * 0x1.0p-53;
    return A;
}

// Mlp::forward of a 5 -> 32 -> 32 -> 32 -> 1 network on standardised-like inputs.
// Arguments: batch columns, OpenMP threads, precision (0 double, 1 single).
// items/s = network evaluations per second.
void BM_MlpForward(benchmark::State& state) {
    const Eigen::Index n = state.range(0);
    const int threads = static_cast<int>(state.range(1));
    const Precision precision = state.range(2) == 0 ? Precision::Double : Precision::Single;
    const int saved = omp_get_max_threads();
    omp_set_num_threads(threads);
    const Mlp net = Mlp::glorotUniform({5, 32, 32, 32, 1}, 1);
    const Eigen::MatrixXd X = (uniformMatrix(5, n, 2).array() * 3.4 - 1.7).matrix();  // ~ z-scores
    Eigen::MatrixXd Y(1, n);
    for (auto _ : state) {
        net.forward(X, Y, precision);
        benchmark::DoNotOptimize(Y.data());
        benchmark::ClobberMemory();
    }
    omp_set_num_threads(saved);
    state.SetItemsProcessed(state.iterations() * n);
    state.counters["threads"] = threads;
}

// The shipped model (data/surrogates, or $TRBC_SURROGATE_DIR) as the inference calls it:
// Surrogate::evaluate of all six outputs (argument 1 = 0), or the relaxation time alone (1),
// for n samples uniform in the prior box, one thread; n = 16 is a batch of the joint MCMC (one
// column per chain). items/s = samples per second. The shipped relaxation network is distilled
// from an ensemble of 8, so a tc costs one network pass.
void BM_ShippedSurrogate(benchmark::State& state) {
    const char* env = std::getenv("TRBC_SURROGATE_DIR");
    Surrogate model;
    try {
        model = Surrogate::load(env ? env : TRBC_BENCH_SURROGATE_DIR);
    } catch (const std::exception& e) {
        state.SkipWithError(e.what());
        return;
    }
    model.precision = state.range(2) == 0 ? Precision::Double : Precision::Single;
    const Eigen::Index n = state.range(0);
    const int saved = omp_get_max_threads();
    omp_set_num_threads(1);
    const PriorRange box[6] = {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam, kPriorFext};
    Eigen::MatrixXd X = uniformMatrix(6, n, 5);
    for (int k = 0; k < 6; ++k) X.row(k) = (box[k].lo + (box[k].hi - box[k].lo) * X.row(k).array()).matrix();
    const bool tcOnly = state.range(1) == 1;
    for (auto _ : state) {
        if (tcOnly) {
            const Eigen::VectorXd tc = model.relaxationTime(X.topRows(5));
            benchmark::DoNotOptimize(tc.data());
        } else {
            const Eigen::MatrixXd Y = model.evaluate(X);
            benchmark::DoNotOptimize(Y.data());
        }
        benchmark::ClobberMemory();
    }
    omp_set_num_threads(saved);
    state.SetItemsProcessed(state.iterations() * n);
    state.counters["relaxation_members"] = double(1 + model.relaxation.ensemble.size());
}

// The vectorised tanh alone; items/s = tanh evaluations per second.
void BM_TanhInPlace(benchmark::State& state) {
    Eigen::VectorXd x = (uniformMatrix(96 * 1024, 1, 3).array() * 6.0 - 3.0).matrix();
    const Eigen::VectorXd x0 = x;
    for (auto _ : state) {
        tanhInPlace(x.data(), x.size());
        benchmark::DoNotOptimize(x.data());
        state.PauseTiming();
        x = x0;
        state.ResumeTiming();
    }
    state.SetItemsProcessed(state.iterations() * x.size());
}

// One epoch of 3.4 at the paper's size: 50 000 rows of (5 inputs, 2 outputs), batch 128 ->
// 40 064 training rows (313 mini-batches with gradient and Adam step) + validation of 9 936 rows.
// Measured as trainMlp with maxEpochs = 4 (4 passes, the first without optimiser steps, and 5
// validations), reported per epoch.
void BM_TrainingEpoch50k(benchmark::State& state) {
    const int n = 50000;
    const Eigen::MatrixXd X = uniformMatrix(5, n, 4);
    Eigen::MatrixXd Y(2, n);
    Y.row(0) = (X.row(0).array() * 3.0).sin() * X.row(1).array().exp() + X.row(2).array() * X.row(3).array();
    Y.row(1) = X.row(4).array().square() - X.row(0).array();
    const Standardisation sx = Standardisation::fit(X), sy = Standardisation::fit(Y);
    const Eigen::MatrixXd Xs = sx.apply(X), Ys = sy.apply(Y);
    TrainingOptions o;
    o.maxEpochs = 4;
    const Eigen::Index nTrain = trainingRowCount(n, o.batchSize);
    double cpuSeconds = 0.0;
    for (auto _ : state) {
        const double t0 = threadCpuSeconds();
        Mlp net = Mlp::glorotUniform({5, 32, 32, 32, 2}, 7);
        const TrainingHistory h = trainMlp(net, Xs.leftCols(nTrain), Ys.leftCols(nTrain), Xs.rightCols(n - nTrain),
                                           Ys.rightCols(n - nTrain), o);
        benchmark::DoNotOptimize(h.bestValidationLoss);
        cpuSeconds += threadCpuSeconds() - t0;
    }
    state.counters["ms_per_epoch"] = 1e3 * cpuSeconds / (static_cast<double>(state.iterations()) * o.maxEpochs);
    state.counters["train_rows"] = static_cast<double>(nTrain);
}

// SURROGATE 5.1.5 at full size: g(x1, x2) = sin(pi x1) exp(x2), 50 000 uniform samples on [0, 1]^2,
// 10 % held-out test rows, batch 128, the whole schedule of 3.4. One iteration; counters give the
// number of passes, the wall time and the test RMSE as a percentage of the output range.
void BM_TrainSmoothFunction50k(benchmark::State& state) {
    const int n = 50000;
    const Eigen::MatrixXd X = uniformMatrix(2, n, 2024);
    Eigen::MatrixXd Y(1, n);
    for (int i = 0; i < n; ++i) Y(0, i) = std::sin(std::numbers::pi * X(0, i)) * std::exp(X(1, i));
    TrainingOptions o;
    o.testFraction = 0.1;
    for (auto _ : state) {
        const TrainingResult r = trainNetwork(X, Y, o, {"x1", "x2"}, {"g"});
        Eigen::MatrixXd Xt(2, r.split.test.size()), Yt(1, r.split.test.size());
        for (std::size_t k = 0; k < r.split.test.size(); ++k) {
            Xt.col(k) = X.col(r.split.test[k]);
            Yt.col(k) = Y.col(r.split.test[k]);
        }
        const double rmse = std::sqrt((r.network.evaluate(Xt) - Yt).squaredNorm() / static_cast<double>(Yt.size()));
        state.counters["passes"] = r.network.history.passes();
        state.counters["hit_cap"] = r.network.history.hitEpochCap;
        state.counters["test_rmse_pct_of_range"] = 100.0 * rmse / (Y.maxCoeff() - Y.minCoeff());
    }
}

}  // namespace

BENCHMARK(BM_MlpForward)
    ->ArgsProduct({{256, 4096, 65536, 1 << 20}, {1}, {0, 1}})
    ->ArgNames({"n", "threads", "single"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MlpForward)
    ->ArgsProduct({{1 << 20}, {2}, {0, 1}})
    ->ArgNames({"n", "threads", "single"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ShippedSurrogate)
    ->ArgsProduct({{16, 65536}, {0, 1}, {0, 1}})
    ->ArgNames({"n", "tc_only", "single"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TanhInPlace)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_TrainingEpoch50k)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_TrainSmoothFunction50k)->Unit(benchmark::kSecond)->Iterations(1);

BENCHMARK_MAIN();
