// trbc flow capsule: an initially spherical capsule in simple shear (flow/capsule.hpp), the
// solver's verification on a deformable membrane.
#include <omp.h>

#include <CLI/CLI.hpp>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "common.hpp"
#include "core/error.hpp"
#include "core/version.hpp"
#include "flow/capsule.hpp"

namespace trbc::cli {
namespace {

struct CapsuleCli {
    CapsuleCase c;
    std::string law = "neo-hookean";
    int threads = 0;
};

InPlaneLaw lawFromName(const std::string& name) {
    if (name == "lim") return InPlaneLaw::Lim;
    if (name == "skalak") return InPlaneLaw::Skalak;
    return InPlaneLaw::NeoHookean;
}

void runCapsuleCommand(CapsuleCli& o) {
    o.c.law = lawFromName(o.law);
    validateCapsuleCase(o.c);
    if (o.threads > 0) omp_set_num_threads(o.threads);
    const CapsuleResult r = runCapsule(o.c);
    nlohmann::json j;
    j["parameters"] = {{"law", o.law},
                       {"ca", o.c.capillary},
                       {"viscosity_ratio", o.c.viscosityRatio},
                       {"skalak_c", o.c.law == InPlaneLaw::Skalak ? nlohmann::json(o.c.skalakC) : nlohmann::json(nullptr)},
                       {"bending_Eb_over_a2_Gs", o.c.bending},
                       {"membrane_viscosity_etam_over_eta_a", o.c.membraneViscosity},
                       {"strain", o.c.strain},
                       {"step_tol", o.c.stepTolerance}};
    j["provenance"] = withBuild({{"command", commandLine()},
                                 {"level", o.c.level},
                                 {"vertices", r.vertices},
                                 {"threads", omp_get_max_threads()},
                                 {"method", "boundary-integral Stokes, no global area constraint, exact volume, linearly "
                                            "implicit adaptive BDF2 (flow/capsule.hpp)"}});
    j["diagnostics"] = {{"steps", r.steps},
                        {"rejected_steps", r.rejectedSteps},
                        {"gmres_iterations", r.gmresIterations},
                        {"wall_s", r.wallSeconds},
                        {"message", r.message}};
    j["series"] = {{"strain", r.times}, {"taylor_D12", r.d12}, {"inclination_deg", r.inclination}};
    if (!r.completed) {
        j["status"] = "failed";
        std::cout << j.dump(2) << std::endl;
        throw NumericalError("flow capsule: " + r.message);
    }
    j["status"] = "ok";
    j["observables"] = {{"taylor_D12", r.taylorD12},
                        {"inclination_deg", r.inclinationDeg},
                        {"membrane_frequency_over_rate", r.membraneFrequencyOverRate},
                        {"steady_state_reached", r.steady},
                        {"d12_variation_in_window", r.d12Variation},
                        {"area_change", r.areaChange}};
    std::cout << j.dump(2) << std::endl;
}

}  // namespace

void registerFlowCapsule(CLI::App* flow) {
    auto o = std::make_shared<CapsuleCli>();
    CLI::App* cmd = flow->add_subcommand(
        "capsule",
        "An initially spherical capsule of radius a in simple shear flow (docs/flow_verification.md, capsules): "
        "stress-free sphere, no global area constraint, exact volume, the literature's dimensionless groups. Prints "
        "the steady Taylor deformation D12 = (L - B) / (L + B) of the equivalent ellipsoid in the shear plane, its "
        "inclination and the membrane's angular frequency / rate, with the time series, as JSON");
    cmd->add_option("--law", o->law,
                    "in-plane law: neo-hookean, W = Gs/2 (I1 - 1 + 1/(I2 + 1)); skalak, W = Gs/4 (I1^2 + 2 I1 - 2 I2 + "
                    "C I2^2); lim (K_alpha = mu = Gs, the red cell's a3, a4, b1, b2 = 0)")
        ->check(CLI::IsMember({"lim", "neo-hookean", "skalak"}))
        ->capture_default_str();
    addNumber(cmd, "--ca", o->c.capillary, "capillary number Ca = eta rate a / Gs (Gs the small-strain shear modulus)",
              NumberRange::closed(1e-6, 100.0))
        ->required();
    addNumber(cmd, "--viscosity-ratio", o->c.viscosityRatio, "inner / outer viscosity lambda",
              NumberRange::closed(1e-3, 1e3))
        ->capture_default_str();
    addNumber(cmd, "--skalak-c", o->c.skalakC, "C of the skalak law (area-dilation modulus Gs (1 + 2 C))",
              NumberRange::leftOpen(-0.5, 1e4))
        ->capture_default_str();
    addNumber(cmd, "--bending", o->c.bending, "bending modulus EB = E_b / (a^2 Gs), E_b = kb of the Helfrich energy (0: none)",
              NumberRange::closed(0.0, 1e3))
        ->capture_default_str();
    addNumber(cmd, "--membrane-viscosity", o->c.membraneViscosity, "membrane viscosity EM = eta_m / (eta a) (0: none)",
              NumberRange::closed(0.0, 1e3))
        ->capture_default_str();
    addNumber(cmd, "--level", o->c.level, "icosphere level (Nv = 10 4^L + 2)", NumberRange::closed(1, 5))->capture_default_str();
    addNumber(cmd, "--strain", o->c.strain, "duration in units of 1 / rate", NumberRange::closed(0.5, 1e4))->capture_default_str();
    addNumber(cmd, "--step-tol", o->c.stepTolerance, "local error per time step, largest vertex displacement / a",
              NumberRange::closed(1e-8, 0.1))
        ->capture_default_str();
    addNumber(cmd, "--steady-window", o->c.steadyWindow,
              "the observables are means over the last this many strain units; steady when D12 varies there by at "
              "most --steady-tol of its final value",
              NumberRange::closed(0.01, 1e4))
        ->capture_default_str();
    addNumber(cmd, "--steady-tol", o->c.steadyTolerance, "relative variation of D12 in the window that counts as steady",
              NumberRange::closed(1e-8, 1.0))
        ->capture_default_str();
    addThreadsOption(cmd, o->threads, "OpenMP threads (0: OpenMP default)", 0);
    cmd->callback([o]() { runCapsuleCommand(*o); });
}

}  // namespace trbc::cli
