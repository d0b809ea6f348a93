// trbc flow shear|tube: one red cell in unbounded simple shear flow or in a microtube (docs/FLOW.md).
// The protocols are library calls (flow/shear_case.hpp, flow/tube_case.hpp); this file parses the
// options, prints the progress and writes the JSON, CSV and VTK outputs of their results.
#include <fmt/format.h>
#include <omp.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>

#include "analysis/validation_draws.hpp"
#include "cli/common.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "flow/shear_case.hpp"
#include "flow/tube_case.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {
namespace {

constexpr double kPi = std::numbers::pi;

nlohmann::json nullable(bool ok, double v) { return ok ? nlohmann::json(v) : nlohmann::json(nullptr); }

void writeText(const std::string& path, const std::string& text) { writeFileAtomically(path, text); }

/// The command-line name of each option the library names in its messages (flow/flow_case.hpp).
std::string cliOptionName(const std::string& name) {
    static const std::map<std::string, std::string> names = {
        {"eta_out_mPa_s", "--eta-out"}, {"eta_in_mPa_s", "--eta-in"}, {"shear_rate_per_s", "--shear-rate"},
        {"level", "--level"}, {"rotations", "--rotations"}, {"tilt_deg", "--tilt-deg"}, {"radius_um", "--radius"},
        {"pressure_gradient_mmHg_per_mm", "--pressure-gradient"}, {"viscosity_ratio", "--viscosity-ratio"},
        {"duration_R_over_V", "--duration"}, {"settle_R_over_V", "--settle"}, {"settle_relax_R_over_V", "--settle-relax"},
        {"settle_etam_Pa_s_um", "--settle-etam"}, {"settle_tol", "--settle-tol"}, {"wall_points", "--wall-points"},
        {"tube_length_um", "--tube-length"}, {"repulsion_range_um", "--repulsion-range"},
        {"repulsion_pressure", "--repulsion-pressure"}, {"frame_interval", "--frame-interval"}, {"step_tol", "--step-tol"}, {"gmres_tol", "--gmres-tol"},
        {"dt", "--dt"}, {"max_steps", "--max-steps"}, {"checkpoint_interval", "--checkpoint-interval"},
        {"resume", "--resume"}, {"rates", "--rates"}, {"temperature_K", "--temperature"},
        {"kick_temperature_K", "--kick-temperature"}, {"thermal_step", "--thermal-step"}};
    const auto it = names.find(name);
    return it == names.end() ? name : it->second;
}

// ---- the cell ----------------------------------------------------------------------------------

/// The cell options shared by `flow shear` and `flow tube` (defaults: the paper's Table 1 means).
struct CellOptions {
    double v = table1::v, mu = table1::mu, FvK = 0.0, kbJ = 0.0, b2 = table1::b2, etam = table1::etam;
    bool allowOutside = false;
    std::string posterior;
    CLI::Option *ov = nullptr, *omu = nullptr, *fvk = nullptr, *okb = nullptr, *ob2 = nullptr, *oetam = nullptr,
                *opost = nullptr;
};

void addCellOptions(CLI::App* cmd, CellOptions& c) {
    c.ov = addNumber(cmd, "--v", c.v, "reduced volume of the stress-free state, prior [0.65, 1]", NumberRange::leftOpen(0.0, 1.0));
    c.omu = addNumber(cmd, "--mu", c.mu, "shear modulus, prior [1, 10] uN/m", NumberRange::positive("uN/m"));
    c.fvk = addNumber(cmd, "--FvK", c.FvK, "Foppl-von Karman number mu R_A^2 / kb, prior [10, 1000]", NumberRange::positive());
    c.okb = addNumber(cmd, "--kb", c.kbJ, "bending modulus, replaces --FvK; prior [1.074e-19, 1.074e-18] J", NumberRange::positive("J"))
                ->excludes(c.fvk);
    c.ob2 = addNumber(cmd, "--b2", c.b2, "Lim non-linear shear coefficient, prior [0, 4]", NumberRange::nonNegative());
    c.oetam = addNumber(cmd, "--etam", c.etam, "membrane viscosity, prior [0.1, 1] Pa s um", NumberRange::positive("Pa s um"));
    cmd->add_flag("--allow-outside-prior", c.allowOutside, "accept cell parameters outside the prior box");
    c.opost = cmd->add_option("--posterior", c.posterior,
                              "take the cell from a theta_new posterior (DIR/phase3/theta_new of `trbc infer`, or its "
                              "samples.csv): the means of v, mu, kb, b2 and etam (docs/FLOW.md)");
    for (CLI::Option* opt : {c.ov, c.omu, c.fvk, c.okb, c.ob2, c.oetam}) c.opost->excludes(opt);
}

/// The cell parameters of the options (kb -> FvK, a given kb checked against its prior); the
/// flow cases check the rest.
CellParameters cellParameters(const CellOptions& c) {
    CellParameters p;
    if (c.opost->count() > 0) {
        const NumericTable t = readThetaNewSamples(c.posterior);
        p.v = t.column("v").mean();
        p.mu = t.column("mu_uN_per_m").mean();
        p.FvK = CellParameters::fvkFromKb(p.mu, t.column("kb_J").mean());
        p.b2 = t.column("b2").mean();
        p.etam = t.column("etam_Pa_s_um").mean();
        return p;
    }
    p.v = c.v;
    p.mu = c.mu;
    p.b2 = c.b2;
    p.etam = c.etam;
    if (c.FvK != 0.0 || c.fvk->count() > 0) {
        p.FvK = c.FvK;
    } else {
        const double kb = c.okb->count() > 0 ? c.kbJ : table1::kbJ;
        validateBendingModulus(kb, c.allowOutside);
        p.FvK = CellParameters::fvkFromKb(p.mu, kb);
    }
    return p;
}

nlohmann::json cellJson(const CellParameters& p) {
    return {{"v", p.v}, {"mu_uN_per_m", p.mu}, {"FvK", p.FvK}, {"kb_J", p.kbJoule()}, {"b2", p.b2},
            {"etam_Pa_s_um", p.etam}};
}

std::string cellSource(const CellOptions& c) {
    if (c.opost->count() > 0) return "means of the theta_new posterior " + std::filesystem::absolute(c.posterior).lexically_normal().string();
    const bool any = c.ov->count() + c.omu->count() + c.okb->count() + c.fvk->count() + c.ob2->count() +
                         c.oetam->count() > 0;
    return any ? "command line (options not given: the paper's Table 1 means)"
               : "the paper's Table 1 means of the theta_new posterior (no cell options given)";
}

// ---- stepping, progress, snapshots -------------------------------------------------------------

/// The stepping options of the library plus the command's own: threads, VTK frames, output directory.
struct SteppingOptions {
    FlowCaseStepping step;
    int threads = 0, vtkEvery = 10;
    std::string out;
};

void addSteppingOptions(CLI::App* cmd, SteppingOptions& s, const std::string& unit) {
    addNumber(cmd, "--frame-interval", s.step.frameInterval, "interval of the saved frames (duration / interval at most 1e7 frames, and their positions at most 4 GiB)",
              NumberRange::leftOpen(0.0, 1e6, unit))
        ->capture_default_str();
    addNumber(cmd, "--step-tol", s.step.stepTolerance, "local error per time step, largest vertex displacement",
              NumberRange::leftOpen(0.0, 1.0, "R_A"))
        ->capture_default_str();
    addNumber(cmd, "--gmres-tol", s.step.gmresTolerance,
              "relative residual of each step's linear solve; 0: a tenth of --step-tol, at most 1e-4 (1e-6 with --dt)",
              NumberRange::closed(0.0, 0.5))
        ->capture_default_str();
    addNumber(cmd, "--dt", s.step.dt, "fixed time step (disables the adaptive step control)", NumberRange::leftOpen(0.0, 100.0, unit));
    addNumber(cmd, "--max-steps", s.step.maxSteps, "limit on time-step attempts (the run fails beyond it)", NumberRange::closed(1, 1e8))
        ->capture_default_str();
    addOutOption(cmd, s.out, "directory for the shapes (VTK + shapes.pvd), frames.csv, steps.csv, flow.json", false);
    addNumber(cmd, "--vtk-every", s.vtkEvery, "write every k-th frame as VTK", NumberRange::closed(1, 1e6))->capture_default_str();
    addThreadsOption(cmd, s.threads, "OpenMP threads (0: OpenMP default)", 0);
    cmd->add_flag("--resume", s.step.resume,
                  "continue a killed run from its snapshots in OUT/checkpoint/ (same command; a snapshot of another "
                  "run or a damaged one is ignored and the run starts afresh); needs --out");
    addNumber(cmd, "--checkpoint-interval", s.step.checkpointInterval,
              "wall time between snapshots in OUT/checkpoint/ (0: after every step; removed when the run has written its outputs)",
              NumberRange::closed(0.0, 1e7, "s"))
        ->capture_default_str();
}

// Progress on stderr at every tenth of each stage's simulated duration (at frame times):
// simulated time, wall time and the ETA from the mean rate since the stage's first frame seen
// (t = 0, or the first frame after a resumed snapshot), plus what `detail` says about the shape.
std::function<void(const FlowCaseProgress&)> progressPrinter(const std::string& command, const std::string& unit,
                                                             std::function<std::string(const Vertices&)> detail) {
    struct Stage {
        std::string name;
        double next = 0.0, tFirst = -1.0, wallFirst = 0.0;
    };
    auto now = std::make_shared<Stage>();
    return [=](const FlowCaseProgress& p) {
        Stage& s = *now;
        if (s.name != p.stage) s = Stage{std::string(p.stage), 0.1 * p.tEnd};
        if (s.tFirst < 0.0) {
            s.tFirst = p.t;
            s.wallFirst = p.wallSeconds;
        }
        if (p.t + 1e-9 < s.next) return;
        while (s.next <= p.t + 1e-9) s.next += 0.1 * p.tEnd;
        const std::string eta = p.t > s.tFirst
                                    ? fmt::format("{:.0f} s", (p.wallSeconds - s.wallFirst) * (p.tEnd - p.t) / (p.t - s.tFirst))
                                    : std::string("?");
        std::cerr << fmt::format("{}{}: t = {:.4g} of {:.4g} {}, {}wall {:.1f} s, ETA {}\n", command,
                                 p.stage == "settling" ? " (settling)" : "", p.t, p.tEnd, unit,
                                 detail ? detail(p.shapeUm) + ", " : std::string(), p.wallSeconds, eta);
    };
}

/// The library's stepping options of the command line: snapshots in OUT/checkpoint, progress
/// and snapshot notes on stderr, messages naming the command-line options.
void configureStepping(SteppingOptions& s, const std::string& command, const std::string& unit,
                       std::function<std::string(const Vertices&)> detail) {
    if (s.step.resume && s.out.empty())
        throw InputError("option --resume: continues from the snapshots in --out DIR/checkpoint; give --out");
    if (!s.out.empty()) s.step.checkpointDirectory = std::filesystem::path(s.out) / "checkpoint";
    s.step.progress = progressPrinter(command, unit, std::move(detail));
    s.step.checkpointLog = [](const std::string& what) { std::cerr << "flow: " << what << "\n"; };
    s.step.optionName = cliOptionName;
}

/// Prepares the output directory and sets the thread count (after the options are checked).
void applySteppingOptions(const SteppingOptions& s) {
    if (!s.out.empty()) ensureWritableDirectory(s.out);
    if (s.threads > 0) omp_set_num_threads(s.threads);
}

/// The snapshots are dropped once the outputs they would rebuild are written.
void removeCheckpoints(const SteppingOptions& s) {
    if (s.out.empty()) return;
    std::error_code ec;
    std::filesystem::remove_all(std::filesystem::path(s.out) / "checkpoint", ec);
}

nlohmann::json checkpointJson(const CellFlowResult& r, double timeUnit) {
    return {{"resumes", r.resumes}, {"resumed_at_s", r.resumes > 0 ? nlohmann::json(r.resumedAt * timeUnit) : nlohmann::json(nullptr)}};
}

nlohmann::json provenanceJson(int level, const char* method) {
    return withBuild({{"command", commandLine()},
                      {"level", level},
                      {"vertices", 10 * (1 << (2 * level)) + 2},
                      {"threads", omp_get_max_threads()},
                      {"sfs_model_version", kSfsModelVersion},
                      {"method", method}});
}

// ---- outputs shared by both flows --------------------------------------------------------------

/// The diagnostics of the time stepping that do not depend on the flow's time unit.
nlohmann::json stepDiagnostics(const FlowScales& scales, const CellFlowResult& r, const ShearCell& cell) {
    const long gm = r.gmresIterations;
    const double L = scales.length, T = scales.time;
    return {
        {"steps", r.steps},
        {"rejected_steps", r.rejectedSteps},
        {"failed_solves", r.failedSolves},
        {"gmres_iterations_total", gm},
        {"gmres_iterations_mean",
         r.steps > 0 ? static_cast<double>(gm) / (r.steps + r.rejectedSteps + r.failedSolves) : 0.0},
        {"gmres_iterations_max", r.maxGmresIterations},
        {"dt_min_s", r.dtSmallest * T},
        {"dt_max_s", r.dtLargest * T},
        {"area_drift_max", r.maxAreaDrift},
        {"volume_drift_max", r.maxVolumeDrift},
        {"area_projection_per_step_max", r.maxAreaCorrection},
        {"volume_projection_per_step_max", r.maxVolumeCorrection},
        {"area_projection_sum", r.sumAreaCorrection},
        {"volume_flux_correction_max_um_per_s", r.maxFluxCorrection * L / T},
        {"volume_projection_sum", r.sumVolumeCorrection},
        {"tension_final_pN_per_um", r.stepLog.empty() ? 0.0 : r.stepLog.back().tension * scales.force() / L},
        {"area_drift_final", r.areaDrift.empty() ? 0.0 : r.areaDrift.back()},
        {"volume_drift_final", r.volumeDrift.empty() ? 0.0 : r.volumeDrift.back()},
        {"frames", r.times.size()},
        {"flow_wall_s", r.wallSeconds},
        {"equilibrium", {{"converged", cell.equilibrium.converged}, {"iterations", cell.equilibrium.iterations},
                         {"wall_s", cell.equilibrium.wallSeconds}}},
        {"sfs", sfsJson(cell.sfs)}};
}

nlohmann::json stepControlJson(const CellFlowOptions& opt, double fixedDt, const char* fixedDtName) {
    return {{"scheme", "linearly implicit variable-step BDF2, error vs quadratic predictor"},
            {"local_error_tolerance_R_A", opt.adaptive ? nlohmann::json(opt.errorTolerance) : nlohmann::json(nullptr)},
            {fixedDtName, opt.adaptive ? nlohmann::json(nullptr) : nlohmann::json(fixedDt)},
            {"gmres_tolerance", effectiveGmresTolerance(opt)},
            {"far_sum", opt.quadrature.singlePrecisionFar ? "single precision" : "double precision"}};
}

/// reference_sfs.vtk, initial.vtk, shape_NNNNN.vtk (every vtkEvery-th frame) + shapes.pvd, steps.csv.
void writeShapesAndSteps(const std::string& dir, const FlowScales& scales, const ShearCell& cell, const Vertices& initial,
                         const CellFlowResult& r, int vtkEvery) {
    const double L = scales.length, T = scales.time;
    writeMesh(dir + "/reference_sfs.vtk", Mesh{cell.reference, cell.faces});
    writeMesh(dir + "/initial.vtk", Mesh{initial, cell.faces});
    // Shapes over time (legacy VTK, one file per saved frame) and a ParaView collection.
    std::string pvd = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
    for (std::size_t k = 0; k < r.frames.size(); k += static_cast<std::size_t>(vtkEvery)) {
        const std::string name = fmt::format("shape_{:05d}.vtk", k);
        writeMesh(dir + "/" + name, Mesh{r.frames[k] * L, cell.faces});
        pvd += fmt::format("<DataSet timestep=\"{:.9g}\" file=\"{}\"/>\n", r.times[k] * T, name);
    }
    pvd += "</Collection>\n</VTKFile>\n";
    writeText(dir + "/shapes.pvd", pvd);
    const double tensionUnit = scales.force() / L;
    std::string steps = csvProvenance() + "t_s,dt_s,local_error_um,gmres_iterations,tension_pN_per_um,area_drift,volume_drift,"
                        "area_projection,volume_projection\n";
    for (const auto& s : r.stepLog)
        steps += fmt::format("{:.9g},{:.6e},{:.6e},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}\n", s.t * T, s.dt * T, s.error * L,
                             s.gmresIterations, s.tension * tensionUnit, s.areaDrift, s.volumeDrift, s.areaCorrection,
                             s.volumeCorrection);
    writeText(dir + "/steps.csv", steps);
}

// ---- flow shear --------------------------------------------------------------------------------

struct ShearCli {
    ShearCaseOptions c;
    std::string start = "in-plane";
    CellOptions cell;
    SteppingOptions step;
    CacheOptions cache;
};

/// Shapes, steps.csv, frames.csv (per frame: time, strain, inclination, unwrapped orientation,
/// drift, centroid) and flow.json.
void writeShearOutputs(const std::string& dir, const ShearCaseResult& res, int vtkEvery, const nlohmann::json& j) {
    writeShapesAndSteps(dir, res.scales, res.prepared, res.prepared.initial, res.flow, vtkEvery);
    const ShearFrameSeries& s = res.series;
    std::string csv = csvProvenance() + "t_s,shear_strain,inclination_deg,orientation_unwrapped_deg,area_drift,volume_drift,cx_um,cy_um,cz_um\n";
    for (std::size_t k = 0; k < s.time.size(); ++k) {
        const Eigen::Vector3d c = s.centroidUm.col(static_cast<Eigen::Index>(k));
        csv += fmt::format("{:.9g},{:.9g},{:.9g},{:.9g},{:.6e},{:.6e},{:.9g},{:.9g},{:.9g}\n", s.time[k], s.shearStrain[k],
                           s.inclinationDeg[k], s.orientationDeg[k], s.areaDrift[k], s.volumeDrift[k], c.x(), c.y(), c.z());
    }
    writeText(dir + "/frames.csv", csv);
    writeText(dir + "/flow.json", j.dump(2) + "\n");
}

nlohmann::json shearParametersJson(const ShearCaseResult& res, const ShearCli& o) {
    const FlowConditions& fc = res.conditions;
    const FlowGroups& g = res.groups;
    return {{"eta_out_mPa_s", fc.etaOut},
            {"eta_in_mPa_s", fc.etaIn},
            {"shear_rate_per_s", fc.shearRate},
            {"shear_stress_Pa", shearStressPa(fc.etaOut, fc.shearRate)},
            {"cell", cellJson(res.cell)},
            {"cell_source", cellSource(o.cell)},
            {"area_volume", "exact constraints: area multiplier (membrane tension) in the coupled system, "
                            "projection onto A0, V0 after each step"},
            {"A0_um2", fc.A0},
            {"V0_um3", fc.V0},
            {"rotations", o.c.rotations},
            {"tilt_deg", o.c.tiltDeg},
            {"start", o.start},
            {"kick_temperature_K", o.start == "random" ? nlohmann::json(o.c.kickTemperatureK) : nlohmann::json(nullptr)},
            {"temperature_K", o.c.temperatureK},
            {"thermal_step_times_rate", o.c.temperatureK > 0.0 ? nlohmann::json(o.c.thermalStep) : nlohmann::json(nullptr)},
            {"seed", o.c.seed},
            {"stop_when_steady", o.c.stopWhenSteady},
            {"t_end_s", res.tEndSeconds},
            {"dimensionless", {{"capillary_number", g.capillary},
                               {"viscosity_ratio", g.viscosityRatio},
                               {"membrane_viscosity_ratio_E", g.membraneViscosity},
                               {"FvK", g.FvK}}}};
}

nlohmann::json shearDiagnosticsJson(const ShearCaseResult& res, const ShearCli& o) {
    const CellFlowResult& r = res.flow;
    nlohmann::json diag = stepDiagnostics(res.scales, r, res.prepared);
    diag["dt_min_times_rate"] = r.dtSmallest;
    diag["dt_max_times_rate"] = r.dtLargest;
    diag["stopped_when_steady"] = r.stoppedEarly;
    diag["rotations_run"] = r.tReached / (4.0 * kPi);
    if (res.integrator.thermal.kT > 0.0)
        diag["thermal"] = {{"kT_internal", res.integrator.thermal.kT},
                           {"lanczos_iterations_per_step", r.steps ? double(r.sqrtIterations) / r.steps : 0.0},
                           {"lanczos_iterations_max", r.maxSqrtIterations},
                           {"mobility_gmres_iterations_per_step", r.steps ? double(r.mobilityIterations) / r.steps : 0.0}};
    diag["step_control"] = stepControlJson(res.integrator, o.step.step.dt, "fixed_dt_times_rate");
    diag["setup_wall_s"] = res.setupWallSeconds;
    diag["wall_s_per_rotation"] = r.tReached > 0 ? r.wallSeconds / (r.tReached / (4.0 * kPi)) : 0.0;
    diag["checkpoint"] = checkpointJson(r, res.scales.time);
    diag["wall_s"] = res.wallSeconds;
    if (!res.completed) diag["t_reached_s"] = r.tReached * res.scales.time;
    return diag;
}

void addShearObservables(nlohmann::json& j, const ShearObservables& obs) {
    const bool tt = obs.regime == ShearRegime::TankTreading;
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
}

void finishShearOptions(ShearCli& o, const std::string& command);

void runShear(ShearCli& o) {
    finishShearOptions(o, "flow shear");
    validateShearCaseOptions(o.c);
    applySteppingOptions(o.step);
    const ShearCaseResult res = runShearCase(o.c);

    nlohmann::json j;
    j["parameters"] = shearParametersJson(res, o);
    j["provenance"] = provenanceJson(o.c.level, "boundary-integral Stokes (second kind, lambda != 1), membrane viscosity "
                                                "implicit, linearly implicit adaptive BDF2 (flow/cell_flow.hpp)");
    j["diagnostics"] = shearDiagnosticsJson(res, o);
    if (!res.completed) {
        j["status"] = "failed";
        j["reason"] = res.message;
        j["observables"] = {{"regime", nullptr}, {"inclination_deg", nullptr}, {"swing_amplitude_deg", nullptr},
                            {"ttf_4pi_f_over_shear_rate", nullptr}};
        std::cout << j.dump(2) << std::endl;
        if (!o.step.out.empty()) writeShearOutputs(o.step.out, res, o.step.vtkEvery, j);
        removeCheckpoints(o.step);  // a resume would only repeat the failure
        throw NumericalError("flow shear: " + res.message);
    }
    j["status"] = "ok";
    addShearObservables(j, *res.observables);
    if (!o.step.out.empty()) writeShearOutputs(o.step.out, res, o.step.vtkEvery, j);
    removeCheckpoints(o.step);
    std::cout << j.dump(2) << std::endl;
}

/// The options that `flow shear` and `flow ramp` share: the fluid, the cell, the mesh, the start,
/// the fluctuations, the stepping and the cache.
void addShearOptions(CLI::App* cmd, ShearCli& o) {
    addNumber(cmd, "--eta-out", o.c.etaOut, "outer (suspending) viscosity", NumberRange::leftOpen(0.0, 1e6, "mPa s"))->required();
    addNumber(cmd, "--eta-in", o.c.etaIn, "inner (cytosol) viscosity", NumberRange::leftOpen(0.0, 1e6, "mPa s"))->capture_default_str();
    addCellOptions(cmd, o.cell);
    addNumber(cmd, "--level", o.c.level, "icosphere level of the cell mesh (Nv = 10 4^L + 2)", NumberRange::closed(1, 5))
        ->capture_default_str();
    addNumber(cmd, "--tilt-deg", o.c.tiltDeg,
              "start turned by this angle about the flow (x) axis, out of the shear plane (the in-plane start, 0, "
              "stays mirror symmetric about that plane and cannot leave it; docs/FLOW.md)",
              NumberRange::closed(0.0, 90.0, "deg"))
        ->capture_default_str();
    addNumber(cmd, "--temperature", o.c.temperatureK,
              "thermal fluctuations of the membrane and both fluids during the run, at this temperature (fixed steps "
              "of --thermal-step; docs/FLOW_THERMAL.md); 0: none",
              NumberRange::closed(0.0, 400.0, "K"))
        ->capture_default_str();
    addNumber(cmd, "--thermal-step", o.c.thermalStep, "fixed time step of a run with --temperature",
              NumberRange::leftOpen(0.0, 1.0, "1/rate"))
        ->capture_default_str();
    cmd->add_option("--start", o.start,
                    "in-plane: the equilibrium disc with its axis along the gradient (turned by --tilt-deg); random: "
                    "that shape at a uniformly random orientation with the thermal l = 2, 3 undulations at "
                    "--kick-temperature, from --seed (one member of the ensemble protocol, docs/FLOW_THERMAL.md)")
        ->check(CLI::IsMember({"in-plane", "random"}))
        ->capture_default_str();
    addNumber(cmd, "--kick-temperature", o.c.kickTemperatureK, "temperature of the undulations of --start random",
              NumberRange::closed(0.0, 400.0, "K"))
        ->capture_default_str();
    addNumber(cmd, "--seed", o.c.seed, "seed of --start random and of the thermal noise of --temperature",
              NumberRange::nonNegative())
        ->capture_default_str();
    addSteppingOptions(cmd, o.step, "1/rate");
    addCacheOptions(cmd, o.cache);
}

/// The library options from the command line's (shared by shear and ramp).
void finishShearOptions(ShearCli& o, const std::string& command) {
    o.c.cell = cellParameters(o.cell);
    o.c.allowOutsidePrior = o.cell.allowOutside;
    o.c.randomStart = o.start == "random";
    setProvenanceSeed(o.c.seed);
    o.c.cacheDir = cacheDirectory(o.cache);
    configureStepping(o.step, command, "/rate", {});
    o.c.step = o.step.step;
}

void registerShear(CLI::App* flow) {
    auto o = std::make_shared<ShearCli>();
    CLI::App* cmd = flow->add_subcommand(
        "shear",
        "One red cell in unbounded simple shear flow u = (rate y, 0, 0) (docs/FLOW.md, shear): boundary-integral "
        "Stokes flow, membrane forces of docs/MEMBRANE_MODEL.md with membrane viscosity, semi-implicit adaptive BDF2. Prints "
        "regime, inclination angle, swinging amplitude and 4 pi f / rate as JSON. Without cell options the cell "
        "is the paper's Table 1 posterior means (v=0.94, mu=4.99 uN/m, kb=2.10e-19 J, b2=1.84, etam=0.69 Pa s um)");
    addNumber(cmd, "--shear-rate", o->c.shearRate, "shear rate", NumberRange::leftOpen(0.0, 1e6, "1/s"))->required();
    addNumber(cmd, "--rotations", o->c.rotations, "duration in rigid-sphere turns, t_end = rotations 4 pi / rate",
              NumberRange::leftOpen(0.0, 1000.0))
        ->capture_default_str();
    cmd->add_flag("--stop-when-steady", o->c.stopWhenSteady,
                  "stop at the first whole turn (from the 4th) where the observables of the frames so far and of those one turn "
                  "earlier agree: both tumbling, or tank-treading with angle and swing within 0.1 deg and TTF within 0.5 % "
                  "(docs/FLOW.md, steady-state stop); --rotations stays the longest duration");
    addShearOptions(cmd, *o);
    cmd->callback([o]() { runShear(*o); });
}

// ---- flow ramp ---------------------------------------------------------------------------------

struct RampCli {
    ShearCli s;
    std::vector<double> rates;
};

void runRamp(RampCli& o) {
    finishShearOptions(o.s, "flow ramp");
    ShearRampOptions r{o.s.c, o.rates};
    r.base.shearRate = o.rates.empty() ? 1.0 : o.rates.front();
    applySteppingOptions(o.s.step);
    const ShearRampResult res = runShearRamp(r);
    nlohmann::json stages = nlohmann::json::array();
    for (const ShearRampStage& st : res.stages) {
        nlohmann::json e{{"shear_rate_per_s", st.shearRate},
                         {"shear_stress_Pa", shearStressPa(o.s.c.etaOut, st.shearRate)},
                         {"direction", st.up ? "up" : "down"},
                         {"status", st.completed ? "ok" : "failed"},
                         {"turns", st.turns},
                         {"stopped_when_steady", st.stoppedWhenSteady},
                         {"wall_s", st.wallSeconds}};
        if (!st.completed) e["reason"] = st.message;
        if (st.observables) addShearObservables(e, *st.observables);
        e.erase("analysis");
        stages.push_back(e);
    }
    const auto bracket = [&](const std::optional<std::pair<double, double>>& b) {
        return b ? nlohmann::json{b->first, b->second} : nlohmann::json(nullptr);
    };
    nlohmann::json j;
    j["parameters"] = {{"eta_out_mPa_s", o.s.c.etaOut},   {"eta_in_mPa_s", o.s.c.etaIn},       {"rates_per_s", o.rates},
                       {"cell", cellJson(o.s.c.cell)},      {"cell_source", cellSource(o.s.cell)}, {"level", o.s.c.level},
                       {"rotations_per_stage", o.s.c.rotations}, {"tilt_deg", o.s.c.tiltDeg},     {"start", o.s.start},
                       {"temperature_K", o.s.c.temperatureK}, {"seed", o.s.c.seed}, {"stop_when_steady", o.s.c.stopWhenSteady}};
    j["provenance"] = provenanceJson(o.s.c.level, "the shear rate stepped up and down, each stage from the last stage's "
                                                  "shape (flow/shear_case.hpp, runShearRamp)");
    j["stages"] = stages;
    j["summary"] = {{"completed", res.completed},
                    {"up_onset_bracket_per_s", bracket(res.upBracket)},
                    {"down_end_bracket_per_s", bracket(res.downBracket)},
                    {"hysteresis", res.upBracket && res.downBracket && *res.upBracket != *res.downBracket},
                    {"wall_s", res.wallSeconds}};
    if (!o.s.step.out.empty()) writeText(o.s.step.out + "/ramp.json", j.dump(2) + "\n");
    removeCheckpoints(o.s.step);
    std::cout << j.dump(2) << std::endl;
    if (!res.completed) throw NumericalError("flow ramp: " + res.stages.back().message);
}

void registerRamp(CLI::App* flow) {
    auto o = std::make_shared<RampCli>();
    o->s.c.rotations = 10.0;
    CLI::App* cmd = flow->add_subcommand(
        "ramp",
        "One red cell in simple shear with the shear rate stepped up through --rates and back down, each stage "
        "--rotations rigid-sphere turns from the shape where the last ended (the ramp protocol, docs/FLOW_THERMAL.md). "
        "Prints each stage's regime and angle and the rates where tank-treading begins going up and ends going down");
    cmd->add_option("--rates", o->rates, "shear rates, strictly increasing (comma-separated), 1/s")
        ->delimiter(',')
        ->required();
    addNumber(cmd, "--rotations", o->s.c.rotations, "duration of each stage in rigid-sphere turns 4 pi / rate",
              NumberRange::leftOpen(0.0, 1000.0))
        ->capture_default_str();
    cmd->add_flag("--stop-when-steady", o->s.c.stopWhenSteady,
                  "end each stage at the steady state (as `flow shear --stop-when-steady`); --rotations stays its longest duration");
    addShearOptions(cmd, o->s);
    cmd->callback([o]() { runRamp(*o); });
}

// ---- flow tube ---------------------------------------------------------------------------------

struct TubeCli {
    TubeCaseOptions c;
    CellOptions cell;
    double settleEtam = 0.0;  // used when given: replaces --settle-relax
    CLI::Option* settleEtamOption = nullptr;
    SteppingOptions step = [] {
        SteppingOptions s;
        s.step = TubeCaseOptions::tubeStepping();
        return s;
    }();
    CacheOptions cache;
};

/// The tube, the fluid and the durations.
void addTubeFlowOptions(CLI::App* cmd, TubeCli& o) {
    // A closed surface of area A0 inside a tube of radius R encloses at most R A0 / 2 - 2 pi R^3 / 3
    // (the capsule of radius R), which must be >= V0: R >= minimumTubeRadius(A0, V0).
    const FlowConditions cellSize;
    addNumber(cmd, "--radius", o.c.radius,
              fmt::format("tube radius R (from the smallest radius whose capsule holds the cell's area {} um^2 and volume {} um^3)",
                          cellSize.A0, cellSize.V0),
              NumberRange::closed(std::ceil(minimumTubeRadius(cellSize.A0, cellSize.V0) * 1e4) / 1e4, 100.0, "um"))
        ->required();
    addNumber(cmd, "--pressure-gradient", o.c.pressureGradient, "pressure gradient (1 mmHg/mm = 1.33322e5 Pa/m)",
              NumberRange::leftOpen(0.0, 1e4, "mmHg/mm"))
        ->required();
    addNumber(cmd, "--eta-out", o.c.etaOut, "viscosity of the suspending fluid", NumberRange::leftOpen(0.0, 1e6, "mPa s"))
        ->capture_default_str();
    addNumber(cmd, "--viscosity-ratio", o.c.viscosityRatio, "cytosol / outer viscosity; the tube solver supports 1 only",
              NumberRange::closed(1.0, 1.0))
        ->capture_default_str();
    addCellOptions(cmd, o.cell);
    addNumber(cmd, "--level", o.c.level, "icosphere level of the cell mesh (Nv = 10 4^L + 2)", NumberRange::closed(1, 4))
        ->capture_default_str();
    addNumber(cmd, "--duration", o.c.duration, "simulated time of the main run (after --settle)", NumberRange::leftOpen(0.0, 1e4, "R/V"))
        ->capture_default_str();
}

void addSettlingOptions(CLI::App* cmd, TubeCli& o) {
    addNumber(cmd, "--settle", o.c.settle,
              "longest settling stage before the main run, R/V (0: none, else >= 10): the cell with the small "
              "membrane viscosity of --settle-relax reaches the steady shape fast; a cell at rest in the co-moving frame "
              "feels no membrane viscosity, and the main run, with the cell's own etam, continues from that "
              "shape and gives the observables",
              NumberRange::closed(0.0, 1e4, "R/V"))
        ->capture_default_str();
    CLI::Option* relax =
        addNumber(cmd, "--settle-relax", o.c.settleRelax,
                  "relaxation time eta_m / mu of the settling stage, R/V (> 0): its membrane viscosity is this x mu "
                  "R / V (at most the cell's own). The slow shape mode relaxes on eta_m / mu, so a fixed time in "
                  "R/V keeps the settling stage's length in R/V independent of the capillary number",
                  NumberRange::leftOpen(0.0, 1e9, "R/V"))
            ->capture_default_str();
    o.settleEtamOption = addNumber(cmd, "--settle-etam", o.settleEtam,
                                   "membrane viscosity of the settling stage; replaces --settle-relax",
                                   NumberRange::leftOpen(0.0, 1e3, "Pa s um"))
                             ->excludes(relax);
    addNumber(cmd, "--settle-tol", o.c.settleTolerance,
              fmt::format("the settling stage ends when the cell's extents along x, y and z vary by less "
                          "than this over the last {:g} R/V", kTubeSettleSpan),
              NumberRange::leftOpen(0.0, 1.0, "(relative)"))
        ->capture_default_str();
}

void addWallOptions(CLI::App* cmd, TubeCli& o) {
    addNumber(cmd, "--wall-points", o.c.wallPoints, "wall vertices per ring (0: chord ~ 1.5 x the cell's mean edge)",
              NumberRange::closed(0, 400))
        ->capture_default_str();
    addNumber(cmd, "--tube-length", o.c.tubeLength,
              "length of the discretised wall (0: the fitted cell's length x 1.15 plus 2 R at each end)",
              NumberRange::closed(0.0, 1e3, "um"))
        ->capture_default_str();
    addNumber(cmd, "--repulsion-range", o.c.repulsionRange, "range of the wall repulsion on the vertices",
              NumberRange::leftOpen(0.0, 10.0, "um"))
        ->capture_default_str();
    addNumber(cmd, "--repulsion-pressure", o.c.repulsionPressure,
              "strength p0 of the wall repulsion in units of eta_out V / R (pressure p0 (delta/d - 1)^2)",
              NumberRange::closed(0.0, 1e6))
        ->capture_default_str();
}

/// frames.csv of a tube stage (times from the start of the stage): centroid, extents, clearance, drift.
void writeTubeFrames(const std::string& dir, const TubeFrameSeries& s) {
    std::string csv = csvProvenance() + "t_s,t_R_over_V,cx_um,cy_um,cz_um,length_um,width_y_um,width_z_um,clearance_um,area_drift,"
                      "volume_drift\n";
    for (std::size_t k = 0; k < s.time.size(); ++k) {
        const Eigen::Vector3d c = s.centroidUm.col(static_cast<Eigen::Index>(k));
        csv += fmt::format("{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.6g},{:.6e},{:.6e}\n", s.time[k],
                           s.timeROverV[k], c.x(), c.y(), c.z(), s.lengthUm[k], s.widthYUm[k], s.widthZUm[k],
                           s.clearanceUm[k], s.areaDrift[k], s.volumeDrift[k]);
    }
    writeText(dir + "/frames.csv", csv);
}

void writeTubeStage(const std::string& dir, const TubeCaseResult& res, const TubeStageResult& stage, int vtkEvery) {
    ensureWritableDirectory(dir);
    writeShapesAndSteps(dir, res.scales, res.prepared, stage.startUm, stage.flow, vtkEvery);
    writeTubeFrames(dir, stage.series);
}

/// The parameters known before the cell is fitted.
nlohmann::json tubeParametersJson(const TubeCaseResult& res, const TubeCli& o) {
    const TubeUnits& u = res.units;
    const double Vum = u.velocityScale, Uc = u.centreLineVelocity;
    return {{"radius_um", o.c.radius},
            {"pressure_gradient_mmHg_per_mm", o.c.pressureGradient},
            {"pressure_gradient_Pa_per_m", u.pressureGradientPaPerM},
            {"eta_out_mPa_s", res.conditions.etaOut},
            {"eta_in_mPa_s", res.conditions.etaIn},
            {"viscosity_ratio", o.c.viscosityRatio},
            {"velocity_scale_V_cm_per_s", Vum * 1e-4},
            {"centre_line_velocity_cm_per_s", Uc * 1e-4},
            {"mean_poiseuille_velocity_cm_per_s", 0.5 * Uc * 1e-4},
            {"time_unit_R_over_V_s", u.timeUnit},
            {"duration_R_over_V", o.c.duration},
            {"duration_s", o.c.duration * u.timeUnit},
            {"frame_interval_R_over_V", o.c.step.frameInterval},
            {"cell", cellJson(res.cell)},
            {"cell_source", cellSource(o.cell)},
            {"area_volume", "exact constraints: area multiplier (membrane tension) in the coupled system, "
                            "projection onto A0, V0 after each step"},
            {"A0_um2", res.conditions.A0},
            {"V0_um3", res.conditions.V0},
            {"minimum_radius_um", u.minimumRadius},
            {"domain", "infinite tube (Poiseuille flux far from the cell) instead of the reference's 50 um periodic box; "
                       "no thermal fluctuations"}};
}

nlohmann::json settlingParametersJson(const TubeCaseResult& res, const TubeCli& o) {
    if (o.c.settle <= 0.0) return nullptr;
    const TubeSettlingViscosity& s = res.settlingViscosity;
    return {{"max_duration_R_over_V", o.c.settle},
            {"criterion", fmt::format("extents along x, y and z vary by < {:g} (relative) over the last {:g} R/V",
                                      o.c.settleTolerance, kTubeSettleSpan)},
            {"etam_Pa_s_um", s.etam},
            {"etam_source", s.fromRelax ? "--settle-relax: eta_m = relax_requested_R_over_V x mu R / V, at most "
                                          "the cell's own eta_m"
                                        : "--settle-etam"},
            {"relax_requested_R_over_V", s.fromRelax ? nlohmann::json(o.c.settleRelax) : nlohmann::json(nullptr)},
            {"capped_at_cell_etam", s.fromRelax && s.etamFromRelax > res.cell.etam},
            {"relaxation_time_R_over_V", s.etam / s.etamPerTimeUnit},
            {"membrane_viscosity_ratio_E", res.groups.membraneViscosity * s.etam / res.cell.etam},
            {"note", "duration_R_over_V is the main run's, which starts from the settled shape and alone gives "
                     "the observables"}};
}

/// What the fit and the wall add to the parameters.
void addFittedParameters(nlohmann::json& params, const TubeCaseResult& res, const TubeCli& o) {
    const TubeGroups& g = res.groups;
    const double L = res.scales.length;
    params["dimensionless"] = {{"capillary_number", g.capillary}, {"viscosity_ratio", g.viscosityRatio},
                               {"membrane_viscosity_ratio_E", g.membraneViscosity}, {"FvK", g.FvK},
                               {"confinement_R_over_R_A", g.confinement}, {"centre_line_velocity_over_V", g.centreLineOverV}};
    params["settling"] = settlingParametersJson(res, o);
    params["tube"] = {{"wall_points_per_ring", res.setup.pointsPerRing},
                      {"wall_vertices", res.wallVertices},
                      {"wall_length_um", 2.0 * res.setup.halfLength * L},
                      {"wall_length_over_R", 2.0 * res.setup.halfLength / res.setup.radius},
                      {"repulsion_range_um", o.c.repulsionRange},
                      {"repulsion_pressure_Pa", res.repulsionPressurePa},
                      {"contact_clearance_um", res.contactClearanceUm}};
    const Eigen::Vector3d& eq = res.fit.equilibriumExtentsUm;
    const Eigen::Vector3d& fit = res.fit.fittedExtentsUm;
    params["initial_condition"] = {
        {"description", "equilibrium shape (docs/FORWARD_MODEL.md, equilibrium) on the axis, disc plane containing the axis (x-z); when "
                        "wider than the tube minus a clearance of 0.1 R, mapped by (a x, c y, b z) with b squeezing "
                        "the disc's diameter and a, c keeping area and volume exact"},
        {"equilibrium_extents_um", {eq.x(), eq.y(), eq.z()}},
        {"fitted_extents_um", {fit.x(), fit.y(), fit.z()}},
        {"clearance_um", res.fit.clearanceUm}};
}

nlohmann::json cellFrameMotionJson(const TubeObservables& ob) {
    return {{"fastest_vertex_path_um", ob.cellFrameMotion},
            {"centroid_travel_um", ob.travel},
            {"ratio", ob.cellFrameMotion / std::max(ob.travel, 1e-300)}};
}

nlohmann::json settlingDiagnosticsJson(const TubeCaseResult& res) {
    const TubeStageResult& s = res.settling;
    nlohmann::json sd = stepDiagnostics(res.scales, s.flow, res.prepared);
    sd.erase("equilibrium");
    sd.erase("sfs");
    sd["t_reached_R_over_V"] = s.flow.tReached;
    sd["settled"] = s.flow.stoppedEarly;
    sd["checkpoint"] = checkpointJson(s.flow, res.units.timeUnit);
    sd["wall_clearance_min_um"] = s.minClearanceUm;
    sd["centroid_off_axis_max_um"] = s.maxOffAxisUm;
    if (s.observables) {
        sd["cell_frame_motion"] = cellFrameMotionJson(*s.observables);
        sd["cell_frame_motion"]["window"] = fmt::format("the last {:g} R/V of the stage", kTubeSettleSpan);
    }
    if (s.flow.completed) {
        const Eigen::Vector3d e = extents(res.main.startUm);
        sd["final_length_um"] = e.x();
        sd["final_width_um"] = e.y();
    }
    return sd;
}

nlohmann::json mainDiagnosticsJson(const TubeCaseResult& res, const TubeCli& o) {
    const CellFlowResult& r = res.main.flow;
    nlohmann::json diag = stepDiagnostics(res.scales, r, res.prepared);
    diag["dt_min_R_over_V"] = r.dtSmallest;
    diag["dt_max_R_over_V"] = r.dtLargest;
    diag["step_control"] = stepControlJson(res.main.integrator, o.step.step.dt, "fixed_dt_R_over_V");
    diag["setup_wall_s"] = res.setupWallSeconds;
    diag["wall_operator_setup_s"] = res.wallSetupSeconds;
    diag["wall_clearance_min_um"] = res.main.minClearanceUm;
    diag["centroid_off_axis_max_um"] = res.main.maxOffAxisUm;
    diag["t_reached_R_over_V"] = r.tReached;
    diag["checkpoint"] = checkpointJson(r, res.units.timeUnit);
    return diag;
}

/// Observables, analysis and the plateau and cell-frame checks of a completed run.
void addTubeObservables(nlohmann::json& j, const TubeCaseResult& res) {
    nlohmann::json& diag = j["diagnostics"];
    if (!res.main.observables) {
        j["observables"] = {{"velocity_cm_per_s", nullptr}, {"length_um", nullptr}, {"width_um", nullptr}};
        j["analysis"] = {{"note", "fewer than 16 frames: no observables (lengthen --duration or shorten --frame-interval)"}};
        return;
    }
    const TubeObservables& ob = *res.main.observables;
    const double Uc = res.units.centreLineVelocity;
    j["observables"] = {{"velocity_cm_per_s", ob.velocity * 1e-4}, {"length_um", ob.length}, {"width_um", ob.widthY},
                        {"width_z_um", ob.widthZ}, {"velocity_over_centre_line", ob.velocity / Uc},
                        {"velocity_over_mean_poiseuille", ob.velocity / (0.5 * Uc)}};
    j["analysis"] = {{"length", "extent of the vertex x (axis), mean over the second half of the frames"},
                     {"width", "extent along y (width_um) and z (width_z_um), same window"},
                     {"velocity", "least-squares slope of the centroid x(t) over the last eighth of the frames"},
                     {"frames_used", ob.framesUsed}};
    diag["plateau"] = {{"length_change_q3_vs_q4", ob.lengthChange},
                       {"velocity_change_e7_vs_e8", ob.velocityChange},
                       {"reached", ob.lengthChange < 0.01 && ob.velocityChange < 0.01},
                       {"criterion", "both relative changes < 1 %"}};
    diag["cell_frame_motion"] = cellFrameMotionJson(ob);
    diag["cell_frame_motion"]["meaning"] =
        "path of the fastest vertex relative to the centroid over the averaging window, against the centroid's travel "
        "(bounds the membrane's speed relative to the cell): ~0 = membrane at rest in the co-moving frame (no "
        "tank-treading), a steady state independent of eta_m";
    if (diag.contains("settling")) {
        const double l0 = diag["settling"]["final_length_um"].get<double>();
        diag["settling"]["length_change_main_vs_settled"] = (ob.length - l0) / ob.length;
        if (!res.settling.flow.stoppedEarly)
            j["analysis"]["warning"] = "the settling stage reached its limit (--settle) before the shape was "
                                       "steady; the main run may not have reached the steady state";
    }
}

/// A failed stage: the JSON with its reason, the stage's outputs so far, exit 3.
[[noreturn]] void tubeStageFailed(nlohmann::json& j, const TubeCaseResult& res, const TubeCli& o) {
    const bool settling = res.stage == TubeCaseStage::Settling;
    j["status"] = "failed";
    j["reason"] = res.message;
    j["observables"] = {{"velocity_cm_per_s", nullptr}, {"length_um", nullptr}, {"width_um", nullptr}};
    std::cout << j.dump(2) << std::endl;
    if (!o.step.out.empty()) {
        writeTubeStage(settling ? o.step.out + "/settling" : o.step.out, res, settling ? res.settling : res.main,
                       o.step.vtkEvery);
        writeText(o.step.out + "/flow.json", j.dump(2) + "\n");
    }
    removeCheckpoints(o.step);  // a resume would only repeat the failure
    throw NumericalError("flow tube, " + res.message);
}

void runTube(TubeCli& o) {
    o.c.cell = cellParameters(o.cell);
    o.c.allowOutsidePrior = o.cell.allowOutside;
    if (o.settleEtamOption->count() > 0) o.c.settleEtam = o.settleEtam;
    o.c.cacheDir = cacheDirectory(o.cache);
    configureStepping(o.step, "flow tube", "R/V", [](const Vertices& X) {
        const Eigen::Vector3d c = centroid(X), e = extents(X);
        return fmt::format("centroid x = {:.4g} um, length {:.4f} um, width {:.4f} um", c.x(), e.x(), e.y());
    });
    o.c.step = o.step.step;
    validateTubeCaseOptions(o.c);
    applySteppingOptions(o.step);
    const TubeCaseResult res = runTubeCase(o.c);

    nlohmann::json j;
    j["parameters"] = tubeParametersJson(res, o);
    j["provenance"] = provenanceJson(
        o.c.level, "boundary-integral Stokes, Poiseuille flow + disturbance, lambda = 1, no-slip wall on a truncated tube "
                   "re-centred on the cell (wall traction eliminated by a Schur complement, S_WW LU-factorised once), "
                   "membrane viscosity implicit, linearly implicit adaptive BDF2 (flow/tube.hpp, flow/cell_flow.hpp)");
    if (res.stage == TubeCaseStage::Fit) {
        j["status"] = "failed";
        j["reason"] = res.message;
        std::cout << j.dump(2) << std::endl;
        throw NumericalError("flow tube: " + res.message);
    }
    addFittedParameters(j["parameters"], res, o);
    nlohmann::json& diag = j["diagnostics"];
    if (res.settling.ran) diag["settling"] = settlingDiagnosticsJson(res);
    if (res.main.ran) diag.update(mainDiagnosticsJson(res, o));
    diag["wall_s"] = res.wallSeconds;
    if (!res.completed) tubeStageFailed(j, res, o);
    j["status"] = "ok";
    addTubeObservables(j, res);
    if (!o.step.out.empty()) {
        if (res.settling.ran) writeTubeStage(o.step.out + "/settling", res, res.settling, o.step.vtkEvery);
        writeTubeStage(o.step.out, res, res.main, o.step.vtkEvery);
        writeText(o.step.out + "/flow.json", j.dump(2) + "\n");
    }
    removeCheckpoints(o.step);
    std::cout << j.dump(2) << std::endl;
}

void registerTube(CLI::App* flow) {
    auto o = std::make_shared<TubeCli>();
    CLI::App* cmd = flow->add_subcommand(
        "tube",
        "One red cell in a straight circular microtube driven by a pressure gradient (docs/FLOW_TUBE.md): Poiseuille "
        "flow plus the disturbance of the cell in the infinite tube, boundary-integral method with a no-slip wall "
        "(viscosity ratio 1), membrane forces of docs/MEMBRANE_MODEL.md with membrane viscosity, semi-implicit adaptive BDF2. "
        "Prints the cell velocity, length and width as JSON. Time unit R/V with V = (pressure gradient / 45) cm/s "
        "(docs/FLOW_TUBE.md). Without cell options the cell is the paper's Table 1 posterior means");
    addTubeFlowOptions(cmd, *o);
    addSettlingOptions(cmd, *o);
    addWallOptions(cmd, *o);
    addSteppingOptions(cmd, o->step, "R/V");
    addCacheOptions(cmd, o->cache);
    cmd->callback([o]() { runTube(*o); });
}

}  // namespace

void registerFlow(CLI::App& app) {
    CLI::App* flow =
        app.add_subcommand("flow", "Flows (docs/FLOW.md): one cell in simple shear flow or in a microtube, or a spherical capsule in shear");
    flow->require_subcommand(1);
    registerShear(flow);
    registerRamp(flow);
    registerTube(flow);
    registerFlowCapsule(flow);
    registerFlowCampaign(flow);
    registerFlowTrain(flow);
    registerFlowSobol(flow);
}

}  // namespace trbc::cli
