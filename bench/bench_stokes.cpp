// Boundary-integral Stokes operators (src/flow/boundary_integral.hpp) on the unit icosphere:
// one matrix-free application of the single layer and of the double layer (the inner loop of
// GMRES), the set-up (quadrature points and near-field corrections; once per geometry) and the
// dense assembly of both operators (once per time step of a level-3 flow run).
// Arguments: icosphere level, OpenMP threads.
#include <benchmark/benchmark.h>
#include <omp.h>

#include "flow/boundary_integral.hpp"
#include "mesh/icosphere.hpp"

namespace {

void BM_SingleLayerApply(benchmark::State& state) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    const trbc::BoundaryIntegralOperators ops(trbc::icosphere(static_cast<int>(state.range(0))));
    const Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Random(3, ops.numVertices());
    for (auto _ : state) {
        Eigen::Matrix3Xd u = ops.singleLayer(f);
        benchmark::DoNotOptimize(u.data());
        benchmark::ClobberMemory();
    }
    state.counters["Nv"] = static_cast<double>(ops.numVertices());
    state.counters["pairs/s"] = benchmark::Counter(
        static_cast<double>(ops.numVertices()) * static_cast<double>(ops.numQuadraturePoints()),
        benchmark::Counter::kIsIterationInvariantRate);
}

void BM_DoubleLayerApply(benchmark::State& state) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    const trbc::BoundaryIntegralOperators ops(trbc::icosphere(static_cast<int>(state.range(0))));
    const Eigen::Matrix3Xd u = Eigen::Matrix3Xd::Random(3, ops.numVertices());
    for (auto _ : state) {
        Eigen::Matrix3Xd v = ops.doubleLayer(u);
        benchmark::DoNotOptimize(v.data());
        benchmark::ClobberMemory();
    }
    state.counters["Nv"] = static_cast<double>(ops.numVertices());
    state.counters["pairs/s"] = benchmark::Counter(
        static_cast<double>(ops.numVertices()) * static_cast<double>(ops.numQuadraturePoints()),
        benchmark::Counter::kIsIterationInvariantRate);
}

void BM_OperatorSetup(benchmark::State& state) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    const trbc::Mesh mesh = trbc::icosphere(static_cast<int>(state.range(0)));
    for (auto _ : state) {
        const trbc::BoundaryIntegralOperators ops(mesh);
        benchmark::DoNotOptimize(&ops);
    }
    state.counters["Nv"] = static_cast<double>(mesh.numVertices());
}

void BM_AssembleSingleLayer(benchmark::State& state) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    const trbc::BoundaryIntegralOperators ops(trbc::icosphere(static_cast<int>(state.range(0))));
    for (auto _ : state) {
        Eigen::MatrixXd A = ops.assembleSingleLayer();
        benchmark::DoNotOptimize(A.data());
    }
    state.counters["Nv"] = static_cast<double>(ops.numVertices());
}

void BM_AssembleDoubleLayer(benchmark::State& state) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    const trbc::BoundaryIntegralOperators ops(trbc::icosphere(static_cast<int>(state.range(0))));
    for (auto _ : state) {
        Eigen::MatrixXd A = ops.assembleDoubleLayer();
        benchmark::DoNotOptimize(A.data());
    }
    state.counters["Nv"] = static_cast<double>(ops.numVertices());
}

}  // namespace

BENCHMARK(BM_AssembleSingleLayer)
    ->ArgsProduct({{2, 3}, {1}})
    ->ArgNames({"level", "threads"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AssembleDoubleLayer)
    ->ArgsProduct({{2, 3}, {1}})
    ->ArgNames({"level", "threads"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SingleLayerApply)
    ->ArgsProduct({{2, 3, 4}, {1, 2}})
    ->ArgNames({"level", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_DoubleLayerApply)
    ->ArgsProduct({{2, 3, 4}, {1, 2}})
    ->ArgNames({"level", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_OperatorSetup)
    ->ArgsProduct({{2, 3, 4}, {1, 2}})
    ->ArgNames({"level", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
