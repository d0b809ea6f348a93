// trbc mesh: inspect and validate meshes, make icospheres and biconcave cells.
#include <fmt/format.h>

#include <iostream>
#include <memory>

#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/version.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {

nlohmann::json meshSummary(const Mesh& m) {
    const double A = totalArea(m.X, m.F), V = enclosedVolume(m.X, m.F);
    const Eigen::Vector3d ext = extents(alignPrincipalAxes(m.X));
    return {{"vertices", m.numVertices()},
            {"faces", m.numFaces()},
            {"edges", 3 * m.numFaces() / 2},
            {"area", A},
            {"volume", V},
            {"reduced_volume", reducedVolume(A, V)},
            {"principal_extents", {ext[0], ext[1], ext[2]}}};
}

std::vector<VertexField> geometryFields(const Mesh& m) {
    const MembraneModel probe(m.F, m.numVertices(), MembraneParameters{});
    const auto d = probe.vertexDiagnostics(m.X);
    return {{"mean_curvature", d.meanCurvature.transpose()}, {"vertex_area", d.area.transpose()}};
}

void registerMesh(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand("mesh", "Inspect, validate and generate meshes");
    cmd->require_subcommand(1);

    auto info = std::make_shared<std::string>();
    CLI::App* infoCmd = cmd->add_subcommand(
        "info", "Validate a mesh (closed, oriented, genus 0) and print its size, area, volume, reduced "
                "volume and principal extents as JSON");
    infoCmd->add_option("mesh", *info, "mesh: OFF, or the PLY and VTK files that trbc writes")->required();
    infoCmd->callback([info]() { std::cout << meshSummary(readMesh(*info)).dump(2) << std::endl; });

    struct IcoOpts {
        int level = 3;
        bool biconcave = false;
        double area = 0.0;
        std::string out;
    };
    auto o = std::make_shared<IcoOpts>();
    CLI::App* ico = cmd->add_subcommand(
        "icosphere", "Unit icosphere (Nv = 10 4^L + 2), optionally mapped to the Evans-Fung biconcave "
                     "shape (um) and scaled to a target area; written as OFF, PLY or VTK (with mean "
                     "curvature and vertex area fields)");
    addNumber(ico, "--level", o->level, "subdivision level L", NumberRange::closed(0, 7))->capture_default_str();
    ico->add_flag("--biconcave", o->biconcave, "map onto the Evans-Fung (1972) resting cell");
    // Bounded so that area, volume and every coordinate stay finite doubles (volume ~ area^1.5).
    // Bounded on both sides so that area, volume, every coordinate and the curvatures (~ 1 /
    // length) stay finite, normal doubles (volume ~ area^1.5, products of edge vectors ~ area).
    addNumber(ico, "--area", o->area, "scale uniformly to this area (0 = keep, else in [1e-100, 1e100])",
              NumberRange::closed(0.0, 1e100, "(length^2, um^2 with --biconcave)"));
    addOutOption(ico, o->out, "output mesh (.off, .ply or .vtk)");
    ico->callback([o]() {
        if (o->area > 0.0 && o->area < 1e-100)
            throw InputError(fmt::format("--area {:g}: too small for finite curvatures; valid: 0 (keep) or [1e-100, 1e100]", o->area));
        Mesh m = icosphere(o->level);
        if (o->biconcave) m.X = evansFungMap(m.X);
        if (o->area > 0) m.X = scaleToArea(m.X, m.F, o->area);
        writeMesh(o->out, m, geometryFields(m));
        nlohmann::json j = meshSummary(m);
        j["output"] = o->out;
        j["provenance"] = withBuild({{"command", commandLine()}});
        std::cout << j.dump(2) << std::endl;
    });
}

}  // namespace trbc::cli
