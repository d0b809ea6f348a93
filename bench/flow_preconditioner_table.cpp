// The preconditioner table of docs/FLOW_SOLVER.md ("Preconditioner"): level-3 cases of a flow campaign
// run for one rigid-sphere turn from their random start, with the bending correction at the
// default steps and without it (bendingPreconditionerRatio infinite), side by side in one run,
// one thread. GMRES iterations per step, accepted steps and the CPU seconds of each run.
//   build/bench_flow_preconditioner_table CASES_CSV [CASE_ID ...]   (default: every case)
// CASES_CSV is a `trbc flow campaign` cases.csv (results/flow_stop_rule/full_length/cases.csv).

#include <omp.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/scratch_dir.hpp"
#include "experiments/parameters.hpp"
#include "flow/cell_flow.hpp"
#include "flow/shear_case.hpp"
#include "sampling/shear_campaign_table.hpp"

using namespace trbc;

namespace {

const std::filesystem::path& cacheDir() {
    static const std::filesystem::path d = processTemporaryDirectory("trbc_preconditioner_table_");
    return d;
}

double cpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

struct Run {
    double iterationsPerStep = 0.0, cpu = 0.0;
    int steps = 0;
    bool completed = false;
};

Run oneTurn(const CellFlowModel& model, const Vertices& X0, double bendingRatio) {
    CellFlowOptions o;
    o.tEnd = 4.0 * std::acos(-1.0);  // one rigid-sphere turn, 4 pi / rate
    o.keepFrames = false;
    o.bendingPreconditionerRatio = bendingRatio;
    const double t0 = cpuSeconds();
    const CellFlowResult r = integrateCellFlow(model, X0, o);
    Run run;
    run.cpu = cpuSeconds() - t0;
    run.steps = r.steps;
    run.completed = r.completed;
    const int attempts = r.steps + r.rejectedSteps + r.failedSolves;
    run.iterationsPerStep = attempts > 0 ? static_cast<double>(r.gmresIterations) / attempts : 0.0;
    return run;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s CASES_CSV [CASE_ID ...]\n", argv[0]);
        return 2;
    }
    try {
        const std::vector<ShearCampaignRow> rows = readShearCampaignCsv(argv[1]);
        std::vector<long> ids;
        for (int k = 2; k < argc; ++k) {
            const std::string_view a(argv[k]);
            long id = -1;
            const auto [end, ec] = std::from_chars(a.data(), a.data() + a.size(), id);
            if (ec != std::errc{} || end != a.data() + a.size() || id < 0) {
                std::fprintf(stderr, "CASE_ID '%s': must be a case id (an integer >= 0)\n", argv[k]);
                return 2;
            }
            ids.push_back(id);
        }
        omp_set_num_threads(1);
        for (long id : ids)
            if (std::none_of(rows.begin(), rows.end(), [&](const ShearCampaignRow& r) { return r.point.caseId == id; })) {
                std::fprintf(stderr, "CASE_ID %ld: not in %s\n", id, argv[1]);
                return 2;
            }
        std::printf("| case | FvK | capillary number | iterations per step, without / with | steps | CPU s, without / with |\n");
        std::printf("|---|---|---|---|---|---|\n");
        double cpuWithout = 0.0, cpuWith = 0.0;
        for (const ShearCampaignRow& r : rows) {
            const ShearCampaignPoint& p = r.point;
            if (!ids.empty() && std::find(ids.begin(), ids.end(), p.caseId) == ids.end()) continue;
            FlowConditions fc;
            fc.etaOut = p.etaOut;
            fc.etaIn = p.etaIn;
            fc.shearRate = p.shearRate;
            const ShearCell c = prepareShearCell(p.cell, 3, cacheDir());
            const CellFlowModel model(p.cell, fc, c.faces, c.reference);
            // The campaign's start (runShearCase with ShearCaseOptions::randomStart).
            const FlowScales& s = model.scales();
            const Vertices X0 = model.toInternal(randomThermalStart(c.initial, s.length,
                                                                    model.membrane().parameters().bending.kb * s.force() * s.length,
                                                                    ShearCaseOptions{}.kickTemperatureK, p.startSeed));
            const Run a = oneTurn(model, X0, std::numeric_limits<double>::infinity());
            const Run b = oneTurn(model, X0, CellFlowOptions{}.bendingPreconditionerRatio);
            cpuWithout += a.cpu;
            cpuWith += b.cpu;
            std::printf("| %ld | %.0f | %.3g | %.1f / %.1f | %d / %d | %.2f / %.2f%s |\n", p.caseId, p.cell.FvK,
                        model.groups().capillary, a.iterationsPerStep, b.iterationsPerStep, a.steps, b.steps, a.cpu, b.cpu,
                        a.completed && b.completed ? "" : " (incomplete)");
            std::fflush(stdout);
        }
        std::filesystem::remove_all(cacheDir());
        std::printf("\nCPU in all: %.1f s without, %.1f s with (%.2fx)\n", cpuWithout, cpuWith, cpuWith / cpuWithout);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    }
    return 0;
}
