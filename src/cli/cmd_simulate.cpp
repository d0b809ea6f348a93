// trbc simulate: one forward-model sample (SFS + equilibrium, stretching, relaxation; docs/FORWARD_MODEL.md)
// in physical units, printed as one JSON object.
#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

#include "cli/common.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "experiments/experiments.hpp"
#include "experiments/simulation_report.hpp"
#include "mesh/io.hpp"
#include "solvers/minimize.hpp"

namespace trbc::cli {
namespace {

std::vector<double> parseForceList(const std::string& text) {
    return parseNumberList(text, "--force-curve", "expected a comma-separated list of pN");
}

ExperimentSet parseExperiments(const std::string& text) {
    if (text.empty()) throw InputError("--experiments: the list is empty (valid: a comma-separated subset of eq, stretch, relax)");
    return parseExperimentSet(splitList(text), "--experiments");
}

void writeCsv(const std::string& path, const std::string& header, const std::vector<std::vector<double>>& cols) {
    std::ostringstream out;
    out.precision(10);
    out << csvProvenance() << header << '\n';
    for (std::size_t i = 0; i < cols.front().size(); ++i) {
        for (std::size_t c = 0; c < cols.size(); ++c) out << (c ? "," : "") << cols[c][i];
        out << '\n';
    }
    writeFileAtomically(path, out.str());
}

void saveShapes(const std::string& dir, const SampleResult& s, const ExperimentSet& which) {
    const Faces& F = s.sfs.mesh.F;
    Mesh sfs = s.sfs.mesh;
    sfs.X = cellMeshes(s.sfs).reference;
    writeMesh(dir + "/sfs.vtk", sfs);
    const Mesh eq{s.equilibrium.shape, F};
    writeMesh(dir + "/equilibrium.vtk", eq);
    writeMesh(dir + "/equilibrium.ply", eq);
    const ThicknessProfile& pr = s.equilibrium.profile;
    std::vector<double> h(pr.r.size());
    for (std::size_t i = 0; i < h.size(); ++i) h[i] = pr.zHigh[i] - pr.zLow[i];
    writeCsv(dir + "/equilibrium_profile.csv", "r_um,zlow_um,zhigh_um,h_um", {pr.r, pr.zLow, pr.zHigh, h});
    if (which.stretching) {
        std::vector<double> f, d0, d1;
        for (std::size_t k = 0; k < s.stretching.size(); ++k) {
            writeMesh(dir + fmt::format("/stretch_{:g}pN.vtk", s.stretching[k].fext), Mesh{s.stretchShapes[k], F});
            if (k == 0 && s.stretching.size() > 1) continue;  // the requested force; the curve follows
            f.push_back(s.stretching[k].fext);
            d0.push_back(s.stretching[k].observables.D0);
            d1.push_back(s.stretching[k].observables.D1);
        }
        writeCsv(dir + "/stretching_curve.csv", "Fext_pN,D0_um,D1_um", {f, d0, d1});
    }
    if (which.relaxation) {
        const RelaxationResult& r = s.relaxation;
        writeMesh(dir + "/relaxation_release.vtk", Mesh{r.released, F});
        writeMesh(dir + "/relaxation_end.vtk", Mesh{r.final, F});
        writeCsv(dir + "/relaxation.csv", "t_s,L_um,W_um,z", {r.t, r.L, r.W, r.z});
    }
}

struct SimulateCommandOptions {
    CellParameters p;
    double kbJ = 0.0, fext = 100.0, timeLimit = 0.0;
    int level = 4, threads = 1;
    std::string experiments = "eq,stretch,relax", saveShapes, forceCurve;
    bool allowOutside = false;
    CacheOptions cache;
    ExperimentOptions exp;
};

void addSimulateOptions(CLI::App* cmd, SimulateCommandOptions& o) {
    addNumber(cmd, "--v", o.p.v, "reduced volume v of the stress-free state, prior [0.65, 1]", NumberRange::leftOpen(0.0, 1.0))
        ->capture_default_str();
    addNumber(cmd, "--mu", o.p.mu, "shear modulus mu_uN_per_m, prior [1, 10] uN/m", NumberRange::positive("uN/m"))
        ->capture_default_str();
    auto* fvk = addNumber(cmd, "--FvK", o.p.FvK, "Foppl-von Karman number mu R_A^2 / kb, prior [10, 1000]", NumberRange::positive())
                    ->capture_default_str();
    addNumber(cmd, "--kb", o.kbJ, "bending modulus kb_J, replaces --FvK; prior [1.074e-19, 1.074e-18] J", NumberRange::positive("J"))
        ->excludes(fvk);
    addNumber(cmd, "--b2", o.p.b2, "Lim non-linear shear coefficient b2, prior [0, 4]", NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--etam", o.p.etam, "membrane viscosity etam_Pa_s_um, prior [0.1, 1] Pa s um", NumberRange::positive("Pa s um"))
        ->capture_default_str();
    addNumber(cmd, "--Fext", o.fext, "bead force Fext_pN per bead, prior [0, 200] pN", NumberRange::nonNegative("pN"))
        ->capture_default_str();
    addNumber(cmd, "--level", o.level, "icosphere level of the meshes (Nv = 10 4^L + 2; 4 as in the paper)", NumberRange::closed(2, 6))
        ->capture_default_str();
    cmd->add_option("--experiments", o.experiments, "comma-separated subset of eq,stretch,relax")->capture_default_str();
    cmd->add_option("--save-shapes", o.saveShapes,
                    "directory for the shapes (VTK/PLY), the equilibrium profile, the stretching curve and the "
                    "relaxation time series (CSV) and simulate.json");
    cmd->add_option("--force-curve", o.forceCurve,
                    "extra force levels in pN, comma-separated, for a whole stretching curve (continuation)");
    cmd->add_flag("--allow-outside-prior", o.allowOutside, "accept parameters outside the prior box (studies)");
    addSolverOptions(cmd, o.exp);
    addThreadsOption(cmd, o.threads, "OpenMP threads for the force evaluation");
    addNumber(cmd, "--time-limit", o.timeLimit,
              "wall-time budget (0: none); past it the run stops with \"status\": \"failed\", the reason \"time limit "
              "reached\" and exit 3",
              NumberRange::closed(0.0, 1e7, "s"))
        ->capture_default_str();
    addCacheOptions(cmd, o.cache);
}

/// The cell of the options (--kb replacing --FvK), checked against the prior box unless allowed.
CellParameters simulatedCell(const SimulateCommandOptions& o) {
    CellParameters p = o.p;
    if (o.kbJ != 0.0) {
        validateBendingModulus(o.kbJ, o.allowOutside);
        p.FvK = CellParameters::fvkFromKb(p.mu, o.kbJ);
    }
    validateCellParameters(p, o.allowOutside);
    validateForce(o.fext, o.allowOutside);
    return p;
}

nlohmann::json simulateProvenance(const SimulateCommandOptions& o, const ExperimentOptions& eo) {
    return withBuild({{"forward_model_revision", kForwardModelRevision}, {"command", commandLine()}, {"level", o.level},
                      {"vertices", 10 * (1 << (2 * o.level)) + 2}, {"sfs_model_version", kSfsModelVersion},
                      {"threads", o.threads}, {"in_plane_axis", inPlaneAxisName(eo.inPlaneAxis)},
                      {"preconditioner", eo.multigrid ? "multigrid" : "none"},
                      {"equilibrium_symmetry", equilibriumSymmetryName(eo.equilibriumSymmetry)},
                      {"equilibrium_seed", eo.kicks.seed}, {"equilibrium_kicks", eo.kicks.perRound}});
}

void runSimulate(const SimulateCommandOptions& o) {
    const CellParameters p = simulatedCell(o);
    const ExperimentSet which = parseExperiments(o.experiments);
    std::vector<double> curve;
    if (!o.forceCurve.empty()) {
        curve = parseForceList(o.forceCurve);
        for (double f : curve) validateForce(f, o.allowOutside);
    }
    if (!o.saveShapes.empty()) ensureWritableDirectory(o.saveShapes);
    omp_set_num_threads(o.threads);
    ExperimentOptions eo = o.exp;
    eo.level = o.level;
    eo.cacheDir = cacheDirectory(o.cache);
    if (o.timeLimit > 0)
        eo.deadline = eo.sfs.deadline = SteadyClock::now() + std::chrono::duration_cast<SteadyClock::duration>(
                                                               std::chrono::duration<double>(o.timeLimit));
    ProgressLine progress("simulate");
    eo.progress = [&progress](const std::string& stage) { progress.stage(stage); };
    nlohmann::json j;
    j["parameters"] = simulationParametersJson(p, o.fext);
    j["provenance"] = simulateProvenance(o, eo);
    const auto t0 = SteadyClock::now();
    SampleResult s;
    try {
        s = runSample(p, o.fext, which, eo, curve, !o.saveShapes.empty());
    } catch (const NumericalError& e) {
        const bool late = o.timeLimit > 0 && deadlinePassed(eo.deadline);
        const std::string reason =
            late ? fmt::format("time limit reached: --time-limit {:g} s ran out during the {}", o.timeLimit, progress.current())
                 : std::string(e.what());
        j["status"] = "failed";
        j["reason"] = reason;
        std::cout << j.dump(2) << std::endl;
        if (late) throw NumericalError(reason);
        throw;
    }
    const double wall = secondsSince(t0);
    const nlohmann::json provenance = j["provenance"];
    j = simulationJson(p, o.fext, o.level, which, s, wall);
    j["provenance"] = provenance;
    if (!o.saveShapes.empty()) {
        saveShapes(o.saveShapes, s, which);
        writeFileAtomically(o.saveShapes + "/simulate.json", j.dump(2) + "\n");
    }
    std::cout << j.dump(2) << std::endl;
}

}  // namespace

void registerSimulate(CLI::App& app) {
    auto o = std::make_shared<SimulateCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "simulate", "One forward-model sample: stress-free state, equilibrium shape (D, hmin, hmax), two-bead "
                    "stretching (D0, D1) and relaxation (tc) of docs/FORWARD_MODEL.md, printed as JSON (um, pN, s). "
                    "Defaults: the reference point v=0.95, mu=4, FvK=250, b2=1.5, etam=0.7, Fext=100");
    addSimulateOptions(cmd, *o);
    cmd->callback([o]() { runSimulate(*o); });
}

}  // namespace trbc::cli
