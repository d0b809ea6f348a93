#pragma once
// Overdamped membrane dynamics  Gamma(X) dX/dt = -dU/dX + f_ext  (docs/FORWARD_MODEL.md, exact constraints), Gamma the
// edge-friction matrix of the membrane viscosity plus an optional isotropic friction eps I,
// or, with a vertex mass m, the reference's second-order dynamics m d2X/dt2 + Gamma dX/dt = -dU/dX
// + f_ext (relaxation), started from rest.
//
// Time stepping is variational BDF2 with adaptive steps: each step minimises
//   Phi(X) = U(X) - f_ext.X + c0/(2 dt) (X - Y)^T [Gamma(X*) + eps I] (X - Y),
// whose stationarity condition is the variable-step BDF2 formula (c0 = (1+2w)/(1+w),
// Y = ((1+w) X_n - w^2/(1+w) X_{n-1}) / c0, w = dt_n / dt_{n-1}; the first step is implicit
// Euler, c0 = 1, Y = X_n; X* is the extrapolated state, so that the scheme stays second order
// although Gamma depends on X). Unconditionally stable for the stiff area/volume penalties, so the
// step follows the physics (the relaxation time) rather than the stiffest mode. Coefficients,
// predictor, error estimate (Milne's device), step control and dense output are those of the one
// BDF2 stepper, solvers/bdf2.hpp.
#include <functional>
#include <string>
#include <vector>

#include "membrane/model.hpp"
#include "solvers/minimize.hpp"
#include "solvers/multigrid.hpp"

namespace trbc {

struct ViscousDynamicsOptions {
    double gamma = 1.0;               ///< edge friction gamma = 4 eta_m / sqrt(3)
    double isotropicFriction = 0.0;   ///< eps: extra friction eps v_i per vertex (0 = none)
    double vertexMass = 0.0;          ///< m > 0: second-order dynamics m dV/dt = -dU/dX - Gamma V + f_ext
    double tEnd = 1.0;
    double dtInitial = 1e-4;
    double dtMax = 0.0;               ///< 0: no cap beyond tEnd
    double dtMin = 1e-14;             ///< a retry step below this ends the run (not completed)
    double errorTolerance = 1e-4;     ///< local error per step, max vertex displacement (length)
    bool adaptive = true;             ///< false: fixed step dtInitial (at most dtMax)
    /// false: steps are shortened to land on every sample time; true: steps follow the error
    /// control alone and samples are interpolated (BDF2 quadratic through the last three states)
    bool interpolateSamples = false;
    /// sigma > 0: the per-step minimisation is preconditioned by the inverse of the 3x3 vertex
    /// blocks of k [Gamma + eps I] + m k^2 I + sigma I (k = c0/dt), sigma an estimate of the elastic
    /// stiffness per vertex (force/length); 0 = plain L-BFGS
    double preconditionerStiffness = 0.0;
    /// Instead of the blocks (when set; see blockJacobiWeight for both): a multigrid H0 (solvers/multigrid.hpp) of the scalar
    /// operator (a0 + k eps + m k^2) I + (a1 + c k gamma) L + a2 L^2, with (a0, a1, a2) =
    /// elasticStiffness and c = frictionLaplacianFactor (the edge dashpots as a scalar Laplacian).
    IcosphereMultigrid* multigrid = nullptr;
    StiffnessModel elasticStiffness;
    double frictionLaplacianFactor = 0.5;
    /// w > 0 (with the multigrid; needs preconditionerStiffness > 0): H0 = B_mg + w B_blocks, the
    /// blocks above added to the V-cycle. The scalar Laplacian sees the dashpots as
    /// isotropic; the blocks carry their edge directions, which dominate the early, friction-bound
    /// steps. A sum of two symmetric positive definite operators, so still one.
    double blockJacobiWeight = 0.0;
    MinimizeOptions inner = [] {
        MinimizeOptions o;
        o.gradientTolerance = 1e-8;
        o.maxIterations = 2000;
        return o;
    }();  ///< per-step minimisation (gradient in force units)
    AreaVolumeConstraint constraint;  ///< exact area/volume constraints during the motion (none by default)
};

struct ViscousDynamicsResult {
    bool completed = false;
    int steps = 0, rejectedSteps = 0, evaluations = 0;
    double dtSmallest = 0.0, dtLargest = 0.0;
    std::string message;
};

/// Called at t = 0 and at every requested sample time (landed on by the steps, or interpolated with
/// interpolateSamples).
using DynamicsObserver = std::function<void(double t, const Vertices& X)>;

/// Integrates from X (updated in place) to options.tEnd.
ViscousDynamicsResult integrateViscous(const MembraneModel& model, Vertices& X,
                                       const ViscousDynamicsOptions& options,
                                       const std::vector<double>& sampleTimes = {},
                                       const DynamicsObserver& observer = {},
                                       const Vertices* externalForces = nullptr);

}  // namespace trbc
