// Boundary-integral Stokes operators (src/flow/boundary_integral.hpp) on the unit icosphere:
// one matrix-free application of the single layer, of the double layer and of both fused (the
// inner loop of GMRES in a flow step), the set-up (quadrature points and near-field corrections;
// once per geometry, i.e. per time step) and the dense assembly of both operators.
// Arguments: icosphere level, OpenMP threads, far rule (0 = corners and centroids, the default;
// 1 = the 3-point face rule); the fused pass also the far sum's precision (0 = double, 1 = single,
// as the flow steps use it).
#include <benchmark/benchmark.h>
#include <omp.h>

#include "flow/boundary_integral.hpp"
#include "mesh/icosphere.hpp"

namespace {

trbc::BoundaryIntegralOperators makeOperators(const benchmark::State& state, bool single = false) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    trbc::QuadratureOptions q;
    q.farRule = state.range(2) == 0 ? trbc::FarRule::VerticesAndCentroids : trbc::FarRule::FacePoints;
    q.singlePrecisionFar = single;
    return trbc::BoundaryIntegralOperators(trbc::icosphere(static_cast<int>(state.range(0))), q);
}

void setCounters(benchmark::State& state, const trbc::BoundaryIntegralOperators& ops) {
    state.counters["Nv"] = static_cast<double>(ops.numVertices());
    state.counters["points"] = static_cast<double>(ops.numQuadraturePoints());
    state.counters["pairs/s"] = benchmark::Counter(
        static_cast<double>(ops.numVertices()) * static_cast<double>(ops.numQuadraturePoints()),
        benchmark::Counter::kIsIterationInvariantRate);
}

void BM_SingleLayerApply(benchmark::State& state) {
    const trbc::BoundaryIntegralOperators ops = makeOperators(state);
    const Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Random(3, ops.numVertices());
    for (auto _ : state) {
        Eigen::Matrix3Xd u = ops.singleLayer(f);
        benchmark::DoNotOptimize(u.data());
        benchmark::ClobberMemory();
    }
    setCounters(state, ops);
}

void BM_DoubleLayerApply(benchmark::State& state) {
    const trbc::BoundaryIntegralOperators ops = makeOperators(state);
    const Eigen::Matrix3Xd u = Eigen::Matrix3Xd::Random(3, ops.numVertices());
    for (auto _ : state) {
        Eigen::Matrix3Xd v = ops.doubleLayer(u);
        benchmark::DoNotOptimize(v.data());
        benchmark::ClobberMemory();
    }
    setCounters(state, ops);
}

void BM_LayersApply(benchmark::State& state) {
    const trbc::BoundaryIntegralOperators ops = makeOperators(state, state.range(3) == 1);
    const Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Random(3, ops.numVertices());
    const Eigen::Matrix3Xd u = Eigen::Matrix3Xd::Random(3, ops.numVertices());
    Eigen::Matrix3Xd Sf, Du;
    for (auto _ : state) {
        ops.layers(f, u, Sf, Du);
        benchmark::DoNotOptimize(Sf.data());
        benchmark::DoNotOptimize(Du.data());
        benchmark::ClobberMemory();
    }
    setCounters(state, ops);
}

void BM_OperatorSetup(benchmark::State& state) {
    omp_set_num_threads(static_cast<int>(state.range(1)));
    const trbc::Mesh mesh = trbc::icosphere(static_cast<int>(state.range(0)));
    trbc::QuadratureOptions q;
    q.farRule = state.range(2) == 0 ? trbc::FarRule::VerticesAndCentroids : trbc::FarRule::FacePoints;
    for (auto _ : state) {
        const trbc::BoundaryIntegralOperators ops(mesh, q);
        benchmark::DoNotOptimize(&ops);
    }
    state.counters["Nv"] = static_cast<double>(mesh.numVertices());
}

void BM_AssembleSingleLayer(benchmark::State& state) {
    const trbc::BoundaryIntegralOperators ops = makeOperators(state);
    for (auto _ : state) {
        trbc::SymmetricBlockMatrix A = ops.assembleSingleLayerBlocks();
        benchmark::DoNotOptimize(A.row(0));
    }
    setCounters(state, ops);
}

void BM_AssembleDoubleLayer(benchmark::State& state) {
    const trbc::BoundaryIntegralOperators ops = makeOperators(state);
    for (auto _ : state) {
        trbc::SymmetricBlockMatrix A = ops.assembleDoubleLayerBlocks();
        benchmark::DoNotOptimize(A.row(0));
    }
    setCounters(state, ops);
}

}  // namespace

BENCHMARK(BM_AssembleSingleLayer)
    ->ArgsProduct({{2, 3}, {1}, {0, 1}})
    ->ArgNames({"level", "threads", "rule"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AssembleDoubleLayer)
    ->ArgsProduct({{2, 3}, {1}, {0, 1}})
    ->ArgNames({"level", "threads", "rule"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SingleLayerApply)
    ->ArgsProduct({{2, 3, 4}, {1, 2}, {0, 1}})
    ->ArgNames({"level", "threads", "rule"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_DoubleLayerApply)
    ->ArgsProduct({{2, 3, 4}, {1, 2}, {0, 1}})
    ->ArgNames({"level", "threads", "rule"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_LayersApply)
    ->ArgsProduct({{2, 3, 4}, {1, 2}, {0, 1}, {0, 1}})
    ->ArgNames({"level", "threads", "rule", "single"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_OperatorSetup)
    ->ArgsProduct({{2, 3, 4}, {1, 2}, {0, 1}})
    ->ArgNames({"level", "threads", "rule"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
