// Energy + forces of the full membrane model (Juelicher bending + Lim + area + volume), the
// inner loop of every experiment. Arguments: icosphere level, OpenMP threads.
#include <benchmark/benchmark.h>
#include <omp.h>

#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"

namespace {

void BM_FullModelEnergyForces(benchmark::State& state) {
    const int level = static_cast<int>(state.range(0));
    omp_set_num_threads(static_cast<int>(state.range(1)));
    using namespace trbc;
    const Mesh sphere = icosphere(level);
    // Stress-free sphere of area 135 um^2; current shape = Evans-Fung cell (um, pN).
    const Vertices ref = scaleToArea(sphere.X, sphere.F, 135.0);
    const Vertices X = scaleToArea(evansFungMap(sphere.X), sphere.F, 135.0);
    MembraneParameters p;
    p.bending.kb = 0.0429;  // mu R_A^2 / FvK at mu = 4, FvK = 1000 (pN um)
    p.lim = {4.0, -2.0, 8.0, 4.0, 0.7, 1.5};
    p.penalty = {5e5, 135.0, 7.23e5, 94.0};
    const MembraneModel model(sphere.F, sphere.numVertices(), p, &ref);
    Vertices grad(3, X.cols());
    for (auto _ : state) {
        benchmark::DoNotOptimize(model.evaluate(X, &grad));
        benchmark::ClobberMemory();
    }
    state.counters["Nv"] = static_cast<double>(X.cols());
    state.counters["threads"] = static_cast<double>(state.range(1));
}

}  // namespace

BENCHMARK(BM_FullModelEnergyForces)
    ->ArgsProduct({{3, 4, 5}, {1, 2}})
    ->ArgNames({"level", "threads"})
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

BENCHMARK_MAIN();
