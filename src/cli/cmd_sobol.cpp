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
#include "core/clock.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "surrogate/sobol.hpp"
#include "surrogate/sobol_io.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {

/// The Sobol' model: rows of X are points (v, mu, FvK, b2, etam); columns of the result are
/// D, hmin, hmax, tc, then D0@F_j and D1@F_j for every force.
static Eigen::MatrixXd sobolOutputs(const Surrogate& s, const Eigen::MatrixXd& X, const std::vector<double>& forces) {
    const Eigen::Index n = X.rows();
    const Eigen::MatrixXd x = X.transpose();  // 5 x n
    const std::size_t nF = forces.size();
    Eigen::MatrixXd Y(n, 4 + 2 * Eigen::Index(nF));
    Eigen::MatrixXd eqIn(2, n);
    eqIn << x.row(0), x.row(2);
    Y.leftCols(3) = s.equilibriumOutputs(eqIn).transpose();
    Y.col(3) = s.relaxationTime(x);
    Eigen::MatrixXd st(5, n);
    st.topRows(4) = x.topRows(4);
    for (std::size_t j = 0; j < nF; ++j) {
        st.row(4).setConstant(forces[j]);
        const Eigen::MatrixXd d = s.stretchingOutputs(st);
        Y.col(4 + 2 * Eigen::Index(j)) = d.row(0).transpose();
        Y.col(5 + 2 * Eigen::Index(j)) = d.row(1).transpose();
    }
    return Y;
}

