#pragma once
// One red cell in a straight circular microtube driven by a pressure gradient (docs/FLOW_TUBE.md)
// as one call: the units (V = (pressure gradient / 45) cm/s, time unit R/V, Poiseuille
// centre-line velocity), the cell of the parameters fitted into the tube, the wall, the settling
// stage with a small membrane viscosity, the main stage with the cell's own, snapshots of both,
// the observables and the per-frame series in physical units. `trbc flow tube` writes its
// outputs from the result; trbc.flow_tube returns it.
//
// Settling stage (docs/FLOW_TUBE.md): the same cell with the membrane viscosity eta_m = settleRelax
// mu R / V (at most the cell's own; or settleEtam as given) reaches the steady shape in a number of
// R/V independent of the capillary number instead of eta_m / mu (~280 R/V for the Table 1 cell at
// 30 mmHg/mm). A cell at rest in the co-moving frame feels no membrane-viscosity force, so the
// steady state is the same; the main stage continues from the settled shape with the cell's own
// eta_m and alone gives the observables.
#include <Eigen/Core>
#include <filesystem>
#include <limits>
#include <optional>
#include <vector>

#include "experiments/parameters.hpp"
#include "flow/cell_flow.hpp"
#include "flow/flow_case.hpp"
#include "flow/tube.hpp"

namespace trbc {

/// The settling stage ends when the cell's extents along x, y and z have varied by less than the
/// settling tolerance (relative) over the last kTubeSettleSpan R/V.
inline constexpr double kTubeSettleSpan = 10.0;
/// 1 mmHg/mm = 133.322 Pa/mm (docs/FLOW_TUBE.md), in Pa/m.
inline constexpr double kPaPerMPerMmHgPerMm = 1.33322e5;

struct TubeCaseOptions {
    double radius = std::numeric_limits<double>::quiet_NaN();            ///< R, um (required)
    double pressureGradient = std::numeric_limits<double>::quiet_NaN();  ///< mmHg/mm (required)
    double etaOut = 1.003;          ///< suspending fluid, mPa s
    double viscosityRatio = 1.0;    ///< cytosol / outer viscosity; the tube solver supports 1 only
    CellParameters cell = paperTable1Cell();
    bool allowOutsidePrior = false;
    int level = 3;                  ///< icosphere level of the cell mesh, 1..4
    double duration = 30.0;         ///< main stage, R/V
    double settle = 60.0;           ///< longest settling stage, R/V (0: none, else >= kTubeSettleSpan)
    double settleRelax = 1.5;       ///< relaxation time eta_m / mu of the settling stage, R/V
    std::optional<double> settleEtam;  ///< membrane viscosity of the settling stage, Pa s um; replaces settleRelax
    double settleTolerance = 2e-3;  ///< relative variation of the extents that counts as settled
    int wallPoints = 0;             ///< wall vertices per ring (0: chord ~ 1.5 x the cell's mean edge)
    double tubeLength = 0.0;        ///< discretised wall, um (0: the fitted cell's length x 1.15 plus 2 R at each end)
    double repulsionRange = 0.1;    ///< um
    double repulsionPressure = 10.0;  ///< p0, units of eta_out V / R
    std::filesystem::path cacheDir;   ///< SFS cache; empty: none
    FlowCaseStepping step = tubeStepping();  ///< times in R/V

