// The pieces of one implicit relaxation step's L-BFGS iteration beside the force evaluation
// (bench_forces): the multigrid H0 (one V-cycle),
// the edge-dashpot force of the membrane viscosity (edge directions computed per call, or once
// per step) and the area/volume constraint Jacobian.
// Argument: icosphere level.
#include <benchmark/benchmark.h>

#include <random>

#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/topology.hpp"
#include "solvers/multigrid.hpp"

namespace {

using namespace trbc;

Vertices randomField(Eigen::Index n) {
    std::mt19937 rng(7);
    std::normal_distribution<double> g;
    Vertices X(3, n);
    for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = g(rng);
    return X;
}

// Reference cell at level 4 in pN/um: a0 = 2 mu A_v / (0.5 um)^2, a1 = mu, a2 = kb / l0^2.
constexpr StiffnessModel kStiffness{1.7, 4.0, 2.8};

void BM_MultigridVCycle(benchmark::State& state) {
    const Mesh m = icosphere(static_cast<int>(state.range(0)));
    auto mg = IcosphereMultigrid::build(m.F, kStiffness);
    const Vertices b = randomField(m.numVertices());
    const Eigen::VectorXd b0 = Eigen::Map<const Eigen::VectorXd>(b.data(), b.size());
    Eigen::VectorXd v;
    for (auto _ : state) {
        v = b0;  // a fresh right-hand side (B v shrinks v: repeated, it would reach denormals)
        mg->apply(v);
        benchmark::DoNotOptimize(v.data());
    }
    state.counters["Nv"] = static_cast<double>(m.numVertices());
}

void BM_MembraneViscousForce(benchmark::State& state) {
    const Mesh m = icosphere(static_cast<int>(state.range(0)));
    const Topology topo = buildTopology(m.F, m.numVertices());
    const Vertices V = randomField(m.numVertices());
    for (auto _ : state) benchmark::DoNotOptimize(membraneViscousForce(m.X, V, 1.6, topo));
    state.counters["Nv"] = static_cast<double>(m.numVertices());
}

// The same with the edge directions computed once (as in an implicit step's solve).
void BM_MembraneViscousForceAlongFixedEdges(benchmark::State& state) {
    const Mesh m = icosphere(static_cast<int>(state.range(0)));
    const Topology topo = buildTopology(m.F, m.numVertices());
    const Vertices V = randomField(m.numVertices());
    const Eigen::Matrix3Xd edges = unitEdgeVectors(m.X, topo);
    for (auto _ : state) benchmark::DoNotOptimize(membraneViscousForceAlong(edges, V, 1.6, topo));
    state.counters["Nv"] = static_cast<double>(m.numVertices());
}

void BM_AreaVolumeWithGradients(benchmark::State& state) {
    const Mesh m = icosphere(static_cast<int>(state.range(0)));
    for (auto _ : state) benchmark::DoNotOptimize(areaVolumeWithGradients(m.X, m.F));
    state.counters["Nv"] = static_cast<double>(m.numVertices());
}

}  // namespace

BENCHMARK(BM_MultigridVCycle)->Arg(3)->Arg(4)->ArgName("level")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MembraneViscousForce)->Arg(3)->Arg(4)->ArgName("level")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MembraneViscousForceAlongFixedEdges)->Arg(3)->Arg(4)->ArgName("level")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_AreaVolumeWithGradients)->Arg(3)->Arg(4)->ArgName("level")->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
