#pragma once
// One deformable red cell in unbounded Stokes flow (docs/FLOW.md, simple shear) -- or, through
// the FlowEnvironment hooks below, in a tube (flow/tube.hpp, docs/FLOW_TUBE.md) -- solved with
// the boundary-integral method of flow/stokes_solver.hpp, coupled to the membrane model of
// docs/MEMBRANE_MODEL.md (Juelicher bending, Lim against the SFS, global area and volume held exactly, as
// the experiments do, instead of the stiff global penalties) and the membrane viscosity (docs/MEMBRANE_MODEL.md).
//
// Units. The user-facing quantities are physical (um, s, mPa s, pN); internally everything is
// nondimensional with
//   length    L = R_A = sqrt(A0 / 4 pi) (3.2776 um for A0 = 135 um^2),
//   time      T = 1 / shear rate (or FlowConditions::timeScale in a quiescent fluid),
//   viscosity eta_out,  force eta_out L^2 / T,  energy eta_out L^3 / T.
// The moduli then are the dimensionless groups: mu' = 1 / Ca (Ca = eta_out rate R_A / mu),
// kb' = kb / (eta_out rate R_A^3) = 1 / (Ca FvK), edge friction gamma' = 4 E / sqrt(3) with
// E = eta_m / (eta_out R_A), viscosity ratio lambda = eta_in / eta_out, tension in units of
// eta_out rate R_A. Background flow u = (y, 0, 0).
//
// Coupling. Membrane nodal forces F_i = -dU/dx_i (U = Juelicher bending + Lim against the SFS)
// become the traction jump through the lumped vertex areas, Delta f_i = -(F_i + F^visc_i -
// tau dA/dx_i) / A_i (Delta f = (sigma_out - sigma_in) . n, n outward), with the membrane-
// viscosity force F^visc = -Gamma(X) u (edge friction matrix of the membrane viscosity, depends on the unknown
// membrane velocity u) and the membrane tension tau, the multiplier of the exact global area
// constraint (docs/FORWARD_MODEL.md, exact constraints: equivalent to the stiff area penalty of docs/MEMBRANE_MODEL.md up to O(tau / kA)). The
// second-kind equation of solveInterfaceVelocity becomes one linear system for (u, tau, q):
//   u - k D u + c S M^-1 (Gamma u + tau dA/dx) - q n = 2/(1+lambda) u_inf + c S M^-1 F,
//   dA/dx . u = area rate,   dV/dx . u = volume rate,
//   c = 1 / (4 pi (1 + lambda)), k = (1 - lambda) / (4 pi (1 + lambda)), M = diag(A_i),
// solved by GMRES (membrane viscosity implicit). The volume needs no force: a uniform pressure
// makes no flow (S n = 0), the continuous flow keeps V exactly and the discrete one leaks at
// O(h^2); q is a uniform normal velocity (flux correction) that removes the leak. The area and
// volume rates are those that bring the linearised A and V back to A0, V0 at the end of the
// step; after each step a Gauss-Newton projection onto A = A0, V = V0 removes the second-order
// rest (its size is reported). Right preconditioner: P = I + c B M^-1 Gamma with B the 3x3 self-
// blocks of S (P^-1 by a sparse Cholesky factorisation of M B^-1 / c + Gamma), which takes the
// stiff membrane-viscosity modes out of GMRES (89 -> 31 iterations at level 3, E = 7).
//
// Time stepping: linearly implicit, variable-step BDF2 ("semi-implicit"). With the BDF2 formula
// c0 (X^{n+1} - Y) / h = u^{n+1} (Y, c0 from X^n, X^{n-1} and the step ratio; the first step is
// implicit Euler) and the elastic force linearised about the predicted state X* (quadratic
// extrapolation of the last three states),
//   F(X^{n+1}) ~ F(X*) - H(X*) (X^{n+1} - X*),   H = d^2U/dX^2 (Hessian-vector products by
// central differences of the gradient), the stiff elastic forces enter the same linear system
// as Gamma -> Gamma + (h / c0) H and F -> F(X*) - H (Y - X*), with the boundary-integral
// operators, M, Gamma and the constraint gradients frozen at X*. This is A-stable for the stiff
// modes (bending and Lim at the grid scale; the area constraint is exact), so the step is set by
// accuracy, not by stiffness: an explicit step would be limited to ~ eta h^3 / kb for bending
// at mesh size h, and a stiff area penalty kA to ~ eta R_A / kA. The BDF2 coefficients, the
// predictor, the error estimate (Milne's device), the step control (errorTolerance in R_A units,
// a GMRES failure retried with h / 4) and the dense output of the frames are those of the one
// BDF2 stepper, solvers/bdf2.hpp. The tank-treading motion itself (vertices turning at rate ~
// shear rate) sets the step: ~0.3-0.5 / rate at tol = 1e-3.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "experiments/experiments.hpp"
#include "experiments/parameters.hpp"
#include "flow/boundary_integral.hpp"
#include "flow/stokes_solver.hpp"
#include "membrane/model.hpp"
#include "mesh/mesh.hpp"

