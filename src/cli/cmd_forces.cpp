// trbc forces: energy and forces of any composition of terms on a mesh, in the mesh's own units,
// for cross-checking against other membrane codes.
#include <fmt/format.h>

#include <fstream>
#include <iostream>
#include <memory>

#include "cli/common.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "membrane/model.hpp"
#include "mesh/io.hpp"
#include "mesh/validate.hpp"

namespace trbc::cli {

nlohmann::json energyTermsJson(const MembraneParameters& p, const EnergyTerms& t) {
    nlohmann::json terms = nlohmann::json::object();
    if (p.hasBending()) terms["bending"] = t.bending;
    if (p.hasAde()) terms["ade"] = t.ade;
    if (p.hasLim()) terms["lim"] = t.lim;
    if (p.hasCapsuleLaw()) terms[inPlaneLawName(p.law)] = t.capsule;
    if (p.hasArea()) terms["area"] = t.area;
    if (p.hasVolume()) terms["volume"] = t.volume;
    return terms;
}

void registerForces(CLI::App& app) {
    struct Opts {
        std::string mesh, reference, out;
        ModulusOptions moduli;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = app.add_subcommand(
        "forces",
        "Energy of each term (JSON on stdout) and per-vertex forces -dU/dx (CSV fx,fy,fz) of a mesh. "
        "Lengths and moduli in the mesh's own units; every modulus defaults to 0 (term off).");
    cmd->add_option("--mesh", o->mesh, "closed triangle mesh (OFF)")->required();
    cmd->add_option("--reference", o->reference, "stress-free mesh for the in-plane term (OFF, same connectivity)");
    addOutOption(cmd, o->out, "output CSV with header fx,fy,fz, one row per vertex");
    addModulusOptions(cmd, o->moduli);
    addInPlaneLawOptions(cmd, o->moduli);
    cmd->callback([o]() {
        const MembraneParameters p = checkedParameters(o->moduli);
        ensureWritableFile(o->out);
        const Mesh mesh = readOff(o->mesh);
        std::unique_ptr<Mesh> ref;
        if (!o->reference.empty()) {
            ref = std::make_unique<Mesh>(readOff(o->reference));
            validateSameConnectivity(mesh, *ref, o->reference);
        } else if (p.hasLim()) {
            throw InputError("the Lim term (--ka or --mu > 0) needs the stress-free mesh --reference");
        } else if (p.hasCapsuleLaw()) {
            throw InputError(fmt::format("the {} law (--Gs > 0) needs the stress-free mesh --reference", o->moduli.law));
        }
        const MembraneModel model(mesh.F, mesh.numVertices(), p, ref ? &ref->X : nullptr);
        Vertices grad;
        EnergyTerms terms;
        const double energy = model.evaluate(mesh.X, &grad, &terms);
        if (!std::isfinite(energy) || !grad.allFinite())
            throw NumericalError(fmt::format("energy or forces are not finite on '{}'", o->mesh));
        std::string csv = csvProvenance() + "fx,fy,fz\n";
        for (Eigen::Index i = 0; i < grad.cols(); ++i)
            csv += fmt::format("{:.17g},{:.17g},{:.17g}\n", -grad(0, i), -grad(1, i), -grad(2, i));
        writeFileAtomically(o->out, csv);
        nlohmann::json j;
        j["energy"] = energy;
        j["terms"] = energyTermsJson(p, terms);
        std::cout << j.dump() << std::endl;
    });
}

}  // namespace trbc::cli
