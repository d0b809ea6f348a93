// trbc flow shear: one red cell in unbounded simple shear flow (VALIDATION.md 3), boundary-integral
// Stokes solver coupled to the membrane model (flow/cell_flow.hpp); prints one JSON object.
#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <numbers>

#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/version.hpp"
#include "flow/cell_flow.hpp"
#include "flow/shear_observables.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {
namespace {

constexpr double kPi = std::numbers::pi;

/// The paper's Table 1 (posterior of theta_new): means of v, mu, kb, b2, eta_m.
constexpr double kTable1V = 0.94, kTable1Mu = 4.99, kTable1KbJ = 2.10e-19, kTable1B2 = 1.84, kTable1Etam = 0.69;

nlohmann::json nullable(bool ok, double v) { return ok ? nlohmann::json(v) : nlohmann::json(nullptr); }

void writeText(const std::string& path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    if (!out) throw InputError("cannot write " + path);
}

void writeOutputs(const std::string& dir, const CellFlowModel& model, const ShearCell& cell, const CellFlowResult& r,
                  int vtkEvery, const nlohmann::json& j) {
    const double L = model.scales().length, T = model.scales().time, rate = model.conditions().shearRate;
    writeMesh(dir + "/reference_sfs.vtk", Mesh{cell.reference, cell.faces});
    writeMesh(dir + "/initial.vtk", Mesh{cell.initial, cell.faces});
    // Shapes over time (legacy VTK, one file per saved frame) and a ParaView collection.
    std::string pvd = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
    for (std::size_t k = 0; k < r.frames.size(); k += static_cast<std::size_t>(vtkEvery)) {
        const std::string name = fmt::format("shape_{:05d}.vtk", k);
        writeMesh(dir + "/" + name, Mesh{model.toMicrons(r.frames[k]), cell.faces});
        pvd += fmt::format("<DataSet timestep=\"{:.9g}\" file=\"{}\"/>\n", r.times[k] * T, name);
    }
    pvd += "</Collection>\n</VTKFile>\n";
    writeText(dir + "/shapes.pvd", pvd);
    // Time series per frame.
    const std::vector<double> phi = unwrappedOrientation(r.frames);
    std::string csv = "t_s,shear_strain,inclination_deg,orientation_unwrapped_deg,area_drift,volume_drift,cx_um,cy_um,cz_um\n";
    for (std::size_t k = 0; k < r.frames.size(); ++k) {
        const Eigen::Vector3d c = centroid(r.frames[k]) * L;
        csv += fmt::format("{:.9g},{:.9g},{:.9g},{:.9g},{:.6e},{:.6e},{:.9g},{:.9g},{:.9g}\n", r.times[k] * T,
                           r.times[k] * T * rate, inclinationAngle(r.frames[k]) * 180.0 / kPi, phi[k] * 180.0 / kPi,
                           r.areaDrift[k], r.volumeDrift[k], c.x(), c.y(), c.z());
    }
    writeText(dir + "/frames.csv", csv);
    const double tensionUnit = model.scales().force() / L;
    std::string steps = "t_s,dt_s,local_error_um,gmres_iterations,tension_pN_per_um,area_drift,volume_drift,"
                        "area_projection,volume_projection\n";
    for (const auto& s : r.stepLog)
        steps += fmt::format("{:.9g},{:.6e},{:.6e},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}\n", s.t * T, s.dt * T, s.error * L,
                             s.gmresIterations, s.tension * tensionUnit, s.areaDrift, s.volumeDrift, s.areaCorrection,
                             s.volumeCorrection);
    writeText(dir + "/steps.csv", steps);
    writeText(dir + "/flow.json", j.dump(2) + "\n");
}

void registerShear(CLI::App* flow) {
    struct Opts {
        double etaOut = std::nan(""), shearRate = std::nan(""), etaIn = 10.0;
        double v = kTable1V, mu = kTable1Mu, FvK = 0.0, kbJ = 0.0, b2 = kTable1B2, etam = kTable1Etam;
        int level = 3, threads = 0, vtkEvery = 10, maxSteps = 200000;
        double rotations = 10.0, tol = 1e-3, dt = 0.0, frameInterval = 0.1;
        std::string out;
        bool allowOutside = false;
        CacheOptions cache;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = flow->add_subcommand(
        "shear",
        "One red cell in unbounded simple shear flow u = (rate y, 0, 0) (VALIDATION.md 3): boundary-integral "
        "Stokes flow, membrane forces of MODEL.md C with membrane viscosity, semi-implicit adaptive BDF2. Prints "
        "regime, inclination angle, swinging amplitude and 4 pi f / rate as JSON. Without cell options the cell "
        "is the paper's Table 1 posterior means (v=0.94, mu=4.99 uN/m, kb=2.10e-19 J, b2=1.84, etam=0.69 Pa s um)");
    cmd->add_option("--eta-out", o->etaOut, "outer (suspending) viscosity, mPa s (> 0)")->required();
    cmd->add_option("--shear-rate", o->shearRate, "shear rate, 1/s (> 0)")->required();
    cmd->add_option("--eta-in", o->etaIn, "inner (cytosol) viscosity, mPa s (> 0)")->capture_default_str();
    auto* ov = cmd->add_option("--v", o->v, "reduced volume of the stress-free state, prior [0.65, 1]");
    auto* omu = cmd->add_option("--mu", o->mu, "shear modulus, uN/m, prior [1, 10]");
    auto* fvk = cmd->add_option("--FvK", o->FvK, "Foppl-von Karman number mu R_A^2 / kb, prior [10, 1000]");
    auto* okb = cmd->add_option("--kb", o->kbJ, "bending modulus, J, replaces --FvK; prior [1.074e-19, 1.074e-18]")
                    ->excludes(fvk);
    auto* ob2 = cmd->add_option("--b2", o->b2, "Lim non-linear shear coefficient, prior [0, 4]");
    auto* oetam = cmd->add_option("--etam", o->etam, "membrane viscosity, Pa s um, prior [0.1, 1]");
    cmd->add_option("--level", o->level, "icosphere level of the cell mesh (Nv = 10 4^L + 2)")
        ->check(CLI::Range(1, 5))->capture_default_str();
    cmd->add_option("--rotations", o->rotations, "duration in rigid-sphere turns, t_end = rotations 4 pi / rate")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--step-tol", o->tol, "local error per time step, largest vertex displacement in units of R_A")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--dt", o->dt, "fixed time step in units of 1/rate (disables the adaptive step control)")
        ->check(CLI::PositiveNumber);
    cmd->add_option("--max-steps", o->maxSteps, "limit on time-step attempts (the run fails beyond it)")
        ->check(CLI::Range(1, 100000000))->capture_default_str();
    cmd->add_option("--frame-interval", o->frameInterval, "interval of the saved frames, units of 1/rate")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--out", o->out, "directory for the shapes (VTK + shapes.pvd), frames.csv, steps.csv, flow.json");
    cmd->add_option("--vtk-every", o->vtkEvery, "write every k-th frame as VTK")
        ->check(CLI::Range(1, 1000000))->capture_default_str();
    cmd->add_flag("--allow-outside-prior", o->allowOutside, "accept cell parameters outside the prior box");
    cmd->add_option("--threads", o->threads, "OpenMP threads (0: OpenMP default)")->check(CLI::Range(0, 1024));
    addCacheOptions(cmd, o->cache);
    cmd->callback([o, ov, omu, okb, fvk, ob2, oetam]() {
        const auto tStart = std::chrono::steady_clock::now();
        FlowConditions fc;
        fc.etaOut = o->etaOut;
        fc.etaIn = o->etaIn;
        fc.shearRate = o->shearRate;
        if (!(fc.shearRate > 0.0) || !std::isfinite(fc.shearRate))
            throw InputError(fmt::format("parameter --shear-rate = {} 1/s: must be finite and > 0 (valid range (0, inf))",
                                         fc.shearRate));
        if (!(fc.etaOut > 0.0) || !std::isfinite(fc.etaOut))
            throw InputError(fmt::format("parameter --eta-out = {} mPa s: must be finite and > 0 (valid range (0, inf))",
                                         fc.etaOut));
        if (!(fc.etaIn > 0.0) || !std::isfinite(fc.etaIn))
            throw InputError(fmt::format("parameter --eta-in = {} mPa s: must be finite and > 0 (valid range (0, inf))",
                                         fc.etaIn));
        validateFlowConditions(fc);
        CellParameters p;
        p.v = o->v;
        p.mu = o->mu;
        p.b2 = o->b2;
        p.etam = o->etam;
        if (o->FvK != 0.0 || fvk->count() > 0) {
            p.FvK = o->FvK;
        } else {
            const double kb = okb->count() > 0 ? o->kbJ : kTable1KbJ;
            if (!(kb > 0.0) || !std::isfinite(kb))
                throw InputError(fmt::format("parameter --kb = {} J: must be positive (prior [1.074e-19, 1.074e-18] J)", kb));
            p.FvK = CellParameters::fvkFromKb(p.mu, kb);
        }
        validateCellParameters(p, o->allowOutside);
        const bool anyCell = ov->count() + omu->count() + okb->count() + fvk->count() + ob2->count() + oetam->count() > 0;
        if (!o->out.empty()) ensureWritableDirectory(o->out);
        if (o->threads > 0) omp_set_num_threads(o->threads);

        nlohmann::json j;
        j["parameters"] = {
            {"eta_out_mPa_s", fc.etaOut},
            {"eta_in_mPa_s", fc.etaIn},
            {"shear_rate_per_s", fc.shearRate},
            {"shear_stress_Pa", fc.etaOut * 1e-3 * fc.shearRate},
            {"cell",
             {{"v", p.v}, {"mu_uN_per_m", p.mu}, {"FvK", p.FvK}, {"kb_J", p.kbJoule()}, {"b2", p.b2},
              {"etam_Pa_s_um", p.etam}}},
            {"cell_source", anyCell ? "command line (options not given: the paper's Table 1 means)"
                                    : "the paper's Table 1 means of the theta_new posterior (no cell options given)"},
            {"area_volume", "exact constraints: area multiplier (membrane tension) in the coupled system, "
                            "projection onto A0, V0 after each step"},
            {"A0_um2", fc.A0},
            {"V0_um3", fc.V0},
            {"rotations", o->rotations},
            {"t_end_s", o->rotations * 4.0 * kPi / fc.shearRate}};
        j["provenance"] = {{"version", kVersion},
                           {"command", commandLine()},
                           {"level", o->level},
                           {"vertices", 10 * (1 << (2 * o->level)) + 2},
                           {"threads", omp_get_max_threads()},
                           {"sfs_model_version", kSfsModelVersion},
                           {"method", "boundary-integral Stokes (second kind, lambda != 1), membrane viscosity implicit, "
                                      "linearly implicit adaptive BDF2 (flow/cell_flow.hpp)"}};

        const ShearCell cell = prepareShearCell(p, o->level, cacheDirectory(o->cache));
        const CellFlowModel model(p, fc, cell.faces, cell.reference);
        const FlowGroups g = model.groups();
        j["parameters"]["dimensionless"] = {{"capillary_number", g.capillary},
                                            {"viscosity_ratio", g.viscosityRatio},
                                            {"membrane_viscosity_ratio_E", g.membraneViscosity},
                                            {"FvK", g.FvK}};
        CellFlowOptions opt;
        opt.tEnd = o->rotations * 4.0 * kPi;
        opt.frameInterval = o->frameInterval;
        opt.errorTolerance = o->tol;
        opt.maxSteps = o->maxSteps;
        if (o->dt > 0.0) {
            opt.adaptive = false;
            opt.dtInitial = o->dt;
            opt.dtMax = o->dt;
        }
        const double setupWall = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
        const CellFlowResult r = integrateCellFlow(model, model.toInternal(cell.initial), opt);

        const double T = model.scales().time;
        long gm = r.gmresIterations;
        nlohmann::json diag = {
            {"steps", r.steps},
            {"rejected_steps", r.rejectedSteps},
            {"failed_solves", r.failedSolves},
            {"gmres_iterations_total", gm},
            {"gmres_iterations_mean", r.steps > 0 ? static_cast<double>(gm) / (r.steps + r.rejectedSteps + r.failedSolves) : 0.0},
            {"gmres_iterations_max", r.maxGmresIterations},
            {"dt_min_s", r.dtSmallest * T},
            {"dt_max_s", r.dtLargest * T},
            {"dt_min_times_rate", r.dtSmallest},
            {"dt_max_times_rate", r.dtLargest},
            {"step_control", {{"scheme", "linearly implicit variable-step BDF2, error vs quadratic predictor"},
                              {"local_error_tolerance_R_A", opt.adaptive ? nlohmann::json(opt.errorTolerance) : nlohmann::json(nullptr)},
                              {"fixed_dt_times_rate", opt.adaptive ? nlohmann::json(nullptr) : nlohmann::json(o->dt)}}},
            {"area_drift_max", r.maxAreaDrift},
            {"volume_drift_max", r.maxVolumeDrift},
            {"area_projection_per_step_max", r.maxAreaCorrection},
            {"volume_projection_per_step_max", r.maxVolumeCorrection},
            {"area_projection_sum", r.sumAreaCorrection},
            {"volume_flux_correction_max_um_per_s", r.maxFluxCorrection * model.scales().length / model.scales().time},
            {"volume_projection_sum", r.sumVolumeCorrection},
            {"tension_final_pN_per_um", r.stepLog.empty() ? 0.0 : r.stepLog.back().tension * model.scales().force() / model.scales().length},
            {"area_drift_final", r.areaDrift.empty() ? 0.0 : r.areaDrift.back()},
            {"volume_drift_final", r.volumeDrift.empty() ? 0.0 : r.volumeDrift.back()},
            {"frames", r.times.size()},
            {"setup_wall_s", setupWall},
            {"flow_wall_s", r.wallSeconds},
            {"wall_s_per_rotation", r.tReached > 0 ? r.wallSeconds / (r.tReached / (4.0 * kPi)) : 0.0},
            {"equilibrium", {{"converged", cell.equilibrium.converged}, {"iterations", cell.equilibrium.iterations},
                             {"wall_s", cell.equilibrium.wallSeconds}}},
            {"sfs", sfsJson(cell.sfs)}};
        if (!r.completed) {
            diag["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
            j["status"] = "failed";
            j["reason"] = r.message;
            j["observables"] = {{"regime", nullptr}, {"inclination_deg", nullptr}, {"swing_amplitude_deg", nullptr},
                                {"ttf_4pi_f_over_shear_rate", nullptr}};
            j["diagnostics"] = diag;
            j["diagnostics"]["t_reached_s"] = r.tReached * T;
            std::cout << j.dump(2) << std::endl;
            if (!o->out.empty()) writeOutputs(o->out, model, cell, r, o->vtkEvery, j);
            throw NumericalError("flow shear: " + r.message);
        }
        const ShearObservables obs = analyzeShearFrames(r.times, r.frames, 1.0);
        const bool tt = obs.regime == ShearRegime::TankTreading;
        j["status"] = "ok";
        j["observables"] = {{"regime", regimeName(obs.regime)},
                            {"inclination_deg", nullable(tt, obs.inclinationDeg)},
                            {"swing_amplitude_deg", nullable(tt, obs.swingAmplitudeDeg)},
                            {"ttf_4pi_f_over_shear_rate", nullable(tt && obs.ttf.defined, obs.ttf4piFOverRate)}};
        j["analysis"] = {{"discarded_fraction", 0.25},
                         {"frames_used", obs.framesUsed},
                         {"angle_fit", {{"mean_deg", obs.angleFit.mean * 180.0 / kPi},
                                        {"amplitude_deg", obs.swingAmplitudeDeg},
                                        {"frequency_over_shear_rate", obs.swingFrequency},
                                        {"rms_deg", obs.angleFit.rms * 180.0 / kPi},
                                        {"converged", obs.angleFit.converged}}},
                         {"zero_crossing_4pi_f_over_shear_rate", nullable(obs.ttf.defined, obs.ttf4piFOverRate)},
                         {"zero_crossing_vertices", obs.ttf.vertices},
                         {"periodogram_4pi_f_over_shear_rate", obs.ttfFft4piFOverRate},
                         {"orientation_advance_deg", obs.orientationAdvance * 180.0 / kPi},
                         {"orientation_range_deg", obs.orientationRange * 180.0 / kPi},
                         {"membrane_advance_relative_to_shape_deg", obs.membraneAdvance * 180.0 / kPi},
                         {"membrane_advance_4pi_f_over_shear_rate", obs.membraneAdvance4piFOverRate}};
        diag["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
        j["diagnostics"] = diag;
        if (!o->out.empty()) writeOutputs(o->out, model, cell, r, o->vtkEvery, j);
        std::cout << j.dump(2) << std::endl;
    });
}

}  // namespace

void registerFlow(CLI::App& app) {
    CLI::App* flow = app.add_subcommand("flow", "Flow validations (VALIDATION.md): one cell in simple shear flow");
    flow->require_subcommand(1);
    registerShear(flow);
}

}  // namespace trbc::cli
