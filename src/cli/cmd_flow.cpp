// trbc flow shear: one red cell in unbounded simple shear flow (docs/FLOW.md, shear), boundary-integral
// Stokes solver coupled to the membrane model (flow/cell_flow.hpp); prints one JSON object.
#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <numbers>

#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "analysis/stage_ledger.hpp"
#include "core/version.hpp"
#include "flow/cell_flow.hpp"
#include "flow/shear_observables.hpp"
#include "flow/tube.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {
namespace {

constexpr double kPi = std::numbers::pi;


nlohmann::json nullable(bool ok, double v) { return ok ? nlohmann::json(v) : nlohmann::json(nullptr); }

void writeText(const std::string& path, const std::string& text) { writeFileAtomically(path, text); }

void writeShapesAndSteps(const std::string& dir, const CellFlowModel& model, const Faces& faces,
                         const Vertices& reference, const Vertices& initial, const CellFlowResult& r, int vtkEvery);

void writeOutputs(const std::string& dir, const CellFlowModel& model, const ShearCell& cell, const CellFlowResult& r,
                  int vtkEvery, const nlohmann::json& j) {
    const double L = model.scales().length, T = model.scales().time, rate = model.conditions().shearRate;
    writeShapesAndSteps(dir, model, cell.faces, cell.reference, cell.initial, r, vtkEvery);
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
    writeText(dir + "/flow.json", j.dump(2) + "\n");
}

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

/// The cell parameters of the options (kb -> FvK), validated against the prior box.
CellParameters cellParameters(const CellOptions& c) {
    CellParameters p;
    if (c.opost->count() > 0) {
        const NumericTable t = readThetaNewSamples(c.posterior);
        p.v = t.column("v").mean();
        p.mu = t.column("mu_uN_per_m").mean();
        p.FvK = CellParameters::fvkFromKb(p.mu, t.column("kb_J").mean());
        p.b2 = t.column("b2").mean();
        p.etam = t.column("etam_Pa_s_um").mean();
        validateCellParameters(p, c.allowOutside);
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
    validateCellParameters(p, c.allowOutside);
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

/// The diagnostics of the time stepping that do not depend on the flow's time unit.
nlohmann::json stepDiagnostics(const CellFlowModel& model, const CellFlowResult& r, const ShearCell& cell) {
    const long gm = r.gmresIterations;
    const double L = model.scales().length, T = model.scales().time;
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
        {"tension_final_pN_per_um", r.stepLog.empty() ? 0.0 : r.stepLog.back().tension * model.scales().force() / L},
        {"area_drift_final", r.areaDrift.empty() ? 0.0 : r.areaDrift.back()},
        {"volume_drift_final", r.volumeDrift.empty() ? 0.0 : r.volumeDrift.back()},
        {"frames", r.times.size()},
        {"flow_wall_s", r.wallSeconds},
        {"equilibrium", {{"converged", cell.equilibrium.converged}, {"iterations", cell.equilibrium.iterations},
                         {"wall_s", cell.equilibrium.wallSeconds}}},
        {"sfs", sfsJson(cell.sfs)}};
}

/// reference_sfs.vtk, initial.vtk, shape_NNNNN.vtk (every vtkEvery-th frame) + shapes.pvd, steps.csv.
void writeShapesAndSteps(const std::string& dir, const CellFlowModel& model, const Faces& faces,
                         const Vertices& reference, const Vertices& initial, const CellFlowResult& r, int vtkEvery) {
    const double L = model.scales().length, T = model.scales().time;
    writeMesh(dir + "/reference_sfs.vtk", Mesh{reference, faces});
    writeMesh(dir + "/initial.vtk", Mesh{initial, faces});
    // Shapes over time (legacy VTK, one file per saved frame) and a ParaView collection.
    std::string pvd = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
    for (std::size_t k = 0; k < r.frames.size(); k += static_cast<std::size_t>(vtkEvery)) {
        const std::string name = fmt::format("shape_{:05d}.vtk", k);
        writeMesh(dir + "/" + name, Mesh{model.toMicrons(r.frames[k]), faces});
        pvd += fmt::format("<DataSet timestep=\"{:.9g}\" file=\"{}\"/>\n", r.times[k] * T, name);
    }
    pvd += "</Collection>\n</VTKFile>\n";
    writeText(dir + "/shapes.pvd", pvd);
    const double tensionUnit = model.scales().force() / L;
    std::string steps = "t_s,dt_s,local_error_um,gmres_iterations,tension_pN_per_um,area_drift,volume_drift,"
                        "area_projection,volume_projection\n";
    for (const auto& s : r.stepLog)
        steps += fmt::format("{:.9g},{:.6e},{:.6e},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}\n", s.t * T, s.dt * T, s.error * L,
                             s.gmresIterations, s.tension * tensionUnit, s.areaDrift, s.volumeDrift, s.areaCorrection,
                             s.volumeCorrection);
    writeText(dir + "/steps.csv", steps);
}

/// Time stepping and output options shared by `flow shear` and `flow tube`; times in the flow's
/// own unit (1/rate for shear, R/V for the tube).
struct SteppingOptions {
    int threads = 0, vtkEvery = 10, maxSteps = 200000;
    double tol = 1e-3, dt = 0.0, frameInterval = 0.1;
    std::string out;
    bool resume = false;
    double checkpointInterval = 60.0;  // wall seconds
};

/// Snapshots of one stage in OUT/checkpoint/STAGE.bin (docs/FLOW.md "Checkpoints"); none without
/// --out. The key holds what the integrator cannot see: the command's parameters (the tube's too),
/// the binary itself (its bytes: another build may step differently) and the thread count (the
/// tube wall's blocked LU depends on it).
CellFlowCheckpoint stageCheckpoint(const SteppingOptions& s, const std::string& stage, const nlohmann::json& parameters,
                                   const std::string& extra = {}) {
    CellFlowCheckpoint c;
    if (s.out.empty()) return c;
    static const std::string build = fileFingerprint("/proc/self/exe");
    c.file = std::filesystem::path(s.out) / "checkpoint" / (stage + ".bin");
    c.intervalSeconds = s.checkpointInterval;
    c.resume = s.resume;
    c.key = fmt::format("{}|{}|build {}|threads {}|{}", stage, parameters.dump(), build, omp_get_max_threads(), extra);
    c.log = [](const std::string& what) { std::cerr << "flow: " << what << "\n"; };
    return c;
}

nlohmann::json checkpointJson(const CellFlowResult& r, double timeUnit) {
    return {{"resumes", r.resumes}, {"resumed_at_s", r.resumes > 0 ? nlohmann::json(r.resumedAt * timeUnit) : nlohmann::json(nullptr)}};
}

/// The snapshots are dropped once the outputs they would rebuild are written.
void removeCheckpoints(const SteppingOptions& s) {
    if (s.out.empty()) return;
    std::error_code ec;
    std::filesystem::remove_all(std::filesystem::path(s.out) / "checkpoint", ec);
}

// Progress on stderr at every tenth of the simulated duration (at frame times): simulated time,
// wall time and the ETA from the mean rate since the first frame seen (t = 0, or the first frame
// after a resumed snapshot), plus what `detail` says about the shape.
CellFlowObserver progressReporter(const std::string& name, double tEnd, const std::string& unit,
                                  std::chrono::steady_clock::time_point tStart,
                                  std::function<std::string(const Vertices&)> detail) {
    return [=, next = 0.1 * tEnd, tFirst = -1.0, wallFirst = 0.0](double t, const Vertices& X) mutable {
        const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
        if (tFirst < 0.0) {
            tFirst = t;
            wallFirst = wall;
        }
        if (t + 1e-9 < next) return;
        while (next <= t + 1e-9) next += 0.1 * tEnd;
        const std::string eta =
            t > tFirst ? fmt::format("{:.0f} s", (wall - wallFirst) * (tEnd - t) / (t - tFirst)) : std::string("?");
        std::cerr << fmt::format("{}: t = {:.4g} of {:.4g} {}, {}wall {:.1f} s, ETA {}\n", name, t, tEnd, unit,
                                 detail ? detail(X) + ", " : std::string(), wall, eta);
    };
}

void addSteppingOptions(CLI::App* cmd, SteppingOptions& s, const std::string& unit) {
    addNumber(cmd, "--frame-interval", s.frameInterval, "interval of the saved frames", NumberRange::leftOpen(0.0, 1e6, unit))
        ->capture_default_str();
    addNumber(cmd, "--step-tol", s.tol, "local error per time step, largest vertex displacement",
              NumberRange::leftOpen(0.0, 1.0, "R_A"))
        ->capture_default_str();
    addNumber(cmd, "--dt", s.dt, "fixed time step (disables the adaptive step control)", NumberRange::leftOpen(0.0, 100.0, unit));
    addNumber(cmd, "--max-steps", s.maxSteps, "limit on time-step attempts (the run fails beyond it)", NumberRange::closed(1, 1e8))
        ->capture_default_str();
    cmd->add_option("--out", s.out, "directory for the shapes (VTK + shapes.pvd), frames.csv, steps.csv, flow.json");
    addNumber(cmd, "--vtk-every", s.vtkEvery, "write every k-th frame as VTK", NumberRange::closed(1, 1e6))->capture_default_str();
    addNumber(cmd, "--threads", s.threads, "OpenMP threads (0: OpenMP default)", NumberRange::closed(0, 1024));
    cmd->add_flag("--resume", s.resume,
                  "continue a killed run from its snapshots in OUT/checkpoint/ (same command; a snapshot of another "
                  "run or a damaged one is ignored and the run starts afresh); needs --out");
    addNumber(cmd, "--checkpoint-interval", s.checkpointInterval,
              "wall time between snapshots in OUT/checkpoint/ (0: after every step; removed when the run has written its outputs)",
              NumberRange::closed(0.0, 1e7, "s"))
        ->capture_default_str();
}

/// Checks --resume against --out, prepares the output directory and sets the thread count.
void applySteppingOptions(const SteppingOptions& s) {
    if (s.resume && s.out.empty())
        throw InputError("option --resume: continues from the snapshots in --out DIR/checkpoint; give --out");
    if (!s.out.empty()) ensureWritableDirectory(s.out);
    if (s.threads > 0) omp_set_num_threads(s.threads);
}

/// The integrator options of SteppingOptions (a fixed --dt switches the step control off).
CellFlowOptions cellFlowOptions(const SteppingOptions& s, double tEnd, double dtMax) {
    CellFlowOptions opt;
    opt.tEnd = tEnd;
    opt.frameInterval = s.frameInterval;
    opt.errorTolerance = s.tol;
    opt.maxSteps = s.maxSteps;
    if (dtMax > 0.0) opt.dtMax = dtMax;
    if (s.dt > 0.0) {
        opt.adaptive = false;
        opt.dtInitial = s.dt;
        opt.dtMax = s.dt;
    }
    return opt;
}

void registerShear(CLI::App* flow) {
    struct Opts {
        double etaOut = std::nan(""), shearRate = std::nan(""), etaIn = 10.0;
        CellOptions cell;
        int level = 3;
        double rotations = 10.0;
        SteppingOptions step;
        CacheOptions cache;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = flow->add_subcommand(
        "shear",
        "One red cell in unbounded simple shear flow u = (rate y, 0, 0) (docs/FLOW.md, shear): boundary-integral "
        "Stokes flow, membrane forces of docs/MEMBRANE_MODEL.md with membrane viscosity, semi-implicit adaptive BDF2. Prints "
        "regime, inclination angle, swinging amplitude and 4 pi f / rate as JSON. Without cell options the cell "
        "is the paper's Table 1 posterior means (v=0.94, mu=4.99 uN/m, kb=2.10e-19 J, b2=1.84, etam=0.69 Pa s um)");
    addNumber(cmd, "--eta-out", o->etaOut, "outer (suspending) viscosity", NumberRange::leftOpen(0.0, 1e6, "mPa s"))->required();
    addNumber(cmd, "--shear-rate", o->shearRate, "shear rate", NumberRange::leftOpen(0.0, 1e6, "1/s"))->required();
    addNumber(cmd, "--eta-in", o->etaIn, "inner (cytosol) viscosity", NumberRange::leftOpen(0.0, 1e6, "mPa s"))->capture_default_str();
    addCellOptions(cmd, o->cell);
    addNumber(cmd, "--level", o->level, "icosphere level of the cell mesh (Nv = 10 4^L + 2)", NumberRange::closed(1, 5))
        ->capture_default_str();
    addNumber(cmd, "--rotations", o->rotations, "duration in rigid-sphere turns, t_end = rotations 4 pi / rate",
              NumberRange::leftOpen(0.0, 1000.0))
        ->capture_default_str();
    addSteppingOptions(cmd, o->step, "1/rate");
    addCacheOptions(cmd, o->cache);
    cmd->callback([o]() {
        const auto tStart = std::chrono::steady_clock::now();
        FlowConditions fc;
        fc.etaOut = o->etaOut;
        fc.etaIn = o->etaIn;
        fc.shearRate = o->shearRate;
        validateFlowConditions(fc);
        const CellParameters p = cellParameters(o->cell);
        applySteppingOptions(o->step);

        nlohmann::json j;
        j["parameters"] = {
            {"eta_out_mPa_s", fc.etaOut},
            {"eta_in_mPa_s", fc.etaIn},
            {"shear_rate_per_s", fc.shearRate},
            {"shear_stress_Pa", fc.etaOut * 1e-3 * fc.shearRate},
            {"cell", cellJson(p)},
            {"cell_source", cellSource(o->cell)},
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
        CellFlowOptions opt = cellFlowOptions(o->step, o->rotations * 4.0 * kPi, 0.0);
        opt.checkpoint = stageCheckpoint(o->step, "main", j["parameters"]);
        const double setupWall = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
        const CellFlowResult r = integrateCellFlow(model, model.toInternal(cell.initial), opt,
                                                   progressReporter("flow shear", opt.tEnd, "/rate", tStart, {}));

        nlohmann::json diag = stepDiagnostics(model, r, cell);
        diag["dt_min_times_rate"] = r.dtSmallest;
        diag["dt_max_times_rate"] = r.dtLargest;
        diag["step_control"] = {
            {"scheme", "linearly implicit variable-step BDF2, error vs quadratic predictor"},
            {"local_error_tolerance_R_A", opt.adaptive ? nlohmann::json(opt.errorTolerance) : nlohmann::json(nullptr)},
            {"fixed_dt_times_rate", opt.adaptive ? nlohmann::json(nullptr) : nlohmann::json(o->step.dt)}};
        diag["setup_wall_s"] = setupWall;
        diag["wall_s_per_rotation"] = r.tReached > 0 ? r.wallSeconds / (r.tReached / (4.0 * kPi)) : 0.0;
        diag["checkpoint"] = checkpointJson(r, model.scales().time);
        if (!r.completed) {
            diag["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
            j["status"] = "failed";
            j["reason"] = r.message;
            j["observables"] = {{"regime", nullptr}, {"inclination_deg", nullptr}, {"swing_amplitude_deg", nullptr},
                                {"ttf_4pi_f_over_shear_rate", nullptr}};
            j["diagnostics"] = diag;
            j["diagnostics"]["t_reached_s"] = r.tReached * model.scales().time;
            std::cout << j.dump(2) << std::endl;
            if (!o->step.out.empty()) writeOutputs(o->step.out, model, cell, r, o->step.vtkEvery, j);
            removeCheckpoints(o->step);  // a resume would only repeat the failure
            throw NumericalError("flow shear: " + r.message);
        }
        ShearObservables obs;
        try {
            obs = analyzeShearFrames(r.times, r.frames, 1.0);
        } catch (const InputError& e) {
            throw InputError(fmt::format("{}: too few frames for the analysis; give more --rotations (now {:g}) or a smaller "
                                         "--frame-interval (now {:g})",
                                         e.what(), o->rotations, o->step.frameInterval));
        }
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
        if (!o->step.out.empty()) writeOutputs(o->step.out, model, cell, r, o->step.vtkEvery, j);
        removeCheckpoints(o->step);
        std::cout << j.dump(2) << std::endl;
    });
}

// ---- flow tube ----------------------------------------------------------------------------------

constexpr double kPaPerMPerMmHgPerMm = 1.33322e5;  // 1 mmHg/mm = 133.322 Pa/mm (docs/FLOW.md, tube)
constexpr double kSettleSpan = 10.0;  // R/V over which the settling stage's shape must be steady

/// Wall points per ring at the default resolution: wall chord ~ 1.5 x the cell's mean edge.
int defaultWallPoints(double radiusUm, const Vertices& cellUm, const Faces& faces) {
    const double faceArea = totalArea(cellUm, faces) / static_cast<double>(faces.cols());
    const double edge = std::sqrt(4.0 * faceArea / std::sqrt(3.0));  // equilateral face of that area
    return std::max(16, static_cast<int>(std::ceil(2.0 * kPi * radiusUm / (1.5 * edge))));
}

/// frames.csv of a tube run (times from the start of the run): centroid, extents, clearance, drift.
void writeTubeFrames(const std::string& dir, const CellFlowModel& model, const CellFlowResult& r, double radiusUm) {
    const double T = model.scales().time;
    std::string csv = "t_s,t_R_over_V,cx_um,cy_um,cz_um,length_um,width_y_um,width_z_um,clearance_um,area_drift,"
                      "volume_drift\n";
    for (std::size_t k = 0; k < r.frames.size(); ++k) {
        const Vertices X = model.toMicrons(r.frames[k]);
        const Eigen::Vector3d c = centroid(X), e = extents(X);
        const double t = r.times[k];
        csv += fmt::format("{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.6g},{:.6e},{:.6e}\n", t * T, t,
                           c.x(), c.y(), c.z(), e.x(), e.y(), e.z(), wallClearance(X, radiusUm), r.areaDrift[k],
                           r.volumeDrift[k]);
    }
    writeText(dir + "/frames.csv", csv);
}

SteppingOptions tubeStepping() {
    SteppingOptions s;
    s.frameInterval = 1.0;  // R/V
    s.tol = kTubeStepTolerance;
    return s;
}

void registerTube(CLI::App* flow) {
    struct Opts {
        double radius = std::nan(""), pg = std::nan(""), etaOut = 1.003, lambda = 1.0;
        CellOptions cell;
        int level = 3, wallPoints = 0;
        double duration = 30.0, tubeLength = 0.0, settle = 60.0, settleRelax = 1.5, settleTol = 2e-3;
        double settleEtam = 0.0;              // used when given: replaces settleRelax
        CLI::Option* settleEtamOption = nullptr;
        double repulsionRange = 0.1, repulsionPressure = 10.0;
        SteppingOptions step = tubeStepping();
        CacheOptions cache;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = flow->add_subcommand(
        "tube",
        "One red cell in a straight circular microtube driven by a pressure gradient (docs/FLOW.md, tube): Poiseuille "
        "flow plus the disturbance of the cell in the infinite tube, boundary-integral method with a no-slip wall "
        "(viscosity ratio 1), membrane forces of docs/MEMBRANE_MODEL.md with membrane viscosity, semi-implicit adaptive BDF2. "
        "Prints the cell velocity, length and width as JSON. Time unit R/V with V = (pressure gradient / 45) cm/s "
        "(docs/FLOW.md, tube). Without cell options the cell is the paper's Table 1 posterior means");
    // A closed surface of area A0 inside a tube of radius R encloses at most R A0 / 2 - 2 pi R^3 / 3
    // (the capsule of radius R), which must be >= V0: R >= minimumTubeRadius(A0, V0).
    const FlowConditions cellSize;
    addNumber(cmd, "--radius", o->radius,
              fmt::format("tube radius R (from the smallest radius whose capsule holds the cell's area {} um^2 and volume {} um^3)",
                          cellSize.A0, cellSize.V0),
              NumberRange::closed(std::ceil(minimumTubeRadius(cellSize.A0, cellSize.V0) * 1e4) / 1e4, 100.0, "um"))
        ->required();
    addNumber(cmd, "--pressure-gradient", o->pg, "pressure gradient (1 mmHg/mm = 1.33322e5 Pa/m)",
              NumberRange::leftOpen(0.0, 1e4, "mmHg/mm"))
        ->required();
    addNumber(cmd, "--eta-out", o->etaOut, "viscosity of the suspending fluid", NumberRange::leftOpen(0.0, 1e6, "mPa s"))
        ->capture_default_str();
    addNumber(cmd, "--viscosity-ratio", o->lambda, "cytosol / outer viscosity; the tube solver supports 1 only",
              NumberRange::closed(1.0, 1.0))
        ->capture_default_str();
    addCellOptions(cmd, o->cell);
    addNumber(cmd, "--level", o->level, "icosphere level of the cell mesh (Nv = 10 4^L + 2)", NumberRange::closed(1, 4))
        ->capture_default_str();
    addNumber(cmd, "--duration", o->duration, "simulated time of the main run (after --settle)", NumberRange::leftOpen(0.0, 1e4, "R/V"))
        ->capture_default_str();
    addNumber(cmd, "--settle", o->settle,
                    "longest settling stage before the main run, R/V (0: none, else >= 10): the cell with the small "
                    "membrane viscosity of --settle-relax reaches the steady shape fast; a cell at rest in the co-moving frame "
                    "feels no membrane viscosity, and the main run, with the cell's own etam, continues from that "
                    "shape and gives the observables",
              NumberRange::closed(0.0, 1e4, "R/V"))
        ->capture_default_str();
    CLI::Option* relax =
        addNumber(cmd, "--settle-relax", o->settleRelax,
                        "relaxation time eta_m / mu of the settling stage, R/V (> 0): its membrane viscosity is this x mu "
                        "R / V (at most the cell's own). The slow shape mode relaxes on eta_m / mu, so a fixed time in "
                        "R/V keeps the settling stage's length in R/V independent of the capillary number",
                  NumberRange::leftOpen(0.0, 1e9, "R/V"))
            ->capture_default_str();
    o->settleEtamOption = addNumber(cmd, "--settle-etam", o->settleEtam,
                                    "membrane viscosity of the settling stage; replaces --settle-relax",
                                    NumberRange::leftOpen(0.0, 1e3, "Pa s um"))
                              ->excludes(relax);
    addNumber(cmd, "--settle-tol", o->settleTol,
              fmt::format("the settling stage ends when the cell's extents along x, y and z vary by less "
                          "than this over the last {:g} R/V", kSettleSpan),
              NumberRange::leftOpen(0.0, 1.0, "(relative)"))
        ->capture_default_str();
    addNumber(cmd, "--wall-points", o->wallPoints, "wall vertices per ring (0: chord ~ 1.5 x the cell's mean edge)",
              NumberRange::closed(0, 400))
        ->capture_default_str();
    addNumber(cmd, "--tube-length", o->tubeLength,
              "length of the discretised wall (0: the fitted cell's length x 1.15 plus 2 R at each end)",
              NumberRange::closed(0.0, 1e3, "um"))
        ->capture_default_str();
    addNumber(cmd, "--repulsion-range", o->repulsionRange, "range of the wall repulsion on the vertices",
              NumberRange::leftOpen(0.0, 10.0, "um"))
        ->capture_default_str();
    addNumber(cmd, "--repulsion-pressure", o->repulsionPressure,
              "strength p0 of the wall repulsion in units of eta_out V / R (pressure p0 (delta/d - 1)^2)",
              NumberRange::closed(0.0, 1e6))
        ->capture_default_str();
    addSteppingOptions(cmd, o->step, "R/V");
    addCacheOptions(cmd, o->cache);
    cmd->callback([o]() {
        const auto tStart = std::chrono::steady_clock::now();
        // ---- Input (exit 2 naming the option and its valid range).
        FlowConditions fc;
        const double Rmin = minimumTubeRadius(fc.A0, fc.V0);
        const CellParameters p = cellParameters(o->cell);
        if (o->settle > 0.0 && o->settle < kSettleSpan)
            throw InputError(fmt::format("parameter --settle = {} R/V: the settling criterion spans {:g} R/V (valid: 0 "
                                         "for no settling stage, or [{:g}, inf) R/V)",
                                         o->settle, kSettleSpan, kSettleSpan));
        applySteppingOptions(o->step);

        // Units: V = pg / 45 cm/s (docs/FLOW.md, tube), time unit R / V; Poiseuille centre-line speed
        // U_c = G R^2 / (4 eta) with G = pg x 1.33322e5 Pa/m.
        const double Vum = o->pg / 45.0 * 1e4;  // um/s
        const double timeUnit = o->radius / Vum;  // s
        const double G = o->pg * kPaPerMPerMmHgPerMm;  // Pa/m
        const double Uc = G * std::pow(o->radius * 1e-6, 2) / (4.0 * o->etaOut * 1e-3) * 1e6;  // um/s
        // Settling viscosity: eta_m / mu = settleRelax R / V; with mu in uN/m, R in um and V in um/s
        // this is eta_m = settleRelax mu R / V in Pa s um. etamPerTimeUnit is the eta_m whose
        // relaxation time eta_m / mu is one R / V.
        const double etamPerTimeUnit = p.mu * timeUnit;  // Pa s um
        const bool settleByRelax = o->settleEtamOption->count() == 0;
        const double settleEtamByRelax = o->settleRelax * etamPerTimeUnit;
        const double settleEtam = settleByRelax ? std::min(p.etam, settleEtamByRelax) : o->settleEtam;
        fc.etaOut = o->etaOut;
        fc.etaIn = o->etaOut * o->lambda;
        fc.shearRate = 0.0;
        fc.timeScale = timeUnit;
        validateFlowConditions(fc);

        nlohmann::json j;
        j["parameters"] = {
            {"radius_um", o->radius},
            {"pressure_gradient_mmHg_per_mm", o->pg},
            {"pressure_gradient_Pa_per_m", G},
            {"eta_out_mPa_s", fc.etaOut},
            {"eta_in_mPa_s", fc.etaIn},
            {"viscosity_ratio", o->lambda},
            {"velocity_scale_V_cm_per_s", Vum * 1e-4},
            {"centre_line_velocity_cm_per_s", Uc * 1e-4},
            {"mean_poiseuille_velocity_cm_per_s", 0.5 * Uc * 1e-4},
            {"time_unit_R_over_V_s", timeUnit},
            {"duration_R_over_V", o->duration},
            {"duration_s", o->duration * timeUnit},
            {"frame_interval_R_over_V", o->step.frameInterval},
            {"cell", cellJson(p)},
            {"cell_source", cellSource(o->cell)},
            {"area_volume", "exact constraints: area multiplier (membrane tension) in the coupled system, "
                            "projection onto A0, V0 after each step"},
            {"A0_um2", fc.A0},
            {"V0_um3", fc.V0},
            {"minimum_radius_um", Rmin},
            {"domain", "infinite tube (Poiseuille flux far from the cell) instead of the reference's 50 um periodic box; "
                       "no thermal fluctuations"}};
        j["provenance"] = {{"version", kVersion},
                           {"command", commandLine()},
                           {"level", o->level},
                           {"vertices", 10 * (1 << (2 * o->level)) + 2},
                           {"threads", omp_get_max_threads()},
                           {"sfs_model_version", kSfsModelVersion},
                           {"method", "boundary-integral Stokes, Poiseuille flow + disturbance, lambda = 1, no-slip "
                                      "wall on a truncated tube re-centred on the cell (wall traction eliminated by a "
                                      "Schur complement, S_WW LU-factorised once), membrane viscosity implicit, "
                                      "linearly implicit adaptive BDF2 (flow/tube.hpp, flow/cell_flow.hpp)"}};

        // ---- Cell: SFS, equilibrium shape with the disc plane containing the axis (x-z), fitted into the tube.
        const ShearCell cell = prepareShearCell(p, o->level, cacheDirectory(o->cache));
        const CellFlowModel model(p, fc, cell.faces, cell.reference);
        const double L = model.scales().length;
        const double clearanceUm = 0.1 * o->radius;
        Vertices initialUm;
        try {
            initialUm = fitIntoTube(cell.initial, cell.faces, o->radius, clearanceUm, fc.A0, fc.V0);
        } catch (const NumericalError& e) {
            j["status"] = "failed";
            const std::string why = fmt::format("the cell cannot be fitted into a tube of --radius {} um: {}", o->radius, e.what());
            j["reason"] = why;
            std::cout << j.dump(2) << std::endl;
            throw NumericalError("flow tube: " + why);
        }
        const Eigen::Vector3d fitted = extents(initialUm), equilibrium = extents(cell.initial);
        const double reachUm = initialUm.row(0).cwiseAbs().maxCoeff();
        TubeSetup ts;
        ts.radius = o->radius / L;
        ts.centreLineSpeed = Uc * timeUnit / L;
        ts.halfLength = (o->tubeLength > 0.0 ? 0.5 * o->tubeLength : 1.15 * reachUm + 2.0 * o->radius) / L;
        ts.pointsPerRing = o->wallPoints > 0 ? o->wallPoints : defaultWallPoints(o->radius, cell.initial, cell.faces);
        ts.repulsionRange = o->repulsionRange / L;
        ts.repulsionPressure = o->repulsionPressure;  // the internal stress unit is eta_out / (R / V)
        ts.vertexWeight = model.targetArea() / static_cast<double>(cell.faces.maxCoeff() + 1);
        if (ts.halfLength - ts.endMargin * ts.radius <= reachUm / L)
            throw InputError(fmt::format("parameter --tube-length = {} um: must exceed the fitted cell's length {:.3f} um "
                                         "plus 2 R = {:.3f} um (valid range ({:.3f}, inf) um, or 0 for the default)",
                                         o->tubeLength, 2.0 * reachUm, 2.0 * o->radius,
                                         2.0 * reachUm + 2.0 * o->radius));
        const Eigen::Index wallVertices =
            static_cast<Eigen::Index>(tubeMesh(ts.radius, ts.halfLength, ts.pointsPerRing).numVertices());
        if (3 * wallVertices > 12000)
            throw InputError(fmt::format(
                "parameters --radius = {} um / --wall-points = {}: the wall would have {} vertices (dense S_WW of {} "
                "unknowns; at most 4000 vertices): use a smaller radius, fewer --wall-points or a shorter --tube-length",
                o->radius, ts.pointsPerRing, wallVertices, 3 * wallVertices));
        const auto tWall = std::chrono::steady_clock::now();
        const TubeEnvironment env(ts);
        const double wallSetup = std::chrono::duration<double>(std::chrono::steady_clock::now() - tWall).count();
        const FlowGroups g = model.groups();
        j["parameters"]["dimensionless"] = {
            {"capillary_number", fc.etaOut * 1e-3 * (Vum / o->radius) * L / p.mu},
            {"viscosity_ratio", o->lambda},
            {"membrane_viscosity_ratio_E", g.membraneViscosity},
            {"FvK", g.FvK},
            {"confinement_R_over_R_A", o->radius / L},
            {"centre_line_velocity_over_V", Uc / Vum}};
        if (o->settle > 0.0)
            j["parameters"]["settling"] = {
                {"max_duration_R_over_V", o->settle},
                {"criterion", fmt::format("extents along x, y and z vary by < {:g} (relative) over the last {:g} R/V",
                                          o->settleTol, kSettleSpan)},
                {"etam_Pa_s_um", settleEtam},
                {"etam_source", settleByRelax ? "--settle-relax: eta_m = relax_requested_R_over_V x mu R / V, at most "
                                                "the cell's own eta_m"
                                              : "--settle-etam"},
                {"relax_requested_R_over_V", settleByRelax ? nlohmann::json(o->settleRelax) : nlohmann::json(nullptr)},
                {"capped_at_cell_etam", settleByRelax && settleEtamByRelax > p.etam},
                {"relaxation_time_R_over_V", settleEtam / etamPerTimeUnit},
                {"membrane_viscosity_ratio_E", g.membraneViscosity * settleEtam / p.etam},
                {"note", "duration_R_over_V is the main run's, which starts from the settled shape and alone gives "
                         "the observables"}};
        else
            j["parameters"]["settling"] = nullptr;
        j["parameters"]["tube"] = {
            {"wall_points_per_ring", ts.pointsPerRing},
            {"wall_vertices", env.wall().numVertices()},
            {"wall_length_um", 2.0 * ts.halfLength * L},
            {"wall_length_over_R", 2.0 * ts.halfLength / ts.radius},
            {"repulsion_range_um", o->repulsionRange},
            {"repulsion_pressure_Pa", o->repulsionPressure * fc.etaOut * 1e-3 * Vum / o->radius},
            {"contact_clearance_um", env.wall().sagitta() * L}};
        j["parameters"]["initial_condition"] = {
            {"description", "equilibrium shape (docs/FORWARD_MODEL.md, equilibrium) on the axis, disc plane containing the axis (x-z); when "
                            "wider than the tube minus a clearance of 0.1 R, mapped by (a x, c y, b z) with b squeezing "
                            "the disc's diameter and a, c keeping area and volume exact"},
            {"equilibrium_extents_um", {equilibrium.x(), equilibrium.y(), equilibrium.z()}},
            {"fitted_extents_um", {fitted.x(), fitted.y(), fitted.z()}},
            {"clearance_um", wallClearance(initialUm, o->radius)}};

        const double setupWall = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
        const auto shape = [L](const Vertices& X) {
            const Eigen::Vector3d c = centroid(X) * L, e = extents(X) * L;
            return fmt::format("centroid x = {:.4g} um, length {:.4f} um, width {:.4f} um", c.x(), e.x(), e.y());
        };
        nlohmann::json diag;
        // A failed stage: the JSON with its reason, the outputs so far, exit 3.
        const auto fail = [&](const std::string& stage, const CellFlowModel& m, const CellFlowResult& r,
                              const Vertices& startUm, const std::string& dir) {
            diag["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
            j["status"] = "failed";
            j["reason"] = stage + ": " + r.message;
            j["observables"] = {{"velocity_cm_per_s", nullptr}, {"length_um", nullptr}, {"width_um", nullptr}};
            j["diagnostics"] = diag;
            std::cout << j.dump(2) << std::endl;
            if (!dir.empty()) {
                ensureWritableDirectory(dir);
                writeShapesAndSteps(dir, m, cell.faces, cell.reference, startUm, r, o->step.vtkEvery);
                writeTubeFrames(dir, m, r, o->radius);
                writeText(o->step.out + "/flow.json", j.dump(2) + "\n");
            }
            removeCheckpoints(o->step);  // a resume would only repeat the failure
            throw NumericalError("flow tube, " + stage + ": " + r.message);
        };

        // ---- Settling stage (docs/FLOW.md "Tube"): the same cell with a small membrane viscosity
        // (eta_m / mu = settleRelax R/V) reaches the steady shape in a number of R/V independent of
        // Ca instead of eta_m / mu (~280 R/V for the Table 1 cell at 30 mmHg/mm). A cell at rest in the co-moving frame feels no membrane-
        // viscosity force, so the steady state is the same; the main stage continues from the
        // settled shape with the cell's own eta_m and alone gives the observables.
        Vertices startUm = initialUm;
        if (o->settle > 0.0) {
            CellParameters ps = p;
            ps.etam = settleEtam;
            const CellFlowModel settleModel(ps, fc, cell.faces, cell.reference);
            CellFlowOptions so = cellFlowOptions(o->step, o->settle, 5.0);
            so.checkpoint = stageCheckpoint(o->step, "settling", j["parameters"], fmt::format("settle-tol {:a}", o->settleTol));
            so.stopWhen = [tol = o->settleTol](const CellFlowResult& sofar) {
                return tubeShapeSettled(sofar.times, sofar.frames, kSettleSpan, tol);
            };
            const CellFlowResult rs = integrateCellFlow(
                settleModel, model.toInternal(initialUm), so,
                progressReporter("flow tube (settling)", so.tEnd, "R/V", tStart, shape), &env);
            nlohmann::json sd = stepDiagnostics(settleModel, rs, cell);
            sd.erase("equilibrium");
            sd.erase("sfs");
            sd["t_reached_R_over_V"] = rs.tReached;
            sd["settled"] = rs.stoppedEarly;
            sd["checkpoint"] = checkpointJson(rs, timeUnit);
            sd["wall_clearance_min_um"] = env.minClearance() * L;
            sd["centroid_off_axis_max_um"] = env.maxOffAxis() * L;
            // Is the membrane at rest in the co-moving frame at the end of this stage too? The
            // motion is measured over the second half of the frames given, here the last
            // kSettleSpan R/V.
            std::size_t first = 0;
            while (first < rs.times.size() && rs.times[first] < rs.tReached - 2.0 * kSettleSpan - 1e-9) ++first;
            if (rs.frames.size() - first >= 16) {
                std::vector<double> tS;
                std::vector<Vertices> fUm;
                for (std::size_t k = first; k < rs.frames.size(); ++k) {
                    tS.push_back(rs.times[k] * timeUnit);
                    fUm.push_back(settleModel.toMicrons(rs.frames[k]));
                }
                const TubeObservables so2 = analyzeTubeFrames(tS, fUm);
                sd["cell_frame_motion"] = {{"fastest_vertex_path_um", so2.cellFrameMotion},
                                           {"centroid_travel_um", so2.travel},
                                           {"ratio", so2.cellFrameMotion / std::max(so2.travel, 1e-300)},
                                           {"window", fmt::format("the last {:g} R/V of the stage", kSettleSpan)}};
            }
            env.resetRecords();
            diag["settling"] = sd;
            const std::string dir = o->step.out.empty() ? std::string() : o->step.out + "/settling";
            if (!rs.completed) fail("settling stage", settleModel, rs, initialUm, dir);
            if (!dir.empty()) {
                ensureWritableDirectory(dir);
                writeShapesAndSteps(dir, settleModel, cell.faces, cell.reference, initialUm, rs, o->step.vtkEvery);
                writeTubeFrames(dir, settleModel, rs, o->radius);
            }
            startUm = model.toMicrons(rs.final);
            const Eigen::Vector3d e = extents(startUm);
            diag["settling"]["final_length_um"] = e.x();
            diag["settling"]["final_width_um"] = e.y();
        }

        CellFlowOptions opt = cellFlowOptions(o->step, o->duration, 5.0);
        opt.checkpoint = stageCheckpoint(o->step, "main", j["parameters"]);
        const CellFlowResult r = integrateCellFlow(model, model.toInternal(startUm), opt,
                                                   progressReporter("flow tube", opt.tEnd, "R/V",
                                                                    std::chrono::steady_clock::now(), shape),
                                                   &env);
        diag.update(stepDiagnostics(model, r, cell));
        diag["dt_min_R_over_V"] = r.dtSmallest;
        diag["dt_max_R_over_V"] = r.dtLargest;
        diag["step_control"] = {
            {"scheme", "linearly implicit variable-step BDF2, error vs quadratic predictor"},
            {"local_error_tolerance_R_A", opt.adaptive ? nlohmann::json(opt.errorTolerance) : nlohmann::json(nullptr)},
            {"fixed_dt_R_over_V", opt.adaptive ? nlohmann::json(nullptr) : nlohmann::json(o->step.dt)}};
        diag["setup_wall_s"] = setupWall;
        diag["wall_operator_setup_s"] = wallSetup;
        diag["wall_clearance_min_um"] = env.minClearance() * L;
        diag["centroid_off_axis_max_um"] = env.maxOffAxis() * L;
        diag["t_reached_R_over_V"] = r.tReached;
        diag["checkpoint"] = checkpointJson(r, timeUnit);
        if (!r.completed) fail("main stage", model, r, startUm, o->step.out);
        std::vector<double> ts_s(r.times.size());
        std::vector<Vertices> framesUm(r.frames.size());
        for (std::size_t k = 0; k < r.frames.size(); ++k) {
            ts_s[k] = r.times[k] * timeUnit;
            framesUm[k] = model.toMicrons(r.frames[k]);
        }
        j["status"] = "ok";
        if (framesUm.size() < 16) {
            j["observables"] = {{"velocity_cm_per_s", nullptr}, {"length_um", nullptr}, {"width_um", nullptr}};
            j["analysis"] = {{"note", "fewer than 16 frames: no observables (lengthen --duration or shorten "
                                      "--frame-interval)"}};
        } else {
            const TubeObservables ob = analyzeTubeFrames(ts_s, framesUm);
            const bool plateau = ob.lengthChange < 0.01 && ob.velocityChange < 0.01;
            j["observables"] = {{"velocity_cm_per_s", ob.velocity * 1e-4},
                                {"length_um", ob.length},
                                {"width_um", ob.widthY},
                                {"width_z_um", ob.widthZ},
                                {"velocity_over_centre_line", ob.velocity / Uc},
                                {"velocity_over_mean_poiseuille", ob.velocity / (0.5 * Uc)}};
            j["analysis"] = {{"length", "extent of the vertex x (axis), mean over the second half of the frames"},
                             {"width", "extent along y (width_um) and z (width_z_um), same window"},
                             {"velocity", "least-squares slope of the centroid x(t) over the last eighth of the frames"},
                             {"frames_used", ob.framesUsed}};
            diag["plateau"] = {{"length_change_q3_vs_q4", ob.lengthChange},
                               {"velocity_change_e7_vs_e8", ob.velocityChange},
                               {"reached", plateau},
                               {"criterion", "both relative changes < 1 %"}};
            diag["cell_frame_motion"] = {
                {"fastest_vertex_path_um", ob.cellFrameMotion},
                {"centroid_travel_um", ob.travel},
                {"ratio", ob.cellFrameMotion / std::max(ob.travel, 1e-300)},
                {"meaning", "path of the fastest vertex relative to the centroid over the averaging window, against "
                            "the centroid's travel (bounds the membrane's speed relative to the cell): ~0 = membrane "
                            "at rest in the co-moving frame (no tank-treading), a steady state independent of eta_m"}};
            if (diag.contains("settling")) {
                const double l0 = diag["settling"]["final_length_um"].get<double>();
                diag["settling"]["length_change_main_vs_settled"] = (ob.length - l0) / ob.length;
                if (!diag["settling"]["settled"].get<bool>())
                    j["analysis"]["warning"] = "the settling stage reached its limit (--settle) before the shape was "
                                               "steady; the main run may not have reached the steady state";
            }
        }
        diag["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tStart).count();
        j["diagnostics"] = diag;
        if (!o->step.out.empty()) {
            writeShapesAndSteps(o->step.out, model, cell.faces, cell.reference, startUm, r, o->step.vtkEvery);
            writeTubeFrames(o->step.out, model, r, o->radius);
            writeText(o->step.out + "/flow.json", j.dump(2) + "\n");
        }
        removeCheckpoints(o->step);
        std::cout << j.dump(2) << std::endl;
    });
}

}  // namespace

void registerFlow(CLI::App& app) {
    CLI::App* flow =
        app.add_subcommand("flow", "Flow validations (docs/FLOW.md): one cell in simple shear flow or in a microtube");
    flow->require_subcommand(1);
    registerShear(flow);
    registerTube(flow);
}

}  // namespace trbc::cli
