#include "solvers/krylov_sqrt.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <vector>

namespace trbc {

KrylovSqrtResult krylovSqrt(const LinearMap& A, const Eigen::VectorXd& z, const KrylovSqrtSettings& settings) {
    KrylovSqrtResult r;
    const Eigen::Index n = z.size();
    r.value = Eigen::VectorXd::Zero(n);
    const double zNorm = z.norm();
    if (!(zNorm > 0.0)) {
        r.converged = true;
        return r;
    }
    const int kMax = std::max(1, std::min<int>(settings.maxIterations, static_cast<int>(n)));
    Eigen::MatrixXd V(n, kMax);
    std::vector<double> alpha, beta;
    V.col(0) = z / zNorm;
    Eigen::VectorXd w, previous = Eigen::VectorXd::Zero(n);
    for (int k = 0; k < kMax; ++k) {
        A(V.col(k), w);
        ++r.iterations;
        alpha.push_back(V.col(k).dot(w));
        // Full re-orthogonalisation (twice: classical Gram-Schmidt needs the second pass).
        for (int pass = 0; pass < 2; ++pass) w -= V.leftCols(k + 1) * (V.leftCols(k + 1).transpose() * w);
        const double b = w.norm();
        const int m = k + 1;
        Eigen::MatrixXd T = Eigen::MatrixXd::Zero(m, m);
        for (int i = 0; i < m; ++i) {
            T(i, i) = alpha[static_cast<std::size_t>(i)];
            if (i + 1 < m) T(i, i + 1) = T(i + 1, i) = beta[static_cast<std::size_t>(i)];
        }
        const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(T);
        r.smallestRitzValue = es.eigenvalues().minCoeff();
        const Eigen::VectorXd sqrtLambda = es.eigenvalues().cwiseMax(0.0).cwiseSqrt();
        // T^(1/2) e_1 = Q diag(sqrt lambda) Q^T e_1
        const Eigen::VectorXd c = es.eigenvectors() * sqrtLambda.cwiseProduct(es.eigenvectors().row(0).transpose());
        r.value = zNorm * (V.leftCols(m) * c);
        const double valueNorm = r.value.norm();
        r.change = k == 0 ? 1.0 : (r.value - previous).norm() / std::max(valueNorm, 1e-300);
        const bool breakdown = b <= 1e-14 * std::max(T.norm(), 1e-300);
        if ((k > 0 && r.change <= settings.tolerance) || breakdown) {
            r.converged = true;
            return r;
        }
        if (k + 1 == kMax) break;
        beta.push_back(b);
        V.col(k + 1) = w / b;
        previous = r.value;
    }
    r.converged = r.iterations == n;  // the whole space: exact up to round-off
    return r;
}

}  // namespace trbc
