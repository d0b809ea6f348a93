// GMRES (solvers/gmres.hpp) against known answers: exact termination after as many iterations as
// the operator has distinct eigenvalues, one iteration with the exact inverse as right
// preconditioner, restarts, a start at the solution, a zero right-hand side, and the true
// residual it reports when the budget runs out.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "solvers/gmres.hpp"

namespace trbc {
namespace {

LinearMap matrixMap(const Eigen::MatrixXd& M) {
    return [M](const Eigen::VectorXd& x, Eigen::VectorXd& y) { y = M * x; };
}

Eigen::MatrixXd randomMatrix(int n, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    Eigen::MatrixXd M(n, n);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) M(i, j) = N(rng);
    return M;
}

Eigen::VectorXd randomVector(int n, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    Eigen::VectorXd v(n);
    for (int i = 0; i < n; ++i) v[i] = N(rng);
    return v;
}

double trueResidual(const Eigen::MatrixXd& M, const Eigen::VectorXd& b, const Eigen::VectorXd& x) {
    return (b - M * x).norm() / b.norm();
}

TEST(Gmres, TerminatesAfterAsManyIterationsAsDistinctEigenvalues) {
    // A = Q diag(1, 2, 3, 4, 5 repeated) Q^-1, non-normal through a random similarity: the
    // minimal polynomial has degree 5, so the Krylov space contains the solution after 5 steps.
    const int n = 40;
    Eigen::VectorXd d(n);
    for (int i = 0; i < n; ++i) d[i] = 1.0 + i % 5;
    const Eigen::MatrixXd Q = randomMatrix(n, 3) + 4.0 * Eigen::MatrixXd::Identity(n, n);
    const Eigen::MatrixXd A = Q * d.asDiagonal() * Q.inverse();
    const Eigen::VectorXd b = randomVector(n, 4);
    Eigen::VectorXd x;
    const GmresResult r = gmres(matrixMap(A), LinearMap{}, b, x, {1e-10, 60, 600});
    EXPECT_TRUE(r.converged);
    EXPECT_EQ(r.iterations, 5);
    EXPECT_LT(trueResidual(A, b, x), 1e-10);
    EXPECT_NEAR(r.residual, trueResidual(A, b, x), 1e-14);
}

TEST(Gmres, ExactRightPreconditionerConvergesInOneIteration) {
    const int n = 30;
    const Eigen::MatrixXd A = randomMatrix(n, 5) + 10.0 * Eigen::MatrixXd::Identity(n, n);
    const Eigen::MatrixXd Ainv = A.inverse();
    const Eigen::VectorXd b = randomVector(n, 6);
    Eigen::VectorXd x;
    const GmresResult r = gmres(matrixMap(A), matrixMap(Ainv), b, x, {1e-10, 60, 600});
    EXPECT_TRUE(r.converged);
    EXPECT_EQ(r.iterations, 1);
    EXPECT_LT((x - A.partialPivLu().solve(b)).norm() / x.norm(), 1e-12);
}

TEST(Gmres, RestartedSolveReachesTheToleranceOnTheTrueResidual) {
    // Eigenvalues spread over [1, 10] (20 distinct in a 200-dimensional space): a restart length
    // of 8 needs several cycles; the reported residual is the true one.
    const int n = 200;
    Eigen::VectorXd d(n);
    for (int i = 0; i < n; ++i) d[i] = 1.0 + 9.0 * (i % 20) / 19.0;
    const Eigen::MatrixXd A = d.asDiagonal();
    const Eigen::VectorXd b = randomVector(n, 7);
    Eigen::VectorXd x;
    const GmresResult r = gmres(matrixMap(A), LinearMap{}, b, x, {1e-9, 8, 1000});
    EXPECT_TRUE(r.converged);
    EXPECT_GT(r.iterations, 8);  // more than one cycle
    EXPECT_LE(r.residual, 1e-9);
    EXPECT_NEAR(r.residual, trueResidual(A, b, x), 1e-15);
    EXPECT_LT((x - b.cwiseQuotient(d)).cwiseAbs().maxCoeff(), 1e-8);
}

TEST(Gmres, StartsAtTheGuessAndStopsWithoutIterationsAtTheSolution) {
    const int n = 20;
    const Eigen::MatrixXd A = randomMatrix(n, 8) + 8.0 * Eigen::MatrixXd::Identity(n, n);
    const Eigen::VectorXd xs = randomVector(n, 9);
    const Eigen::VectorXd b = A * xs;
    Eigen::VectorXd x;
    const GmresResult r = gmres(matrixMap(A), LinearMap{}, b, x, {1e-8, 60, 600}, &xs);
    EXPECT_TRUE(r.converged);
    EXPECT_EQ(r.iterations, 0);
    EXPECT_EQ(x, xs);
    // A guess half-way needs fewer iterations than a start from zero to the same tolerance.
    const Eigen::VectorXd half = 0.5 * xs;
    const GmresResult fromZero = gmres(matrixMap(A), LinearMap{}, b, x, {1e-12, 60, 600});
    const GmresResult fromHalf = gmres(matrixMap(A), LinearMap{}, b, x, {1e-12, 60, 600}, &half);
    EXPECT_TRUE(fromHalf.converged);
    EXPECT_LE(fromHalf.iterations, fromZero.iterations);
    EXPECT_LT((x - xs).norm() / xs.norm(), 1e-10);
}

TEST(Gmres, ZeroRightHandSideGivesZero) {
    const Eigen::MatrixXd A = Eigen::MatrixXd::Identity(5, 5);
    Eigen::VectorXd x = Eigen::VectorXd::Ones(5);
    const GmresResult r = gmres(matrixMap(A), LinearMap{}, Eigen::VectorXd::Zero(5), x, {});
    EXPECT_TRUE(r.converged);
    EXPECT_EQ(r.iterations, 0);
    EXPECT_EQ(x, Eigen::VectorXd::Zero(5));
}

TEST(Gmres, ReportsTheTrueResidualWhenTheBudgetRunsOut) {
    const int n = 100;
    Eigen::VectorXd d(n);
    for (int i = 0; i < n; ++i) d[i] = std::pow(10.0, 3.0 * i / (n - 1));  // 100 distinct eigenvalues
    const Eigen::MatrixXd A = d.asDiagonal();
    const Eigen::VectorXd b = randomVector(n, 10);
    Eigen::VectorXd x;
    const GmresResult r = gmres(matrixMap(A), LinearMap{}, b, x, {1e-12, 5, 10});
    EXPECT_FALSE(r.converged);
    EXPECT_EQ(r.iterations, 10);
    EXPECT_GT(r.residual, 1e-12);
    EXPECT_LT(r.residual, 1.0);
    EXPECT_NEAR(r.residual, trueResidual(A, b, x), 1e-14);
}

}  // namespace
}  // namespace trbc
