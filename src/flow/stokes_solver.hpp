#pragma once
// Boundary-integral Stokes solvers for one closed surface in unbounded flow (Pozrikidis 1992):
// (a) a rigid body, first-kind single-layer equation for the traction (resistance and mobility
//     problems); (b) a drop / capsule interface with viscosity ratio lambda, second-kind equation
//     for the interface velocity given the traction jump. The linear systems are solved by
//     trbc's GMRES (solvers/gmres.hpp), without a preconditioner.
//
// Sign conventions: n is the outward normal of the closed surface; the traction f = sigma . n on
// a rigid body is the force per area exerted by the outside fluid on the body; the traction jump
// of an interface is Delta f = (sigma_out - sigma_in) . n, which equals minus the force per area
// that the interface (membrane, surface tension) exerts on the fluids, e.g. Delta f = 2 gamma H n
// (H = 1/a on a sphere) for a surface tension gamma.
#include <Eigen/Core>

#include "flow/boundary_integral.hpp"

namespace trbc {

/// A linear background flow u_inf(x) = velocity + gradient x (gradient_ij = du_i/dx_j).
struct LinearFlow {
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
    Eigen::Matrix3d gradient = Eigen::Matrix3d::Zero();

    Eigen::Vector3d operator()(const Eigen::Vector3d& x) const { return velocity + gradient * x; }
    /// u_inf at every vertex.
    Eigen::Matrix3Xd at(const Eigen::Matrix3Xd& X) const;

    static LinearFlow uniform(const Eigen::Vector3d& U);
    /// u_inf = (rate y, 0, 0): flow x, gradient y, vorticity -rate along z.
    static LinearFlow simpleShear(double rate);
};

enum class OperatorMode {
    Auto,        ///< dense when 3 Nv <= denseLimit, matrix-free otherwise
    Dense,       ///< assemble the 3 Nv x 3 Nv matrix once, GMRES on it
    MatrixFree,  ///< apply the operators on the fly in every GMRES iteration
};

struct GmresOptions {
    double tolerance = 1e-8;  ///< on the true relative residual |b - A x| / |b|
    int restart = 60;
    int maxIterations = 600;
    OperatorMode mode = OperatorMode::Auto;
    Eigen::Index denseLimit = 4000;
};

struct GmresReport {
    int iterations = 0;     ///< Krylov iterations (operator applications minus restarts)
    double residual = 0.0;  ///< true relative residual at exit
};

struct RigidBodyResult {
    Eigen::Matrix3Xd traction;      ///< f = sigma . n at the vertices (fluid on body)
    Eigen::Vector3d force;          ///< int f dS, hydrodynamic force on the body
    Eigen::Vector3d torque;         ///< int (x - c) x f dS about the centre c
    Eigen::Vector3d velocity;       ///< translational velocity U of the body
    Eigen::Vector3d angularVelocity;///< Omega about the centre c
    GmresReport gmres;
};

/// Resistance problem: the body moves with U + Omega x (x - c) in the background flow; solves
/// the first-kind equation (Pozrikidis 1992, ch. 2, rigid particle; the double layer of a
/// rigid-body motion drops out)
///   U + Omega x (x_i - c) = u_inf(x_i) - 1/(8 pi mu) int G(x - x_i) . f(x) dS(x)
/// for the traction f, with the null space of the single layer (f = n, since int G . n dS = 0)
/// removed by a rank-one (Wielandt) term that fixes int f . n dS = 0.
/// Throws InputError for viscosity <= 0, NumericalError when GMRES does not converge.
RigidBodyResult solveRigidBodyResistance(const BoundaryIntegralOperators& ops, double viscosity,
                                         const Eigen::Vector3d& velocity,
                                         const Eigen::Vector3d& angularVelocity,
                                         const Eigen::Vector3d& center,
                                         const LinearFlow& background = {},
                                         const GmresOptions& gmres = {});

/// Mobility problem: a rigid body under external force F and torque L (about c) in the
/// background flow. Unknowns f, U, Omega; equations: the resistance equation above at every
/// vertex plus int f dS = -F and int (x - c) x f dS = -L (force and torque balance).
/// F = L = 0: a freely suspended body.
RigidBodyResult solveRigidBodyMobility(const BoundaryIntegralOperators& ops, double viscosity,
                                       const Eigen::Vector3d& center, const LinearFlow& background = {},
                                       const Eigen::Vector3d& externalForce = Eigen::Vector3d::Zero(),
                                       const Eigen::Vector3d& externalTorque = Eigen::Vector3d::Zero(),
                                       const GmresOptions& gmres = {});

struct InterfaceResult {
    Eigen::Matrix3Xd velocity;  ///< interface velocity u at the vertices
    GmresReport gmres;
};

/// Drop / capsule interface between the outside fluid (viscosity mu) and an inside fluid of
/// viscosity lambda mu. Second-kind equation for x_i on the interface (Pozrikidis 1992, ch. 5):
///   u(x_i) = 2/(1+lambda) u_inf(x_i) - 1/(4 pi mu (1+lambda)) int G(x - x_i) . Delta f dS
///            + (1-lambda)/(4 pi (1+lambda)) PV int u . T(x - x_i) . n dS
/// (derivation: add the exterior representation of u - u_inf to lambda times the interior
/// identity, then take x_0 to the interface from outside, where the double layer jumps by
/// 4 pi u(x_0)). `tractionJump` = Delta f at the vertices (3 x Nv). `initialGuess`, when given,
/// starts GMRES (e.g. the previous time step). Throws InputError for mu <= 0 or lambda <= 0.
InterfaceResult solveInterfaceVelocity(const BoundaryIntegralOperators& ops, double viscosity,
                                       double viscosityRatio, const Eigen::Matrix3Xd& tractionJump,
                                       const LinearFlow& background = {}, const GmresOptions& gmres = {},
                                       const Eigen::Matrix3Xd* initialGuess = nullptr);

}  // namespace trbc
