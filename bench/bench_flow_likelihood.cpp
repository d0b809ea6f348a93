// The flow data's likelihood (inference/flow_likelihood.hpp) through the shipped flow networks, as
// the joint MCMC calls it: one batch of 16 cells (one candidate per chain) per call, for each
// flow data set of `trbc infer --datasets all`. items/s = cells per second. Second argument: the
// networks, 0 the 16-member ensembles (data/surrogates/flow), 1 the distilled ones that `trbc
// infer` uses (data/surrogates/flow_distilled), side by side in one run.
#include <benchmark/benchmark.h>

#include <memory>

#include "analysis/flow_data_sets.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace {

using namespace trbc;

struct Shipped {
    std::shared_ptr<const FlowSurrogate> networks;
    FlowModel model;
    std::vector<FlowDataSet> sets;
    explicit Shipped(const char* name) {
        const std::filesystem::path dir = std::filesystem::path(TRBC_BENCH_DATA_DIR) / "surrogates" / name;
        networks = std::make_shared<const FlowSurrogate>(FlowSurrogate::load(dir));
        model = surrogateFlowModel(networks);
        sets = flowDataSets(std::filesystem::path(TRBC_BENCH_DATA_DIR) / "experiments/validation", flowNetworkErrors(dir));
    }
};

const Shipped& shipped(std::int64_t which) {
    static const Shipped ensemble("flow"), distilled("flow_distilled");
    return which == 0 ? ensemble : distilled;
}
const char* modelName(std::int64_t which) { return which == 0 ? "ensemble" : "distilled"; }

// Argument: the data set's index in flowDataSets (0-6 donors, 7 TTF, 8-9 critical stresses).
void BM_FlowLogLikelihood(benchmark::State& state) {
    const Shipped& s = shipped(state.range(1));
    const FlowModel& model = s.model;
    const FlowDataSet& d = s.sets[static_cast<std::size_t>(state.range(0))];
    Eigen::MatrixXd cells(6, 16);
    for (Eigen::Index k = 0; k < cells.cols(); ++k) cells.col(k) << 0.93, 4.66, 0.226, 2.0, 0.06 + 0.01 * k, 0.5;
    long points = 0;
    for (const FlowCurve& c : d.curves) points += c.value.size();
    for (auto _ : state) {
        Eigen::VectorXd ll = flowLogLikelihood(model, d, cells);
        benchmark::DoNotOptimize(ll.data());
    }
    state.SetItemsProcessed(state.iterations() * cells.cols());
    state.SetLabel(d.name + " (" + std::to_string(points) + " points), " + modelName(state.range(1)));
}
BENCHMARK(BM_FlowLogLikelihood)->ArgsProduct({benchmark::CreateDenseRange(0, 9, 1), {0, 1}})->Unit(benchmark::kMicrosecond);

// FlowSurrogate::predict of N columns (both networks).
void BM_FlowPredict(benchmark::State& state) {
    const Shipped& s = shipped(state.range(1));
    const Eigen::Index n = state.range(0);
    Eigen::MatrixXd x(7, n);
    for (Eigen::Index k = 0; k < n; ++k) x.col(k) << 0.93, 4.66, 221.0, 2.0, 0.7, 23.9, 1.0 + k;
    for (auto _ : state) {
        FlowPrediction p = s.networks->predict(x);
        benchmark::DoNotOptimize(p.inclinationDeg.data());
    }
    state.SetItemsProcessed(state.iterations() * n);
    state.SetLabel(modelName(state.range(1)));
}
BENCHMARK(BM_FlowPredict)->ArgsProduct({{16, 640}, {0, 1}})->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
