#pragma once
// Energy minimisation by L-BFGS (hand-written, see README "Why hand-written"): stops on the
// largest per-vertex gradient norm (a force, in the caller's units), is aware of energy round-off
// near tight tolerances, counts evaluations and never throws on a failed line search.
#include <Eigen/Core>
#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "membrane/model.hpp"

namespace trbc {

struct MinimizeOptions {
    double gradientTolerance = 1e-6;  ///< stop when max_i |dU/dx_i| <= this (force units)
    int maxIterations = 100000;
    int memory = 12;                  ///< number of L-BFGS correction pairs
    double maxVertexStep = 0.0;       ///< cap on any vertex's displacement per iteration (0 = none)
    /// With a preconditioner: scale it by s.y / y.H0 y of the newest pair (true), or take it as
    /// it is when it already has the Hessian's physical scale (false; saves one application per
    /// iteration).
    bool scalePreconditioner = true;
    /// With scalePreconditioner: the scale s.y / y.H0 y is refreshed at every this-many-th pair and
    /// kept in between (each refresh costs one more application of the preconditioner).
    int preconditionerScaleInterval = 1;
    /// Stop (not converged) once this instant has passed: a wall-time budget shared by several
    /// minimisations (a campaign cell's --cell-time-limit).
    std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
    /// Called once per iteration from the calling thread when set; a front end throws from it to
    /// abandon the run (Ctrl-C in the Python module).
    std::function<void()> interruptCheck;
};

/// Whether a deadline has passed (the default, time_point::max(), never does and reads no clock).
inline bool deadlinePassed(std::chrono::steady_clock::time_point deadline) {
    return deadline != std::chrono::steady_clock::time_point::max() && std::chrono::steady_clock::now() > deadline;
}

struct MinimizeResult {
    bool converged = false;
    int iterations = 0;
    int evaluations = 0;
    double energy = 0.0;
    double gradientNorm = 0.0;        ///< max_i |P dU/dx_i| at the returned point (P: tangent projector)
    Eigen::VectorXd multipliers;      ///< Lagrange multipliers of the equality constraints
    double constraintError = 0.0;     ///< max_k |c_k| / scale_k at the returned point
    std::string message;
};

/// f(x, grad) returns the objective and writes its gradient; x holds 3 coordinates per vertex.
using Objective = std::function<double(const Eigen::VectorXd& x, Eigen::VectorXd& grad)>;

/// Equality constraints c(x) = 0 (a few, smooth, with independent gradients).
struct EqualityConstraints {
    /// Writes the values c (m) and the Jacobian columns J = [dc_1/dx ... dc_m/dx] (n x m).
    std::function<void(const Eigen::VectorXd& x, Eigen::VectorXd& c, Eigen::MatrixXd& J)> evaluate;
    /// Optional: the values c alone, cheaper than evaluate. The retraction then checks a Newton
    /// step with them and keeps the Jacobian of the point it stepped from when the step lands
    /// within the tolerance (that Jacobian differs from the exact one by the step, i.e. by O(|c|)).
    std::function<void(const Eigen::VectorXd& x, Eigen::VectorXd& c)> values;
    Eigen::VectorXd scale;            ///< c is satisfied when |c_k| <= tolerance * scale_k
    double tolerance = 1e-10;
    int maxNewtonIterations = 20;
};

/// An approximation H0 of the inverse Hessian applied in place (v <- H0 v), symmetric positive
/// definite: the L-BFGS two-loop recursion starts from it, scaled by s.y / y.H0 y of the newest
/// pair (Nocedal & Wright 7.2 with a non-scalar H0). Without one, H0 = (s.y / y.y) I.
using Preconditioner = std::function<void(Eigen::VectorXd& v)>;

/// Minimises f starting from x (overwritten with the best point found). With constraints, x is
/// first projected onto the manifold c = 0 and every trial point is pulled back onto it
/// (retraction by Gauss-Newton steps x -= J (J^T J)^{-1} c); the L-BFGS pairs use the gradient of
/// the Lagrangian and the search directions are projected onto the tangent space, so the stiffness
/// of penalties never enters and the multipliers come out as by-products.
MinimizeResult lbfgsMinimize(const Objective& f, Eigen::VectorXd& x, const MinimizeOptions& options,
                             const EqualityConstraints* constraints = nullptr,
                             const Preconditioner* preconditioner = nullptr);

/// Exact global constraints A(X) = area, V(X) = volume (docs/FORWARD_MODEL.md, exact constraints: equivalent to the stiff
/// global penalties up to relative area/volume errors of order tension / kA). A zero leaves that
/// quantity free. Multipliers: membrane tension (area) and pressure (volume), with the sign
/// convention grad U = lambda_A grad A + lambda_V grad V at a constrained minimum.
struct AreaVolumeConstraint {
    double area = 0.0, volume = 0.0;
    bool active() const { return area > 0.0 || volume > 0.0; }
};
EqualityConstraints areaVolumeConstraints(const Faces& faces, Eigen::Index numVertices,
                                          const AreaVolumeConstraint& target);

/// U(X) - sum_i f_ext_i . x_i and its gradient (f_ext may be null): the potential that the
/// minimiser and the time integrator work on.
double loadedEnergy(const MembraneModel& model, const Vertices& X, const Vertices* externalForces, Vertices& grad);

/// Minimises U(X) - sum_i f_ext_i . x_i for a membrane model, X updated in place.
/// A preconditioner (H0 of L-BFGS) may be given. With `inversionSymmetry` (partners of
/// inversionPartners), the minimisation stays in the centrally symmetric shapes (x_i = -x_j for the
/// partners i, j): X is replaced by its symmetric part first (moved to the origin), and so are every
/// gradient and every preconditioned direction. The energy (its reference shape, any external
/// forces) must be invariant under the inversion; the result is then a stationary point of the
/// unrestricted problem too (docs/EQUILIBRIUM.md "Two equilibria near v = 1").
MinimizeResult minimizeEnergy(const MembraneModel& model, Vertices& X, const MinimizeOptions& options,
                              const Vertices* externalForces = nullptr, const AreaVolumeConstraint& constraint = {},
                              const Preconditioner* preconditioner = nullptr,
                              const std::vector<Eigen::Index>* inversionSymmetry = nullptr);

/// max_i |g_i| over the 3-vectors of a flattened gradient.
double maxVertexNorm(const Eigen::VectorXd& g);

}  // namespace trbc
