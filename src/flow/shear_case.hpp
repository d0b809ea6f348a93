#pragma once
// One red cell in unbounded simple shear flow u = (rate y, 0, 0) (docs/FLOW.md, shear) as one
// call: the cell of the parameters (SFS, equilibrium shape with its disc in the flow-vorticity
// plane), the run over `rotations` rigid-sphere turns 4 pi / rate with snapshots, the observables
// of flow/shear_observables.hpp and the per-frame series in physical units. `trbc flow shear`
// writes its outputs from the result; trbc.flow_shear returns it.
#include <Eigen/Core>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "experiments/parameters.hpp"
#include "flow/cell_flow.hpp"
#include "flow/flow_case.hpp"
#include "flow/shear_observables.hpp"

namespace trbc {

struct ShearCaseOptions {
    double etaOut = std::numeric_limits<double>::quiet_NaN();     ///< outer viscosity, mPa s (required)
    double shearRate = std::numeric_limits<double>::quiet_NaN();  ///< 1/s (required)
    double etaIn = 10.0;                                          ///< cytosol viscosity, mPa s
    CellParameters cell = paperTable1Cell();
    bool allowOutsidePrior = false;
    int level = 3;            ///< icosphere level of the cell mesh, 1..5
    double rotations = 10.0;  ///< duration t_end = rotations 4 pi / rate
    /// The start turned by this angle about the flow (x) axis, in [0, 90] degrees: its symmetry
    /// axis leaves the gradient direction y for (0, cos, sin), so the cell is no longer mirror
    /// symmetric about the shear plane z = 0, whose exactly in-plane start cannot leave it
    /// (a stand-in for thermal symmetry breaking).
    double tiltDeg = 0.0;
    /// Thermal fluctuations of the membrane and both fluids during the run (ThermalOptions), K;
    /// 0: none. Fixed steps of thermalStep / rate, at most the membrane's viscous time
    /// (thermalStepTimesRate).
    double temperatureK = 0.0;
    double thermalStep = 0.2;
    /// The start of the ensemble protocol (docs/FLOW_THERMAL.md): the equilibrium shape turned to a
    /// uniformly random orientation and given the thermal l = 2, 3 undulations
    /// (experiments/thermal_undulations.hpp) at kickTemperatureK, both drawn from `seed`.
    bool randomStart = false;
    double kickTemperatureK = 293.15;
    std::uint64_t seed = 1;  ///< of the random start and of the thermal noise
    /// Stop at the first whole turn (from steadyRule.minRotations on) where the observables are
    /// steady (shearSteadyStateReached), instead of after all `rotations`.
    bool stopWhenSteady = false;
    SteadyStopRule steadyRule;
    std::filesystem::path cacheDir;  ///< SFS cache; empty: none
    FlowCaseStepping step;    ///< times in 1/rate
};

/// Throws InputError naming the option and its valid range: eta_out_mPa_s, shear_rate_per_s,
/// eta_in_mPa_s in (0, 1e6], the cell inside the prior box (unless allowOutsidePrior), level in
/// [1, 5], rotations in (0, 1000], tilt_deg in [0, 90], temperature_K and kick_temperature_K in
/// [0, 400], thermal_step in (0, 1], the stepping options (validateStepping).
void validateShearCaseOptions(const ShearCaseOptions& o);

/// X turned about its centroid to a uniformly random orientation (a unit quaternion of four normal
/// variates) and given the thermal l = 2, 3 undulations of a cell of bending modulus kb (pN um)
/// at temperatureK, radius R_A (um); both drawn from `seed`.
Vertices randomThermalStart(const Vertices& X, double radiusUm, double kbPnUm, double temperatureK, std::uint64_t seed);

/// X turned by tiltDeg degrees about the flow (x) axis through its centroid, y towards z.
Vertices tiltAboutFlowAxis(const Vertices& X, double tiltDeg);

/// Per frame, in physical units.
struct ShearFrameSeries {
    std::vector<double> time;            ///< s
    std::vector<double> shearStrain;     ///< rate t
    std::vector<double> inclinationDeg;  ///< inclinationAngle
    std::vector<double> orientationDeg;  ///< long axis in the x-y plane, unwrapped
    std::vector<double> areaDrift, volumeDrift;  ///< A/A0 - 1, V/V0 - 1
    Eigen::Matrix3Xd centroidUm;
};

struct ShearCaseResult {
    bool completed = false;  ///< false: the run failed (message); the frames so far are kept
    std::string message;
    CellParameters cell;
    FlowConditions conditions;
    FlowScales scales;       ///< internal units: length R_A (um), time 1/rate (s)
    FlowGroups groups;
    double tEndSeconds = 0.0;
    ShearCell prepared;      ///< SFS, mesh, Lim reference and initial shape (um, tilted), equilibrium diagnostics
    CellFlowOptions integrator;  ///< the time stepping as run
    CellFlowResult flow;     ///< internal units
    ShearFrameSeries series;
    std::optional<ShearObservables> observables;  ///< when completed (times in 1/rate)
    double setupWallSeconds = 0.0;  ///< SFS and equilibrium
    double wallSeconds = 0.0;       ///< the whole case
};

/// Runs the case. Bad options: InputError (validateShearCaseOptions; too few frames for the
/// analysis, naming rotations and frame_interval). A failed run is no exception: completed =
/// false with the integrator's reason.
ShearCaseResult runShearCase(const ShearCaseOptions& o);

/// The step of a thermal run, 1/rate: `requested`, at most the membrane's viscous time eta_m / mu
/// (times the rate). Longer steps let the noise of a few steps build a fold at one vertex that the
/// operators frozen over the step do not see, and the run diverges (docs/FLOW_THERMAL.md, "The step").
double thermalStepTimesRate(const CellParameters& cell, double shearRate, double requested);

/// The ramp protocol (docs/FLOW_THERMAL.md, "Ramp"): one cell, the shear rate stepped up through
/// `rates` and back down (r_1 < ... < r_n, then r_{n-1}, ..., r_1), each stage `base.rotations`
/// rigid-sphere turns at its rate (or until steady, with base.stopWhenSteady) starting from the
/// shape where the stage before ended; the first
/// stage starts as runShearCase does (in-plane, tilted or random). Experiments find the regimes'
/// boundary at different rates going up and down (Dupire et al. 2012; Minetti et al. 2019).
struct ShearRampOptions {
    ShearCaseOptions base;      ///< everything but shearRate
    std::vector<double> rates;  ///< 1/s, strictly increasing, at least two
};

struct ShearRampStage {
    double shearRate = 0.0;  ///< 1/s
    bool up = true;
    bool completed = false;
    std::string message;
    std::optional<ShearObservables> observables;  ///< when completed (times in 1/rate)
    double turns = 0.0;               ///< rigid-sphere turns run
    bool stoppedWhenSteady = false;   ///< ended by the steady-state stop (base.stopWhenSteady)
    double thermalStep = 0.0;         ///< the step taken with base.temperatureK > 0, 1/rate (thermalStepOnFrames)
    double wallSeconds = 0.0;
};

struct ShearRampResult {
    std::vector<ShearRampStage> stages;  ///< up, then down
    ShearCell prepared;                  ///< the first stage's start
    bool completed = false;              ///< every stage completed
    /// The rates bracketing the onset of tank-treading going up, [last rate not tank-treading, first
    /// tank-treading], and its end going down, [first rate not tank-treading, last tank-treading];
    /// absent when the regime does not change on that leg.
    std::optional<std::pair<double, double>> upBracket, downBracket;
    double wallSeconds = 0.0;
};

/// Throws InputError for bad options (validateShearCaseOptions of the base at every rate; rates
/// strictly increasing, at least two, at most 50). A failed stage ends the ramp (completed = false).
ShearRampResult runShearRamp(const ShearRampOptions& o);

}  // namespace trbc
