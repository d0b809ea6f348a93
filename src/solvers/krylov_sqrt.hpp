#pragma once
// The square root of a symmetric positive operator applied to a vector, A^(1/2) z, by the Lanczos
// method (Chow & Saad, SIAM J. Sci. Comput. 36 (2014) A2015; Ando, Chow, Saad & Skolnick, J. Chem.
// Phys. 137 (2012) 064106): the Brownian increment of a mobility known only through its action
// (flow/cell_flow.hpp, thermal fluctuations).
//
// Method. After k steps of Lanczos from v1 = z / |z|, A V_k = V_k T_k + beta_k v_{k+1} e_k^T with T_k
// tridiagonal, and A^(1/2) z ~ |z| V_k T_k^(1/2) e_1 (T_k^(1/2) from its eigen-decomposition). The
// basis is re-orthogonalised in full against the earlier vectors (the vectors are few, and without
// it the lost orthogonality gives spurious copies of the extreme Ritz values). The iteration stops
// when two successive estimates differ by at most `tolerance` of the newer one's norm, or on a
// breakdown (beta_k <= 1e-14 |T_k|: the Krylov space is invariant, the estimate exact). Ritz
// values below zero, which an operator that is symmetric only up to its discretisation can give,
// are set to zero and reported (smallestRitzValue).
//
// Hand-written because Eigen's MatrixFunctions (unsupported) take a dense matrix, not an operator.
#include <Eigen/Core>

#include "solvers/gmres.hpp"

namespace trbc {

struct KrylovSqrtSettings {
    double tolerance = 1e-3;  ///< on the change of the estimate between iterations, relative
    int maxIterations = 100;
};

struct KrylovSqrtResult {
    Eigen::VectorXd value;       ///< A^(1/2) z
    int iterations = 0;          ///< operator applications
    bool converged = false;
    double change = 0.0;         ///< relative change at the last iteration
    double smallestRitzValue = 0.0;
};

/// A^(1/2) z for the symmetric positive (semi-)definite operator A. z = 0 gives 0.
KrylovSqrtResult krylovSqrt(const LinearMap& A, const Eigen::VectorXd& z, const KrylovSqrtSettings& settings = {});

}  // namespace trbc
