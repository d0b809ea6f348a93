#include "experiments/simulation_report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.hpp"
#include "experiments/reference_protocol.hpp"

namespace trbc {

nlohmann::json sfsJson(const StressFreeState& s) {
    return {{"v", s.v},
            {"v_imposed", s.vTarget},
            {"level", s.level},
            {"reduced_volume", s.reducedVolume},
            {"energy_kappa", s.energy},
            {"max_tangential_force_kappa_per_R", s.gradientNorm},
            {"tension_kappa_per_R2", s.tension},
            {"pressure_kappa_per_R3", s.pressure},
            {"iterations", s.iterations},
            {"force_evaluations", s.evaluations},
            {"converged", s.converged},
            {"wall_s", s.wallSeconds},
            {"principal_extents_rel", {s.principalExtents[0], s.principalExtents[1], s.principalExtents[2]}},
            {"from_cache", s.fromCache}};
}

nlohmann::json staticSolverJson(const SolverDiagnostics& d) {
    return {{"converged", d.converged},
            {"iterations", d.iterations},
            {"force_evaluations", d.evaluations},
            {"wall_s", d.wallSeconds},
            {"max_tangential_force_pN", d.gradientNorm},
            {"tension_pN_per_um", d.tension},
            {"pressure_Pa", d.pressure},
            {"energy_J", d.energy / cell::joule},
            {"message", d.message}};
}

nlohmann::json equilibriumBranchJson(const EquilibriumResult& e) {
    nlohmann::json candidates = nlohmann::json::array();
    for (const EquilibriumCandidate& c : e.candidates)
        candidates.push_back({{"start", c.start}, {"round", c.round}, {"kick", c.kick}, {"converged", c.converged},
                              {"energy_J", c.energy / cell::joule}, {"hmin_um", c.hmin}, {"inversion_asymmetry", c.asymmetry},
                              {"force_evaluations", c.evaluations}, {"wall_s", c.wallSeconds}});
    const bool kicked = e.kickRms > 0.0;
    return {{"branch", e.branch},
            {"energy_gap_J", kicked ? nlohmann::json(e.energyGap / cell::joule) : nlohmann::json(nullptr)},
            {"kick_rms_um", kicked ? nlohmann::json(e.kickRms) : nlohmann::json(nullptr)},
            {"candidates", candidates}};
}

ExperimentSet parseExperimentSet(const std::vector<std::string>& names, const std::string& option) {
    ExperimentSet s{false, false, false};
    for (const std::string& item : names) {
        if (item == "eq")
            s.equilibrium = true;
        else if (item == "stretch")
            s.stretching = true;
        else if (item == "relax")
            s.relaxation = true;
        else
            throw InputError(fmt::format("{}: unknown experiment '{}' (valid: eq, stretch, relax)", option, item));
    }
    s.equilibrium = true;  // stretching and relaxation start from the equilibrium shape
    return s;
}

nlohmann::json simulationParametersJson(const CellParameters& p, double fextPn) {
    return {{"v", p.v}, {"mu_uN_per_m", p.mu}, {"FvK", p.FvK}, {"kb_J", p.kbJoule()},
            {"b2", p.b2}, {"etam_Pa_s_um", p.etam}, {"Fext_pN", fextPn}};
}

nlohmann::json cellPhysicalJson(const CellParameters& p, double kbJ) {
    return {{"v", p.v},
            {"mu_uN_per_m", p.mu},
            {"kb_J", kbJ},
            {"FvK", p.FvK},
            {"b2", p.b2},
            {"etam_Pa_s_um", p.etam},
            {"Kalpha_uN_per_m", p.mu},
            {"A0_um2", cell::area},
            {"V0_um3", cell::volume},
            {"R_A_um", std::sqrt(cell::radiusSquared)}};
}

nlohmann::json cellDimensionlessJson(const CellParameters& p) {
    const double RA = std::sqrt(cell::radiusSquared);
    return {{"length_unit_um", RA},
            {"energy_unit_J", p.mu * cell::radiusSquared * 1e-18},
            {"time_unit_s", p.etam / p.mu},
            {"mu", 1.0},
            {"Kalpha", 1.0},
            {"kb", 1.0 / p.FvK},
            {"a3", cell::a3},
            {"a4", cell::a4},
            {"b1", cell::b1},
            {"b2", p.b2},
            {"reduced_volume", p.v},
            {"area", 4.0 * M_PI},
            {"volume", cell::volume / (RA * RA * RA)},
            {"note", "lengths in R_A = sqrt(A0 / 4 pi), moduli in mu, kb = 1 / FvK, times in etam / mu "
                     "(membrane relaxation scale; docs/MEMBRANE_MODEL.md)"}};
}

nlohmann::json simulationJson(const CellParameters& p, double fextPn, int level, const ExperimentSet& which,
                              const SampleResult& s, double wallSeconds) {
    nlohmann::json j;
    j["parameters"] = simulationParametersJson(p, fextPn);
    nlohmann::json obs = {{"D_um", nullptr}, {"hmin_um", nullptr}, {"hmax_um", nullptr},
                          {"D0_um", nullptr}, {"D1_um", nullptr}, {"tc_s", nullptr}};
    nlohmann::json diag;
    diag["sfs"] = sfsJson(s.sfs);
    const ReferenceProtocolSteps ref = referenceProtocolSteps(p, level);
    // `evaluations` and `refSteps` sum the sample's experiments; the SFS joins the total only when
    // this run computed it.
    long evaluations = 0;
    double refSteps = 0.0;
    diag["sfs"]["reference_protocol_steps"] = ref.sfs;
    obs["D_um"] = s.equilibrium.observables.D;
    obs["hmin_um"] = s.equilibrium.observables.hmin;
    obs["hmax_um"] = s.equilibrium.observables.hmax;
    diag["equilibrium"] = staticSolverJson(s.equilibrium.diagnostics);
    diag["equilibrium"].update(equilibriumBranchJson(s.equilibrium));
    diag["equilibrium"]["reference_protocol_steps"] = ref.equilibrium;
    evaluations += s.equilibrium.diagnostics.evaluations;
    refSteps += ref.equilibrium;
    if (which.stretching) {
        obs["D0_um"] = s.stretching.front().observables.D0;
        obs["D1_um"] = s.stretching.front().observables.D1;
        diag["stretching"] = staticSolverJson(s.stretching.front().diagnostics);
        diag["stretching"]["reference_protocol_steps"] = ref.stretchPerForce;
        evaluations += s.stretching.front().diagnostics.evaluations;
        refSteps += ref.stretchPerForce;
        if (s.stretching.size() > 1) {
            nlohmann::json c = nlohmann::json::array();
            int curveEvaluations = 0;
            for (std::size_t k = 1; k < s.stretching.size(); ++k) {
                const auto& pt = s.stretching[k];
                c.push_back({{"Fext_pN", pt.fext}, {"D0_um", pt.observables.D0}, {"D1_um", pt.observables.D1},
                             {"force_evaluations", pt.diagnostics.evaluations}});
                curveEvaluations += pt.diagnostics.evaluations;
            }
            j["stretching_curve"] = c;
            diag["stretching_curve"] = {{"levels", s.stretching.size() - 1},
                                        {"force_evaluations", curveEvaluations},
                                        {"reference_protocol_steps", ref.stretchPerForce * (s.stretching.size() - 1)}};
        }
    }
    if (which.relaxation) {
        const RelaxationResult& r = s.relaxation;
        obs["tc_s"] = r.fit.tc;
        j["relaxation_fit"] = {{"law", "z = L/W (largest over second-largest extent; relaxation.csv); Hochmuth fit z(t) = zinf "
                                       "(Lambda + exp(-t/tc)) / (Lambda - exp(-t/tc)), Lambda = (z0 + zinf) / (z0 - zinf), z0 "
                                       "= z at the first sample of the fit, t0_s its time (the first sample after release); rms = "
                                       "root-mean-square residual of z"},
                               {"tc_s", r.fit.tc}, {"z0", r.fit.z0}, {"t0_s", r.fit.t0}, {"zinf", r.fit.zInf}, {"rms", r.fit.rms},
                               {"pre_stretch_force_pN", r.preStretchForce}};
        diag["relaxation"] = {{"pre_stretch", staticSolverJson(r.preStretch)},
                              {"converged", r.dynamics.converged},
                              {"time_steps", r.dynamics.iterations},
                              {"rejected_steps", r.rejectedSteps},
                              {"force_evaluations", r.dynamics.evaluations + r.preStretch.evaluations},
                              {"wall_s", r.dynamics.wallSeconds + r.preStretch.wallSeconds},
                              {"reference_protocol_steps", ref.preStretch + ref.relaxation}};
        evaluations += r.dynamics.evaluations + r.preStretch.evaluations;
        refSteps += ref.preStretch + ref.relaxation;
    }
    const bool sfsComputed = !s.sfs.fromCache;
    const auto cost = [](long e, double steps, double wall) {
        return nlohmann::json{{"force_evaluations", e},
                              {"reference_protocol_steps", steps},
                              {"reduction_factor", steps / std::max<long>(1, e)},
                              {"wall_s", wall}};
    };
    diag["sample"] = cost(evaluations, refSteps, std::max(0.0, wallSeconds - (sfsComputed ? s.sfs.wallSeconds : 0.0)));
    diag["total"] = cost(evaluations + (sfsComputed ? s.sfs.evaluations : 0), refSteps + (sfsComputed ? ref.sfs : 0.0), wallSeconds);
    j["status"] = "ok";
    j["observables"] = obs;
    j["diagnostics"] = diag;
    return j;
}

}  // namespace trbc