    /// Frames every R/V, the tube's step tolerance (kTubeStepTolerance).
    static FlowCaseStepping tubeStepping();
};

/// Throws InputError naming the option and its valid range: radius_um in [R_min, 100] (R_min
/// rounded up to 1e-4 um), pressure_gradient_mmHg_per_mm in (0, 1e4], eta_out_mPa_s in (0, 1e6],
/// viscosity_ratio = 1, the cell inside the prior box (unless allowOutsidePrior), level in [1, 4],
/// duration_R_over_V in (0, 1e4], settle_R_over_V 0 or in [kTubeSettleSpan, 1e4],
/// settle_relax_R_over_V in (0, 1e9], settle_etam_Pa_s_um in (0, 1e3], settle_tol in (0, 1],
/// wall_points in [0, 400], tube_length_um in [0, 1e3], repulsion_range_um in (0, 10],
/// repulsion_pressure in [0, 1e6], the stepping options (validateStepping).
void validateTubeCaseOptions(const TubeCaseOptions& o);

/// Units of docs/FLOW_TUBE.md.
struct TubeUnits {
    double velocityScale = 0.0;           ///< V = (pressure gradient / 45) cm/s, um/s
    double timeUnit = 0.0;                ///< R / V, s
    double pressureGradientPaPerM = 0.0;  ///< G
    double centreLineVelocity = 0.0;      ///< U_c = G R^2 / (4 eta_out), um/s
    double minimumRadius = 0.0;           ///< smallest tube that holds the cell's A0 and V0, um
};

/// The settling stage's membrane viscosity.
struct TubeSettlingViscosity {
    double etam = 0.0;             ///< Pa s um
    bool fromRelax = true;         ///< min(cell's eta_m, etamFromRelax); else settleEtam as given
    double etamFromRelax = 0.0;    ///< settleRelax mu R / V, Pa s um
    double etamPerTimeUnit = 0.0;  ///< the eta_m whose relaxation time eta_m / mu is one R / V
};

/// Dimensionless groups of the tube (docs/FLOW_TUBE.md).
struct TubeGroups {
    double capillary = 0.0;          ///< eta_out (V / R) R_A / mu
    double viscosityRatio = 0.0;
    double membraneViscosity = 0.0;  ///< E = eta_m / (eta_out R_A)
    double FvK = 0.0;
    double confinement = 0.0;        ///< R / R_A
    double centreLineOverV = 0.0;    ///< U_c / V
};

/// The initial shape: the equilibrium shape on the axis, disc plane containing the axis (x-z),
/// mapped by fitIntoTube to keep 0.1 R from the wall.
struct TubeFit {
    Vertices initialUm;
    Eigen::Vector3d equilibriumExtentsUm = Eigen::Vector3d::Zero();
    Eigen::Vector3d fittedExtentsUm = Eigen::Vector3d::Zero();
    double clearanceUm = 0.0;
};

/// Per frame of a stage, in physical units; times from the stage's start.
struct TubeFrameSeries {
    std::vector<double> time;          ///< s
    std::vector<double> timeROverV;    ///< R/V
    Eigen::Matrix3Xd centroidUm;
    std::vector<double> lengthUm, widthYUm, widthZUm;  ///< extents along x (axis), y, z
    std::vector<double> clearanceUm;   ///< wallClearance
    std::vector<double> areaDrift, volumeDrift;
};

struct TubeStageResult {
    bool ran = false;
    CellParameters cell;          ///< the settling stage's has its own eta_m
    CellFlowOptions integrator;   ///< the time stepping as run
    CellFlowResult flow;          ///< internal units
    Vertices startUm;             ///< the stage's initial shape
    TubeFrameSeries series;
    double minClearanceUm = 0.0, maxOffAxisUm = 0.0;  ///< the tube's records over the stage
    /// Main stage: over all its frames (completed, at least 16 frames). Settling stage: over its
    /// last 2 kTubeSettleSpan R/V (at least 16 frames there), for the cell-frame motion of the
    /// settled shape.
    std::optional<TubeObservables> observables;
};

enum class TubeCaseStage { Fit, Settling, Main };

struct TubeCaseResult {
    bool completed = false;
    TubeCaseStage stage = TubeCaseStage::Fit;  ///< the stage reached; where it failed unless completed
    /// Why it failed: the fit's reason, or "settling stage: ..." / "main stage: ..." with the integrator's.
    std::string message;
    CellParameters cell;
    FlowConditions conditions;
    FlowScales scales;            ///< internal units: length R_A (um), time R/V (s)
    TubeUnits units;
    TubeSettlingViscosity settlingViscosity;
    ShearCell prepared;           ///< SFS, mesh, Lim reference, equilibrium shape (um), equilibrium diagnostics
    // Set once the cell is fitted (stage Settling or Main):
    TubeFit fit;
    TubeGroups groups;
    TubeSetup setup;              ///< internal units
    Eigen::Index wallVertices = 0;
    double contactClearanceUm = 0.0;    ///< the polygonal wall's inset (sagitta): a vertex there touches it
    double repulsionPressurePa = 0.0;   ///< p0 in Pa
    double wallSetupSeconds = 0.0;      ///< S_WW assembled and factorised
    double setupWallSeconds = 0.0;      ///< everything before the first stage
    TubeStageResult settling, main;
    double wallSeconds = 0.0;           ///< the whole case
};

/// Runs the case. Bad options: InputError (validateTubeCaseOptions; a tube_length_um shorter
/// than the fitted cell plus 2 R; a wall of more than 4000 vertices). A cell that cannot be fitted
/// or a failed stage is no exception: completed = false with the reason (the failed stage's
/// frames so far are kept).
TubeCaseResult runTubeCase(const TubeCaseOptions& o);

}  // namespace trbc
