#pragma once
// The exact solutions that verify the boundary-integral Stokes solver (docs/flow_verification.md),
// each returning the solver's relative error on a unit sphere: the test suite checks them at the
// production level, bench/stokes_convergence_table prints them at levels 1-4.
#include <utility>

#include "flow/boundary_integral.hpp"
#include "flow/stokes_solver.hpp"
#include "flow/tube.hpp"

namespace trbc::stokes_verification {

/// Rigid unit sphere translating with U = (0.3, -0.2, 1) in fluid at rest: F = -6 pi mu a U.
double translatingSphereError(const BoundaryIntegralOperators& ops, int* iterations = nullptr);

/// Rigid unit sphere rotating with Omega: torque -8 pi mu a^3 Omega.
double rotatingSphereError(const BoundaryIntegralOperators& ops);

/// Freely suspended unit sphere in u = (gamma y, 0, 0), centred at c (mesh also rotated, so that its
/// symmetry axes are not aligned with the flow): Omega = (0, 0, -gamma/2), U = u_inf(c), and the
/// stresslet S = 20/3 pi mu a^3 E (Batchelor 1970). Returns {max(|Omega - Omega_exact|, |U -
/// U_exact| / a) / (gamma/2), |S - S_exact| / |S_exact|}. Omega and U alone would be exact up to
/// the GMRES tolerance (the icosphere is centrally symmetric); the stresslet tests the quadrature.
std::pair<double, double> shearedSphereErrors(int level, int* iterations = nullptr);

/// Drop of viscosity ratio lambda driven by a force F: the Hadamard-Rybczynski velocity U = F (1 +
/// lambda) / (2 pi mu a (2 + 3 lambda)) and interface velocity u = U - (I - n n) U / (2 (1 +
/// lambda)) (Happel & Brenner 1965, 4-21). Returns the relative errors of U (volume mean of the
/// interface velocity) and of the field u (max over vertices / |U|).
std::pair<double, double> hadamardRybczynskiErrors(const BoundaryIntegralOperators& ops, double lambda,
                                                   int* iterations = nullptr);

// ---- A rigid sphere of radius beta on the axis of a tube of radius 1 (Haberman & Sayre 1958).

/// Drag factor K(beta): F = 6 pi mu a U K for a sphere translating along the axis in fluid at rest.
double habermanK(double beta);
/// U / U_c of a freely suspended sphere on the axis of Poiseuille flow (the b^2 term is Faxen's law).
double habermanFreeSpeed(double beta);
/// The operators of an icosphere of the level scaled to radius a.
BoundaryIntegralOperators sphereOps(int level, double a);
/// Relative drag error of a sphere (radius beta, tube radius 1) translating along the axis.
double dragError(const BoundaryIntegralOperators& sphere, const TubeWall& wall, double beta);
/// Relative velocity error of a free sphere on the axis of Poiseuille flow (U_c = 1); the solve in `out`.
double freeSphereError(const BoundaryIntegralOperators& sphere, const TubeWall& wall, double beta,
                       RigidBodyResult* out = nullptr);

}  // namespace trbc::stokes_verification
