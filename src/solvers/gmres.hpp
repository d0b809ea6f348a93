#pragma once
// Restarted GMRES (Saad & Schultz 1986; Saad, "Iterative Methods for Sparse Linear Systems",
// 2nd ed., algorithms 6.9 and 9.5): the one Krylov solver of trbc, used by the boundary-integral
// Stokes solvers (flow/stokes_solver.hpp) and by the coupled system of a cell's time step
// (flow/cell_flow.hpp).
//
// Method. Arnoldi with modified Gram-Schmidt and one re-orthogonalisation pass (the second pass
// keeps the basis orthogonal to machine precision when the operator is far from normal, as the
// double layer of a deformed cell is), the Hessenberg least-squares problem reduced by Givens
// rotations, right preconditioning
//   A M^-1 y = b - A x0,  x = x0 + M^-1 y,
// so that the residual GMRES minimises is the true residual of A x = b and the stopping test
// needs no preconditioner norm. A cycle stops when the rotated residual estimate |g_{j+1}| falls
// below tolerance / 2 (the true residual lags the estimate in floating point), on a lucky
// breakdown (h_{j+1,j} <= 1e-14 |R_jj|), or after `restart` iterations; then the true residual
// |b - A x| / |b| is computed, and GMRES restarts from x while it is above the tolerance, below
// the iteration budget and still decreasing.
//
// Hand-written because Eigen's unsupported GMRES takes no right preconditioner given as a function
// (only a preconditioner class applied on the left, whose residual is not the true one) and tests
// its tolerance against the residual at the start of each restart cycle.
#include <Eigen/Core>
#include <functional>

namespace trbc {

/// y = A x for a linear operator known only through its action; y is resized by the callee.
using LinearMap = std::function<void(const Eigen::VectorXd& x, Eigen::VectorXd& y)>;

struct GmresSettings {
    double tolerance = 1e-8;  ///< on the true relative residual |b - A x| / |b|
    int restart = 60;         ///< Krylov vectors per cycle
    int maxIterations = 600;  ///< over all cycles
};

struct GmresResult {
    int iterations = 0;     ///< Arnoldi steps (operator applications minus the residual checks)
    double residual = 0.0;  ///< true relative residual at exit
    bool converged = false;
};

/// Solves A x = b. `preconditioner` applies M^-1 (right preconditioning); an empty function is
/// the identity. `initialGuess` (size of b) starts the iteration; nullptr starts from zero without
/// an operator application. x is set to the last iterate also when the tolerance is not reached
/// (converged = false): callers decide whether that is an error. b = 0 gives x = 0.
GmresResult gmres(const LinearMap& A, const LinearMap& preconditioner, const Eigen::VectorXd& b, Eigen::VectorXd& x,
                  const GmresSettings& settings, const Eigen::VectorXd* initialGuess = nullptr);

}  // namespace trbc
