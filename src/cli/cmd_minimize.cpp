// trbc minimize: relax a mesh to a local energy minimum of any composition of terms.
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>

#include "cli/common.hpp"
#include "core/clock.hpp"
#include "core/error.hpp"
#include "core/version.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"
#include "mesh/validate.hpp"
#include "solvers/minimize.hpp"

namespace trbc::cli {
namespace {

struct MinimizeCommandOptions {
    std::string mesh, reference, out;
    ModulusOptions moduli;
    double reducedVolume = 0.0, tolerance = 1e-6, oblate = 1.0;
    bool haveReducedVolume = false;
    int maxIterations = 200000;
    double maxStep = 0.0;
};

void addMinimizeOptions(CLI::App* cmd, MinimizeCommandOptions& o) {
    cmd->add_option("--mesh", o.mesh, "initial mesh (OFF)")->required();
    cmd->add_option("--reference", o.reference, "stress-free mesh for the Lim term (OFF)");
    addOutOption(cmd, o.out, "relaxed mesh (.off, .ply or .vtk)");
    addModulusOptions(cmd, o.moduli);
    addNumber(cmd, "--reduced-volume", o.reducedVolume,
              "set V0 from a reduced volume v: V0 = v A0^{3/2} / (6 sqrt(pi)), A0 = --A0 or the mesh area", NumberRange::leftOpen(0.0, 1.0))
        ->each([&o](const std::string&) { o.haveReducedVolume = true; });
    addNumber(cmd, "--oblate-seed", o.oblate, "scale the initial z coordinates by this factor (< 1 seeds the oblate/discocyte branch)",
              NumberRange::closed(0.05, 1.0))
        ->capture_default_str();
    addNumber(cmd, "--tol", o.tolerance, "stop when the largest vertex force is below this", NumberRange::positive("(mesh force units)"))
        ->capture_default_str();
    addNumber(cmd, "--max-step", o.maxStep, "cap on any vertex displacement per iteration (0 = none)",
              NumberRange::nonNegative("(mesh length units)"))
        ->capture_default_str();
    addNumber(cmd, "--max-iter", o.maxIterations, "iteration limit", NumberRange::closed(1, 1e9))->capture_default_str();
}

/// The moduli of the options; --reduced-volume sets V0 (at --A0, else the mesh's area).
MembraneParameters minimizeParameters(const MinimizeCommandOptions& o, const Mesh& mesh) {
    ModulusOptions moduli = o.moduli;
    if (o.haveReducedVolume) {
        if (!moduli.haveA0) moduli.A0 = totalArea(mesh.X, mesh.F);
        moduli.haveA0 = true;
        moduli.V0 = volumeOfReducedVolume(o.reducedVolume, moduli.A0);
        moduli.haveV0 = true;
    }
    return checkedParameters(moduli);
}

/// z about the centroid scaled by `factor`.
void flattenAlongZ(Vertices& X, double factor) {
    const Eigen::Vector3d c = centroid(X);
    X.row(2) = ((X.row(2).array() - c[2]) * factor + c[2]).matrix();
}

/// The printed record: status, energy by term, mesh summary, solver diagnostics.
nlohmann::json minimizeJson(const MembraneParameters& p, const EnergyTerms& terms, const Mesh& mesh, const MinimizeResult& r, bool finite,
                            double wall, const std::string& out) {
    const bool ok = r.converged && finite;
    nlohmann::json j;
    j["status"] = ok ? "ok" : "failed";
    if (!ok) j["reason"] = finite ? "did not converge: " + r.message : std::string("the energy, the forces or the shape are not finite");
    j["energy"] = terms.total();
    j["terms"] = energyTermsJson(p, terms);
    j["mesh"] = meshSummary(mesh);
    j["diagnostics"] = {{"converged", r.converged}, {"iterations", r.iterations},
                        {"evaluations", r.evaluations}, {"max_vertex_force", r.gradientNorm},
                        {"message", r.message}, {"wall_s", wall}};
    j["output"] = ok ? nlohmann::json(out) : nlohmann::json(nullptr);
    j["provenance"] = withBuild({{"command", commandLine()}});
    return j;
}

void runMinimize(const MinimizeCommandOptions& o) {
    ensureWritableFile(o.out);
    Mesh mesh = readOff(o.mesh);
    const MembraneParameters p = minimizeParameters(o, mesh);
    std::unique_ptr<Mesh> ref;
    if (!o.reference.empty()) {
        ref = std::make_unique<Mesh>(readOff(o.reference));
        validateSameConnectivity(mesh, *ref, o.reference);
    } else if (p.hasLim()) {
        throw InputError("the Lim term (--ka or --mu > 0) needs the stress-free mesh --reference");
    }
    const MembraneModel model(mesh.F, mesh.numVertices(), p, ref ? &ref->X : nullptr);
    if (o.oblate < 1.0) flattenAlongZ(mesh.X, o.oblate);
    MinimizeOptions opt;
    opt.gradientTolerance = o.tolerance;
    opt.maxIterations = o.maxIterations;
    opt.maxVertexStep = o.maxStep;
    const auto t0 = SteadyClock::now();
    ProgressLine progress("minimize");
    progress.stage(fmt::format("L-BFGS on {} vertices", mesh.numVertices()));
    const MinimizeResult r = minimizeEnergy(model, mesh.X, opt);
    const double wall = secondsSince(t0);
    Vertices grad;
    EnergyTerms terms;
    model.evaluate(mesh.X, &grad, &terms);
    const bool finite = std::isfinite(terms.total()) && grad.allFinite() && mesh.X.allFinite();
    // A shape that did not converge is not the relaxed mesh that --out promises: not written.
    if (r.converged && finite) {
        const auto d = model.vertexDiagnostics(mesh.X);
        writeMesh(o.out, mesh, {{"force", -grad}, {"mean_curvature", d.meanCurvature.transpose()}, {"vertex_area", d.area.transpose()}});
    }
    std::cout << minimizeJson(p, terms, mesh, r, finite, wall, o.out).dump(2) << std::endl;
    if (!finite) throw NumericalError("minimisation diverged (non-finite energy, forces or shape); nothing written to " + o.out);
    if (!r.converged) throw NumericalError("minimisation did not converge: " + r.message + "; nothing written to " + o.out);
}

}  // namespace

void registerMinimize(CLI::App& app) {
    auto o = std::make_shared<MinimizeCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "minimize", "Relax a mesh to a local minimum of the chosen energy terms by L-BFGS (mesh units) "
                    "and write it with per-vertex force, mean curvature and area fields");
    addMinimizeOptions(cmd, *o);
    cmd->callback([o]() { runMinimize(*o); });
}

}  // namespace trbc::cli
