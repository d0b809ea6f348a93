// trbc sobol: first-order and total Sobol' indices of every surrogate output with respect to
// (v, mu, FvK, b2, etam) on the input box (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices): D, hmin, hmax, tc, and D0, D1
// at each force of a grid over [0, 200] pN.
#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>

#include "cli/common.hpp"
#include "core/output_dir.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "surrogate/sobol.hpp"
#include "surrogate/sobol_io.hpp"
#include "surrogate/surrogate_sobol.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {
namespace {

struct SobolCommandOptions {
    std::string model, out, base = "sobol";
    long samples = 1024;
    std::uint64_t seed = 1;
    int forces = 100, resamples = 100, threads = 1;
    bool noPlot = false;
};

void addSobolOptions(CLI::App* cmd, SobolCommandOptions& o) {
    addSurrogateModelOption(cmd, o.model);
    addNumber(cmd, "--samples", o.samples, "N, base rows of the Saltelli design (N(2D+2) evaluations; N(2D+2) x outputs at most "
                                           "2^27 values, the memory of the model's outputs: N up to 262144 with the default --forces)",
              NumberRange::closed(2, double(1L << 24)))
        ->capture_default_str();
    addNumber(cmd, "--seed", o.seed, "seed of the bootstrap (and of the base sample with --base random)", NumberRange::nonNegative())
        ->capture_default_str();
    cmd->add_option("--base", o.base, "base sample: sobol (Joe-Kuo low-discrepancy) or random")
        ->check(CLI::IsMember({"sobol", "random"}))->capture_default_str();
    addNumber(cmd, "--forces", o.forces, "number of forces F_j = 200 j / (n - 1) pN for D0 and D1", NumberRange::closed(2, 1000))
        ->capture_default_str();
    addNumber(cmd, "--resamples", o.resamples, "bootstrap resamples", NumberRange::closed(2, 100000))->capture_default_str();
    addOutOption(cmd, o.out);
    addThreadsOption(cmd, o.threads);
    cmd->add_flag("--no-plot", o.noPlot, "skip the figures (scripts/plot_sobol.py)");
}

/// First-order / total indices of the scalar outputs, each +- its 95 % CI half-width.
void printScalarIndices(const SobolResult& r) {
    std::cout << "first-order / total indices, each +- its 95 % CI half-width:\n";
    for (int out = 0; out < kSobolScalarOutputs; ++out) {
        std::cout << fmt::format("  {:<8}", r.outputs[out]);
        for (std::size_t in = 0; in < r.inputs.size(); ++in)
            std::cout << fmt::format("  {}: {:.3f}+-{:.3f}/{:.3f}+-{:.3f}", r.inputs[in], r.S1(out, in), r.S1_ci(out, in), r.ST(out, in),
                                     r.ST_ci(out, in));
        std::cout << '\n';
    }
}

void drawFigures(const std::filesystem::path& dir) {
    const std::string cmdline = fmt::format("/usr/bin/python3 {} {} >/dev/null 2>&1", shellQuote(scriptDirectory() / "plot_sobol.py"), shellQuote(dir));
    if (std::system(cmdline.c_str()) != 0)
        std::cerr << "sobol: the figures were not drawn (needs python3-matplotlib): " << cmdline << '\n';
    else
        std::cout << fmt::format("figures: {}/sobol_scalar.png, {}/sobol_force.png\n", dir.string(), dir.string());
}

void runSobol(const SobolCommandOptions& o) {
    const std::filesystem::path modelDir = surrogateModelDirectory(o.model);
    const Surrogate s = Surrogate::load(modelDir);
    const OutputDirectory outDir(o.out, "sobol", "--out", {"sobol.json", "sobol_indices.csv"});
    ensureWritableDirectory(o.out);
    omp_set_num_threads(o.threads);
    const std::vector<double> forces = sobolForces(o.forces);
    const std::vector<std::string> outputs = surrogateSobolOutputs(forces);
    // Every evaluation's outputs are held at once: N (2D + 2) x outputs doubles, checked before the
    // model is evaluated.
    constexpr double kMaxValues = double(1L << 27);
    const double values = double(o.samples) * (2.0 * 5.0 + 2.0) * double(outputs.size());
    if (values > kMaxValues)
        throw InputError(fmt::format("--samples {} with --forces {}: N (2D + 2) x {} outputs = {:.3g} values, more than the limit of "
                                     "2^27 = {:.3g}; use --samples {} or fewer",
                                     o.samples, o.forces, outputs.size(), values, kMaxValues,
                                     static_cast<long>(kMaxValues / (12.0 * double(outputs.size())))));
    Eigen::VectorXd lo(5), hi(5);
    for (int k = 0; k < 5; ++k) lo(k) = kCellBox[k].lo, hi(k) = kCellBox[k].hi;
    SobolOptions so;
    so.nBase = o.samples;
    so.base = o.base == "sobol" ? SobolBase::Sobol : SobolBase::PseudoRandom;
    so.seed = o.seed;
    setProvenanceSeed(o.seed);
    so.resamples = o.resamples;
    const auto t0 = SteadyClock::now();
    const SobolResult r = sobolAnalysis([&](const Eigen::MatrixXd& X) { return surrogateSobolModel(s, X, forces); }, lo, hi, so,
                                        surrogateSobolInputs(), outputs);
    const double wall = secondsSince(t0);
    const std::filesystem::path dir = o.out;
    writeSobolCsv(dir / "sobol_indices.csv", r);
    writeSobolSecondOrderCsv(dir / "sobol_second_order.csv", r);
    const SobolResolution res = sobolResolution(r);
    const std::string warning =
        res.resolved ? std::string()
                     : fmt::format("N = {} base rows do not resolve the indices (95 % CI half-widths up to {:.3g}{}): they are "
                                   "sampling noise; use --samples 1024 or more",
                                   r.nBase, res.widestHalfWidth, res.outside > 0.1 ? ", indices outside [0, 1]" : "");
    nlohmann::json j = withBuild({{"command", commandLine()}, {"model", modelDir.string()},
                                  {"seed", o.seed}, {"base", o.base}, {"n_base", r.nBase},
                                  {"evaluations", r.evaluations}, {"resamples", r.resamples}, {"wall_s", wall},
                                  {"resolved", res.resolved}});
    if (!res.resolved) j["warning"] = warning;
    writeFileAtomically(dir / "sobol.json", j.dump(2) + "\n");
    if (!res.resolved) std::cerr << "sobol: warning: " << warning << '\n';
    std::cout << fmt::format("sobol: {} outputs x {} inputs, {} model evaluations per output, {:.2f} s\n", outputs.size(),
                             r.inputs.size(), r.evaluations, wall);
    printScalarIndices(r);
    if (!o.noPlot) drawFigures(dir);
}

}  // namespace

void registerSobol(CLI::App& app) {
    auto o = std::make_shared<SobolCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "sobol", "Sobol' sensitivity indices (first order and total, bootstrap 95 % intervals; docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices) of D_um, "
                 "hmin_um, hmax_um, tc_s and of D0_um, D1_um at each force, with respect to v, mu_uN_per_m, FvK, b2, "
                 "etam_Pa_s_um uniform on the prior box; writes OUT/sobol_indices.csv, sobol_second_order.csv, sobol.json "
                 "and the figures");
    addSobolOptions(cmd, *o);
    cmd->callback([o]() { runSobol(*o); });
}

}  // namespace trbc::cli