void registerSobol(CLI::App& app) {
    struct Opts {
        std::string model, out, base = "sobol";
        long samples = 1024;
        std::uint64_t seed = 1;
        int forces = 100, resamples = 100, threads = 1;
        bool noPlot = false;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = app.add_subcommand(
        "sobol", "Sobol' sensitivity indices (first order and total, bootstrap 95 % intervals; docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices) of D_um, "
                 "hmin_um, hmax_um, tc_s and of D0_um, D1_um at each force, with respect to v, mu_uN_per_m, FvK, b2, "
                 "etam_Pa_s_um uniform on the prior box; writes OUT/sobol_indices.csv, sobol_second_order.csv, sobol.json "
                 "and the figures");
    addSurrogateModelOption(cmd, o->model);
    addNumber(cmd, "--samples", o->samples, "N, base rows of the Saltelli design (N(2D+2) evaluations)",
              NumberRange::closed(2, double(1L << 24)))
        ->capture_default_str();
    addNumber(cmd, "--seed", o->seed, "seed of the bootstrap (and of the base sample with --base random)", NumberRange::nonNegative())
        ->capture_default_str();
    cmd->add_option("--base", o->base, "base sample: sobol (Joe-Kuo low-discrepancy) or random")
        ->check(CLI::IsMember({"sobol", "random"}))->capture_default_str();
    addNumber(cmd, "--forces", o->forces, "number of forces F_j = 200 j / (n - 1) pN for D0 and D1", NumberRange::closed(2, 1000))
        ->capture_default_str();
    addNumber(cmd, "--resamples", o->resamples, "bootstrap resamples", NumberRange::closed(2, 100000))->capture_default_str();
    addOutOption(cmd, o->out);
    addThreadsOption(cmd, o->threads);
    cmd->add_flag("--no-plot", o->noPlot, "skip the figures (scripts/plot_sobol.py)");
    cmd->callback([o]() {
        const std::filesystem::path modelDir = surrogateModelDirectory(o->model);
        const Surrogate s = Surrogate::load(modelDir);
        ensureWritableDirectory(o->out);
        omp_set_num_threads(o->threads);
        std::vector<double> forces;
        for (int j = 0; j < o->forces; ++j) forces.push_back(200.0 * j / (o->forces - 1));
        std::vector<std::string> outputs = {"D_um", "hmin_um", "hmax_um", "tc_s"};
        for (double f : forces) outputs.push_back(fmt::format("D0_um@{:.4g}", f)), outputs.push_back(fmt::format("D1_um@{:.4g}", f));
        const std::vector<std::string> inputs = {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um"};
        Eigen::VectorXd lo(5), hi(5);
        for (int k = 0; k < 5; ++k) lo(k) = kCellBox[k].lo, hi(k) = kCellBox[k].hi;
        SobolOptions so;
        so.nBase = o->samples;
        so.base = o->base == "sobol" ? SobolBase::Sobol : SobolBase::PseudoRandom;
        so.seed = o->seed;
        so.resamples = o->resamples;
        const auto t0 = SteadyClock::now();
        const SobolResult r = sobolAnalysis([&](const Eigen::MatrixXd& X) { return sobolOutputs(s, X, forces); }, lo, hi, so,
                                            inputs, outputs);
        const double wall = secondsSince(t0);
        const std::filesystem::path dir = o->out;
        writeSobolCsv(dir / "sobol_indices.csv", r);
        writeSobolSecondOrderCsv(dir / "sobol_second_order.csv", r);
        // Indices are resolved when every 95 % CI half-width of the scalar outputs is below 0.1 and
        // every index lies in [0, 1] up to that width; otherwise the numbers are sampling noise.
        double widest = 0.0, outside = 0.0;
        for (int out = 0; out < 4; ++out)
            for (int in = 0; in < 5; ++in) {
                widest = std::max({widest, r.S1_ci(out, in), r.ST_ci(out, in)});
                for (const double S : {r.S1(out, in), r.ST(out, in)}) outside = std::max({outside, S - 1.0, -S});
            }
        const bool resolved = std::isfinite(widest) && widest < 0.1 && outside < 0.1;
        const std::string warning =
            resolved ? std::string()
                     : fmt::format("N = {} base rows do not resolve the indices (95 % CI half-widths up to {:.3g}{}): they are "
                                   "sampling noise; use --samples 1024 or more",
                                   r.nBase, widest, outside > 0.1 ? ", indices outside [0, 1]" : "");
        nlohmann::json j = {{"command", commandLine()}, {"version", kVersion}, {"model", modelDir.string()},
                            {"seed", o->seed}, {"base", o->base}, {"n_base", r.nBase},
                            {"evaluations", r.evaluations}, {"resamples", r.resamples}, {"wall_s", wall},
                            {"resolved", resolved}};
        if (!resolved) j["warning"] = warning;
        writeFileAtomically(dir / "sobol.json", j.dump(2) + "\n");
        if (!resolved) std::cerr << "sobol: warning: " << warning << '\n';
        std::cout << fmt::format("sobol: {} outputs x {} inputs, {} model evaluations per output, {:.2f} s\n", outputs.size(),
                                 inputs.size(), r.evaluations, wall);
        std::cout << "first-order / total indices, each +- its 95 % CI half-width:\n";
        for (int out = 0; out < 4; ++out) {
            std::cout << fmt::format("  {:<8}", outputs[out]);
            for (int in = 0; in < 5; ++in)
                std::cout << fmt::format("  {}: {:.3f}+-{:.3f}/{:.3f}+-{:.3f}", inputs[in], r.S1(out, in), r.S1_ci(out, in), r.ST(out, in),
                                         r.ST_ci(out, in));
            std::cout << '\n';
        }
        if (!o->noPlot) {
            const std::string cmdline = fmt::format("/usr/bin/python3 {}/scripts/plot_sobol.py {} >/dev/null 2>&1", TRBC_SOURCE_DIR, dir.string());
            if (std::system(cmdline.c_str()) != 0)
                std::cerr << "sobol: the figures were not drawn (needs python3-matplotlib): " << cmdline << '\n';
            else
                std::cout << fmt::format("figures: {}/sobol_scalar.png, {}/sobol_force.png\n", dir.string(), dir.string());
        }
    });
}

}  // namespace trbc::cli
