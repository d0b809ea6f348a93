// trbc flow shear|tube: one red cell in unbounded simple shear flow or in a microtube (docs/FLOW.md).
// The protocols are library calls (flow/shear_case.hpp, flow/tube_case.hpp); this file parses the
// options, prints the progress and writes their records (flow/flow_record.hpp).
#include <fmt/format.h>
#include <omp.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>

#include "analysis/calibrated_cell.hpp"
#include "cli/common.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "flow/flow_record.hpp"
#include "flow/shear_case.hpp"
#include "flow/tube_case.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {
namespace {

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
                              "samples.csv): the calibrated cell, the means of v, mu, kb, b2 and etam (docs/FLOW.md)");
    for (CLI::Option* opt : {c.ov, c.omu, c.fvk, c.okb, c.ob2, c.oetam}) c.opost->excludes(opt);
}

/// The cell parameters of the options (kb -> FvK, a given kb checked against its prior); the
/// flow cases check the rest.
CellParameters cellParameters(const CellOptions& c) {
    CellParameters p;
    if (c.opost->count() > 0) {
        return calibratedCell(c.posterior).cell;
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

std::string cellSource(const CellOptions& c) {
    if (c.opost->count() > 0) {
        const CalibratedCell cc = calibratedCell(c.posterior);
        return fmt::format("the calibrated cell of the theta_new posterior {}: {} of {}",
                           std::filesystem::absolute(c.posterior).lexically_normal().string(), cc.estimator, cc.source.string());
    }
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

nlohmann::json provenanceJson(int level, const char* method) {
    return withBuild({{"command", commandLine()},
                      {"level", level},
                      {"vertices", 10 * (1 << (2 * level)) + 2},
                      {"threads", omp_get_max_threads()},
                      {"sfs_model_version", kSfsModelVersion},
                      {"method", method}});
}

// ---- flow shear --------------------------------------------------------------------------------

struct ShearCli {
    ShearCaseOptions c;
    std::string start = "in-plane";
    CellOptions cell;
    SteppingOptions step;
    CacheOptions cache;
};

void finishShearOptions(ShearCli& o, const std::string& command);

void runShear(ShearCli& o) {
    finishShearOptions(o, "flow shear");
    validateShearCaseOptions(o.c);
    applySteppingOptions(o.step);
    const ShearCaseResult res = runShearCase(o.c);
    const nlohmann::json j =
        shearRecord(res, o.c, cellSource(o.cell),
                    provenanceJson(o.c.level, "boundary-integral Stokes (second kind, lambda != 1), membrane viscosity "
                                              "implicit, linearly implicit adaptive BDF2 (flow/cell_flow.hpp)"));
    if (!o.step.out.empty()) writeShearOutputs(o.step.out, res, o.step.vtkEvery, j);
    removeCheckpoints(o.step);  // a resume would only repeat a failure
    std::cout << j.dump(2) << std::endl;
    if (!res.completed) throw NumericalError("flow shear: " + res.message);
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
    addNumber(cmd, "--thermal-step", o.c.thermalStep, "fixed time step of a run with --temperature; shortened to rate eta_m / mu (the "
              "membrane's viscous time) when longer (docs/FLOW_THERMAL.md, The step)",
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
    const nlohmann::json j = rampRecord(res, r, cellSource(o.s.cell),
                                        provenanceJson(o.s.c.level, "the shear rate stepped up and down, each stage from the last "
                                                                    "stage's shape (flow/shear_case.hpp, runShearRamp)"));
    if (!o.s.step.out.empty()) writeFileAtomically(o.s.step.out + "/ramp.json", j.dump(2) + "\n");
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
    const nlohmann::json j = tubeRecord(
        res, o.c, cellSource(o.cell),
        provenanceJson(o.c.level, "boundary-integral Stokes, Poiseuille flow + disturbance, lambda = 1, no-slip wall on a truncated "
                                  "tube re-centred on the cell (wall traction eliminated by a Schur complement, S_WW LU-factorised "
                                  "once), membrane viscosity implicit, linearly implicit adaptive BDF2 (flow/tube.hpp, "
                                  "flow/cell_flow.hpp)"));
    if (res.stage != TubeCaseStage::Fit && !o.step.out.empty()) {
        // A failed stage leaves its own outputs so far (the settling stage's in settling/).
        if (res.settling.ran && (res.completed || res.stage == TubeCaseStage::Settling))
            writeTubeStage(o.step.out + "/settling", res, res.settling, o.step.vtkEvery);
        if (res.completed || res.stage != TubeCaseStage::Settling) writeTubeStage(o.step.out, res, res.main, o.step.vtkEvery);
        writeFileAtomically(o.step.out + "/flow.json", j.dump(2) + "\n");
    }
    removeCheckpoints(o.step);  // a resume would only repeat a failure
    std::cout << j.dump(2) << std::endl;
    if (!res.completed) throw NumericalError((res.stage == TubeCaseStage::Fit ? "flow tube: " : "flow tube, ") + res.message);
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
    registerFlowDistill(flow);
}

}  // namespace trbc::cli