namespace trbc {

/// The most frames a flow run records (duration / frame interval; a few scalars each), and the most
/// memory its kept frames may take (3 Nv doubles each): both are checked before the run.
inline constexpr long kMaxFlowFrames = 10000000;
inline constexpr double kMaxFlowFrameBytes = 4.0 * 1024 * 1024 * 1024;

/// Physical flow conditions of one run.
struct FlowConditions {
    double etaOut = 28.9;      ///< outer (suspending) viscosity, mPa s
    double etaIn = 10.0;       ///< inner (cytosol) viscosity, mPa s (docs/FLOW.md, shear)
    double shearRate = 0.0;    ///< 1/s; u = (rate y, 0, 0); 0 = quiescent fluid
    double timeScale = 0.0;    ///< s; 0 = 1 / shearRate (required when shearRate = 0)
    double A0 = cell::area;    ///< um^2
    double V0 = cell::volume;  ///< um^3
};

/// Throws InputError naming the parameter and its valid range (viscosities positive and
/// finite, shear rate >= 0; a time scale when the fluid is quiescent; A0, V0 > 0).
void validateFlowConditions(const FlowConditions& f);

/// Scales of the internal units (header comment).
struct FlowScales {
    double length = 1.0;     ///< um
    double time = 1.0;       ///< s
    double viscosity = 1.0;  ///< pN s / um^2 (= Pa s)
    double force() const { return viscosity * length * length / time; }  ///< pN
};

/// A membrane given directly in internal units (trbc flow capsule): the moduli in units of
/// eta_out rate L (in-plane) and eta_out rate L^3 (bending), the edge friction gamma' = 4 E / sqrt 3
/// (E = eta_m / (eta_out L)), the viscosity ratio, simple shear at unit rate. Without the global area
/// constraint the in-plane law alone resists area change, as for the capsules of the literature;
/// the volume stays exact (the flow conserves it).
struct MembraneFlowSpec {
    MembraneParameters membrane;
    double edgeFriction = 0.0;
    double viscosityRatio = 1.0;
    bool areaConstraint = false;
    double shearRate = 1.0;  ///< of the background flow (0: quiescent fluid; the time unit stays)
};

/// The nondimensional problem: membrane model, edge friction, viscosity ratio, background flow.
class CellFlowModel {
public:
    /// `referenceUm`: Lim reference (stress-free state, um), same connectivity as every shape.
    CellFlowModel(const CellParameters& cell, const FlowConditions& flow, const Faces& faces,
                  const Vertices& referenceUm);
    /// `reference`: stress-free state in internal units; A0 and V0 are its area and volume.
    CellFlowModel(const MembraneFlowSpec& spec, const Faces& faces, const Vertices& reference);

    const FlowScales& scales() const { return scales_; }
    FlowGroups groups() const;
    const CellParameters& cell() const { return cell_; }
    const FlowConditions& conditions() const { return flow_; }
    const MembraneModel& membrane() const { return membrane_; }
    const Faces& faces() const { return membrane_.faces(); }
    double edgeFriction() const { return gamma_; }    ///< gamma' = 4 E / sqrt 3
    double viscosityRatio() const { return lambda_; }
    const LinearFlow& background() const { return background_; }
    double targetArea() const { return area0_; }     ///< internal units
    double targetVolume() const { return volume0_; }
    /// The area held exactly by a multiplier (a red cell) or left to the in-plane law (a capsule).
    bool areaConstraint() const { return areaConstraint_; }
    /// Set by the MembraneFlowSpec constructor: the membrane is not built from `cell()`.
    bool hasMembraneSpec() const { return spec_ != nullptr; }

