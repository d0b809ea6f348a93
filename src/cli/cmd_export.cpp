// trbc export: the calibrated cell for other RBC codes: the theta_new posterior
// summarised by a quantile of each marginal, its stress-free state and equilibrium shape (OFF and
// PLY, um) and its parameters in physical and in dimensionless units (JSON).
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>

#include "analysis/validation_draws.hpp"
#include "cli/common.hpp"
#include "core/output_dir.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "experiments/experiments.hpp"
#include "experiments/sfs.hpp"
#include "experiments/simulation_report.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {
namespace {

namespace fs = std::filesystem;

/// q-quantile of a sample (linear interpolation between order statistics).
double sampleQuantile(Eigen::VectorXd x, double q) {
    std::sort(x.data(), x.data() + x.size());
    const double pos = q * static_cast<double>(x.size() - 1);
    const auto i = static_cast<Eigen::Index>(std::floor(pos));
    const double w = pos - static_cast<double>(i);
    return i + 1 < x.size() ? (1.0 - w) * x[i] + w * x[i + 1] : x[i];
}

struct ExportCommandOptions {
    std::string posterior, out;
    double quantile = 0.5;
    int level = 4, threads = 1;
    ExperimentOptions exp;
    CacheOptions cache;
};

void addExportOptions(CLI::App* cmd, ExportCommandOptions& o) {
    cmd->add_option("--posterior", o.posterior, "posterior directory with samples.csv (or the file), e.g. DIR/phase3/theta_new")->required();
    addNumber(cmd, "--quantile", o.quantile, "quantile of each marginal (0.5: the medians)", NumberRange::open(0.0, 1.0))
        ->capture_default_str();
    addNumber(cmd, "--level", o.level, "icosphere level of the meshes (Nv = 10 4^L + 2)", NumberRange::closed(1, 6))
        ->capture_default_str();
    addOutOption(cmd, o.out);
    addThreadsOption(cmd, o.threads);
    addSolverOptions(cmd, o.exp);
    addCacheOptions(cmd, o.cache);
}

/// The cell whose every parameter is the q-quantile of its own marginal; FvK = mu R_A^2 / kb from those.
CellParameters quantileCell(const NumericTable& t, double q, double& kbJ) {
    CellParameters p;
    p.v = sampleQuantile(t.column("v"), q);
    p.mu = sampleQuantile(t.column("mu_uN_per_m"), q);
    kbJ = sampleQuantile(t.column("kb_J"), q);
    p.FvK = CellParameters::fvkFromKb(p.mu, kbJ);
    p.b2 = sampleQuantile(t.column("b2"), q);
    p.etam = sampleQuantile(t.column("etam_Pa_s_um"), q);
    return p;
}

/// Tail quantiles of a theta_new posterior can leave the prior box (the surrogates' training
/// box, where the posterior was never checked against data): said loudly and recorded ("" inside).
std::string priorBoxWarning(const CellParameters& p, double q) {
    try {
        validateCellParameters(p, false);
    } catch (const InputError& e) {
        const std::string warning = fmt::format("--quantile {:g} gives a cell outside the prior box: {}", q, e.what());
        std::cerr << "export: warning: " << warning << '\n';
        return warning;
    }
    return "";
}

void runExport(const ExportCommandOptions& o) {
    const fs::path in(o.posterior);
    const fs::path file = fs::is_directory(in) ? in / "samples.csv" : in;
    const NumericTable t = readThetaNewSamples(in);
    const OutputDirectory outDir(o.out, "export", "--out", {"cell.json"});
    ensureWritableDirectory(o.out);
    omp_set_num_threads(o.threads);
    double kbJ = 0.0;
    const CellParameters p = quantileCell(t, o.quantile, kbJ);
    validateCellParameters(p, true);
    const std::string warning = priorBoxWarning(p, o.quantile);

    ExperimentOptions eo = o.exp;
    eo.level = o.level;
    eo.cacheDir = cacheDirectory(o.cache);
    const auto t0 = SteadyClock::now();
    ProgressLine progress("export");
    progress.stage(fmt::format("stress-free state (v = {:g}, level {})", p.v, o.level));
    const StressFreeState sfs = stressFreeState(p.v, o.level, eo.cacheDir);
    const CellMeshes meshes = cellMeshes(sfs);
    progress.stage("equilibrium shape");
    const EquilibriumResult eq = runEquilibrium(p, meshes, eo);
    const double wall = secondsSince(t0);

    const fs::path dir(o.out);
    for (const char* ext : {"off", "ply"}) {
        writeMesh((dir / fmt::format("sfs.{}", ext)).string(), Mesh{meshes.reference, meshes.faces});
        writeMesh((dir / fmt::format("equilibrium.{}", ext)).string(), Mesh{eq.shape, meshes.faces});
    }
    nlohmann::json j;
    j["source"] = {{"posterior", fs::absolute(file).lexically_normal().string()}, {"samples", t.values.rows()}};
    j["quantile"] = o.quantile;
    if (!warning.empty()) j["warning"] = warning;
    j["note"] = "each parameter is the given quantile of its own marginal; FvK = mu R_A^2 / kb from those";
    j["physical"] = cellPhysicalJson(p, kbJ);
    j["dimensionless"] = cellDimensionlessJson(p);
    j["observables"] = {{"D_um", eq.observables.D}, {"hmin_um", eq.observables.hmin}, {"hmax_um", eq.observables.hmax}};
    j["files"] = {{"stress_free", {"sfs.off", "sfs.ply"}},
                  {"equilibrium", {"equilibrium.off", "equilibrium.ply"}},
                  {"mesh", {{"level", o.level}, {"vertices", meshes.reference.cols()}, {"faces", meshes.faces.cols()}, {"units", "um"}}}};
    j["diagnostics"] = {{"sfs_from_cache", sfs.fromCache}, {"equilibrium_converged", eq.diagnostics.converged}, {"wall_s", wall}};
    j["provenance"] = withBuild({{"command", commandLine()}});
    writeFileAtomically(dir / "cell.json", j.dump(2) + "\n");
    std::cout << j.dump(2) << std::endl;
}

}  // namespace

void registerExport(CLI::App& app) {
    auto o = std::make_shared<ExportCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "export", "Export the calibrated cell for flow solvers: the given quantile of each marginal of a theta_new posterior "
                  "(samples.csv of `trbc infer`: DIR/phase3/theta_new), its stress-free state and equilibrium shape as OFF and "
                  "PLY meshes (um) and OUT/cell.json with the parameters in physical units (v, mu_uN_per_m, kb_J, FvK, b2, "
                  "etam_Pa_s_um, A0_um2, V0_um3) and in the dimensionless units of docs/MEMBRANE_MODEL.md");
    addExportOptions(cmd, *o);
    cmd->callback([o]() { runExport(*o); });
}

}  // namespace trbc::cli