    Vertices toInternal(const Vertices& Xum) const { return Xum / scales_.length; }
    Vertices toMicrons(const Vertices& X) const { return X * scales_.length; }

private:
    CellParameters cell_;
    FlowConditions flow_;
    FlowScales scales_;
    Vertices internalReference_;  ///< Lim reference, internal units (initialised before membrane_)
    MembraneModel membrane_;
    double gamma_ = 0.0, lambda_ = 1.0, area0_ = 0.0, volume0_ = 0.0;
    LinearFlow background_;
    bool areaConstraint_ = true;
    std::shared_ptr<const MembraneFlowSpec> spec_;
};

struct CellFlowResult;

/// Snapshots of a run (docs/FLOW.md "Checkpoints"): a run killed at any moment and started again
/// with the same model, initial shape, options and key continues from its last snapshot and ends
/// with the result an uninterrupted run gets, bit for bit (wall time and the resume records
/// aside). A run that ends writes its final snapshot, so that a multi-stage caller resumes past
/// its finished stages; a failed run writes none (its resume repeats the failure from the last
/// periodic snapshot). The frame observer is not called again for frames before the snapshot.
struct CellFlowCheckpoint {
    std::filesystem::path file;      ///< empty: no snapshots
    double intervalSeconds = 60.0;   ///< wall time between snapshots (0: after every accepted step)
    bool resume = false;             ///< continue from `file` when it holds a snapshot of this run
    /// What the integrator cannot see and the run depends on (the environment's parameters, the
    /// stage): part of the fingerprint that a snapshot must match.
    std::string key;
    /// Told whether a snapshot was resumed or why it was not (another run, damaged, missing).
    std::function<void(const std::string&)> log;
};

/// Thermal fluctuations of the membrane and the fluids (docs/FLOW_THERMAL.md). Off when kT = 0:
/// the run is then the deterministic one, step for step.
///
/// Scheme. Fixed steps h, linearly implicit trapezoidal rule with the operators frozen at the
/// extrapolated midpoint X* = X^n + (h/2)(X^n - X^{n-1}) / h_{n-1}:
///   X^{n+1} = X^n + h u,   u = N (F(X*) - H (X^n - X*) - (h/2) H u - Gamma u + f_Gamma) + N M_lambda^-1 w,
/// the coupled system of one step with the Hessian weight h/2 (instead of BDF2's h/c0), and two
/// noises: w ~ sqrt(2 kT / h) M_lambda^(1/2) xi (Lanczos, solvers/krylov_sqrt.hpp), with M_lambda =
/// (I - k D)^-1 c S M^-1 the fluid's mobility of the nodal forces, and f_Gamma = sqrt(2 kT gamma / h)
/// sum_edges xi_e d_e (+ on one end, - on the other), whose covariance is (2 kT / h) Gamma. N
/// holds the constraints: exact area (a force -tau dA/dx, the mobility-weighted projection) and
/// volume (a uniform normal velocity). For a linear force the trapezoidal rule keeps the Gibbs
/// covariance kT H^-1 exactly at any step; the approximations are stated in docs/FLOW_THERMAL.md.
/// The random numbers of step n come from (seed, n) alone, so a resumed run repeats them.
struct ThermalOptions {
    double kT = 0.0;                ///< thermal energy, internal units eta_out rate R_A^3 (0: off)
    std::uint64_t seed = 1;
    /// Fixed step, internal time: shortened to divide the frame interval, or (when longer) to a whole
    /// number of frame intervals.
    double step = 0.2;
    double sqrtTolerance = 1e-3;    ///< Lanczos: relative change of M^(1/2) xi between iterations
    int sqrtMaxIterations = 100;
    /// GMRES of (I - k D) y = c S M^-1 F inside M_lambda (lambda != 1): a tenth of the Lanczos tolerance.
    double mobilityTolerance = 1e-4;
};

struct CellFlowOptions {
    ThermalOptions thermal;
    double tEnd = 40.0 * 3.14159265358979323846;  ///< internal time (10 rotations 4 pi / rate)
    double frameInterval = 0.1;      ///< frames at k frameInterval (interpolated), internal time
    bool keepFrames = true;
    double errorTolerance = 1e-3;    ///< local error per step, max vertex displacement, R_A
    bool adaptive = true;            ///< false: fixed steps dtInitial
    double dtInitial = 1e-2, dtMin = 1e-8, dtMax = 1.0;  ///< internal time
    int maxSteps = 200000;
    /// Relative true residual of the coupled system; 0: a tenth of errorTolerance, at most 1e-4
    /// (1e-6 with fixed steps).
    double gmresTolerance = 0.0;
    int gmresRestart = 100, gmresMaxIterations = 1000;
    OperatorMode operators = OperatorMode::Auto;  ///< dense when 3 Nv <= denseLimit
    /// A step costs one dense assembly plus two block products per GMRES iteration, or one fused
    /// far pass per iteration: the dense form wins at level 2 (3 Nv = 486; the fused pass is 5 %
    /// slower per rotation), the fused pass from level 3 on (13 % faster; docs/FLOW.md).
    Eigen::Index denseLimit = 1000;
    /// The far sum in single precision (QuadratureOptions::singlePrecisionFar): the matrix-free
    /// products from level 3 on cost 0.39x, the operators change by ~1e-7 of their size.
    QuadratureOptions quadrature{.singlePrecisionFar = true};
    double maxDrift = 0.05;          ///< |A/A0 - 1| or |V/V0 - 1| beyond this: diverged
    bool preconditioner = true;      ///< right preconditioner P = I + c B M^-1 Gamma (flow/coupled_system.hpp)
    /// With the preconditioner: the tension and flux multipliers eliminated through their 2 x 2
    /// Schur complement (false: left unpreconditioned; 1.6x the GMRES iterations at level 3).
    bool eliminateMultipliers = true;
    double preconditionerScale = 1.0;  ///< B = this x the self-blocks of the single layer
    /// The implicit bending stiffness in the preconditioner (a correction of the normal components
    /// after the solve with P) at a step where both hold: at some vertex alpha kb L_ii^2 / A_i
    /// reaches bendingPreconditionerRatio times the single layer's self-block stiffness, and the
    /// mean of kb L_ii / A_i reaches bendingOverShearRatio times the shear modulus (bending the
    /// stiffer at the grid scale; L the cotan Laplacian, A_i the vertex area). Elsewhere the
    /// correction costs more than it saves (docs/FLOW_SOLVER.md, "Preconditioner"). Both 0: at
    /// every step; either infinite: never. kb L_ii / A_i grows as 1 / edge^2, so the second test
    /// passes up to FvK of about 22 at level 2, 90 at level 3 and 350 at level 4.
    double bendingPreconditionerRatio = 10.0;
    double bendingOverShearRatio = 2.0;
    /// Checked after every step that recorded a frame (with the frames so far): true ends the run
    /// there as completed, with stoppedEarly set. Empty: run to tEnd.
    std::function<bool(const CellFlowResult& sofar)> stopWhen;
    CellFlowCheckpoint checkpoint;
};

/// The GMRES tolerance a step uses: CellFlowOptions::gmresTolerance, or (0) a tenth of the step's
/// local error tolerance, at most 1e-4; 1e-6 with fixed steps.
double effectiveGmresTolerance(const CellFlowOptions& o);

struct CellFlowStepRecord {
    double t = 0.0, dt = 0.0, error = 0.0;  ///< internal units (t after the step)
    int gmresIterations = 0;
    double tension = 0.0;                   ///< area multiplier, internal units (eta_out rate R_A)
    double fluxCorrection = 0.0;            ///< uniform normal velocity of the volume row, internal units
    double areaDrift = 0.0, volumeDrift = 0.0;  ///< A/A0 - 1, V/V0 - 1 after the projection
    /// A/A0 - 1 and V/V0 - 1 of the linearised step before the projection removed them (what
    /// the step would add to the drift without the projection)
    double areaCorrection = 0.0, volumeCorrection = 0.0;
};

struct CellFlowResult {
    bool completed = false;
    bool stoppedEarly = false;             ///< completed by CellFlowOptions::stopWhen before tEnd
    std::string message;
    std::vector<double> times;             ///< frame times, internal units
    std::vector<Vertices> frames;          ///< internal units (kept when keepFrames)
    std::vector<double> areaDrift, volumeDrift;  ///< per frame, A/A0 - 1 and V/V0 - 1
    std::vector<CellFlowStepRecord> stepLog;     ///< accepted steps
    Vertices final;                        ///< state at the end (or at the failure)
    double tReached = 0.0;
    int steps = 0, rejectedSteps = 0, failedSolves = 0;
    long gmresIterations = 0;              ///< accepted and rejected steps
    int maxGmresIterations = 0;
    double dtSmallest = 0.0, dtLargest = 0.0;
    double maxAreaDrift = 0.0, maxVolumeDrift = 0.0;  ///< max |drift| over the accepted steps
    /// Largest and summed |change| per step removed by the projection (the sums bound the drift
    /// that would accumulate without it).
    double maxAreaCorrection = 0.0, maxVolumeCorrection = 0.0;
    double sumAreaCorrection = 0.0, sumVolumeCorrection = 0.0;
    double maxFluxCorrection = 0.0;  ///< largest |uniform normal velocity| of the volume row (R_A rate)
    /// Thermal runs: operator applications of the Lanczos square roots (summed, largest per step) and
    /// the GMRES iterations of (I - k D) inside the mobility (lambda != 1).
    long sqrtIterations = 0, mobilityIterations = 0;
    int maxSqrtIterations = 0;
    double wallSeconds = 0.0;              ///< summed over the resumed parts
    int resumes = 0;                       ///< times the run continued from a snapshot
    double resumedAt = -1.0;               ///< time of the last snapshot resumed, internal units (-1: none)
};

/// Called at t = 0 and at every frame time (internal units).
using CellFlowObserver = std::function<void(double t, const Vertices& X)>;

/// What surrounds the cell when it is not alone in unbounded fluid (the tube of flow/tube.hpp):
/// the hooks of the coupled system. Without an environment (nullptr) the cell is in unbounded
/// fluid with the model's linear background flow (shear), exactly as before.
class FlowEnvironment {
public:
    virtual ~FlowEnvironment() = default;
    /// Undisturbed velocity u_inf at the vertices X (internal units). It enters the right-hand
    /// side as 2/(1+lambda) u_inf.
    virtual Vertices background(const Vertices& X) const = 0;
    /// Adds the gradient of an external potential of the vertices (wall repulsion) to g. It is
    /// treated like the membrane energy: explicit part in F, Hessian in the implicit part.
    virtual void addExternalGradient(const Vertices& X, Vertices& g) const = 0;
    /// The walls' part of the single layer, frozen at the state Xs (the step's predictor): a map
    /// W with S f -> S f + W f for a vertex density f (3 x Nv). Empty function: no walls.
    using DensityMap = std::function<Vertices(const Vertices&)>;
    virtual DensityMap wallOperator(const Vertices& Xs, const BoundaryIntegralOperators& cellOperators) const = 0;
    /// Empty when the accepted state X is admissible, otherwise the reason why the run must stop
    /// (contact with a wall, the cell leaving the discretised wall, ...).
    virtual std::string inadmissible(const Vertices& X) const = 0;
    /// What the environment has recorded over the run (kept in the integrator's snapshots) and
    /// its restoration on resume.
    virtual std::vector<double> records() const { return {}; }
    virtual void restoreRecords(const std::vector<double>& /*records*/) const {}
};

/// The thermal step a run takes (ThermalOptions::step): shortened to divide the frame interval, or
/// when longer to a whole number of frame intervals.
double thermalStepOnFrames(const CellFlowOptions& opt);

/// Integrates dX/dt = u(X) from `initial` (internal units). Never throws on a numerical failure:
/// returns completed = false with the reason (GMRES failure at the smallest step, step below
/// dtMin, drift beyond maxDrift, non-finite state, maxSteps, an inadmissible state of the
/// environment). Throws InputError for bad options.
CellFlowResult integrateCellFlow(const CellFlowModel& model, const Vertices& initial, const CellFlowOptions& options,
                                 const CellFlowObserver& observer = {}, const FlowEnvironment* environment = nullptr);

/// The interface velocity at X with the elastic forces explicit (no implicit term): the
/// right-hand side of dX/dt = u(X). For tests and diagnostics.
struct VelocityEvaluation {
    Vertices velocity;
    double tension = 0.0;
    int gmresIterations = 0;
    double residual = 0.0;
};
VelocityEvaluation membraneVelocity(const CellFlowModel& model, const Vertices& X, const CellFlowOptions& options = {},
                                    const FlowEnvironment* environment = nullptr);

/// The cell of docs/FLOW.md, shear for parameters p: SFS(v) (cached in cacheDir), equilibrium
/// shape (docs/FORWARD_MODEL.md, equilibrium) as initial condition, rotated so that its symmetry axis lies along the
/// gradient direction y (the disc in the flow-vorticity plane), centred at the origin.
struct ShearCell {
    StressFreeState sfs;
    Faces faces;
    Vertices reference;   ///< Lim reference: SFS scaled to A0, um
    Vertices initial;     ///< um
    SolverDiagnostics equilibrium;
};
ShearCell prepareShearCell(const CellParameters& p, int level, const std::filesystem::path& cacheDir);

/// Rotation about the z (vorticity) axis by `angle` radians, about the centroid.
Vertices rotateAboutVorticity(const Vertices& X, double angle);

}  // namespace trbc
