// Input gradients of the surrogate networks (Mlp::inputGradient, TrainedNetwork::inputGradient,
// Surrogate::inputGradient / inputJacobian) against central finite differences of evaluate().
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.hpp"
#include "experiments/parameters.hpp"
#include "surrogate/surrogate.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

// Central differences of f (rows x n) with respect to row j of x, step h_j per row.
template <class F>
Eigen::MatrixXd centralDifference(const F& f, const Eigen::MatrixXd& x, int j, double h) {
    Eigen::MatrixXd xp = x, xm = x;
    xp.row(j).array() += h;
    xm.row(j).array() -= h;
    return (f(xp) - f(xm)) / (2.0 * h);
}

// Random points strictly inside the prior box (6 x n).
Eigen::MatrixXd interiorPoints(int n, unsigned seed) {
    const PriorRange box[6] = {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam, kPriorFext};
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.05, 0.95);
    Eigen::MatrixXd x(6, n);
    for (int c = 0; c < n; ++c)
        for (int k = 0; k < 6; ++k) x(k, c) = box[k].lo + (box[k].hi - box[k].lo) * u(rng);
    return x;
}

TEST(SurrogateGradient, ShippedJacobianMatchesFiniteDifferences) {
    const Surrogate s = Surrogate::load(std::string(TRBC_TEST_DATA) + "/../../data/surrogates");
    const Eigen::MatrixXd x = interiorPoints(40, 7);
    const Eigen::MatrixXd J = s.inputJacobian(x);
    ASSERT_EQ(J.rows(), 36);
    ASSERT_EQ(J.cols(), x.cols());
    const double range[6] = {0.35, 9.0, 990.0, 4.0, 0.9, 200.0};
    auto f = [&](const Eigen::MatrixXd& z) { return s.evaluate(z); };
    for (int j = 0; j < 6; ++j) {
        // h = 1e-6 of the range: truncation h^2 |y'''| / 6 stays below the tolerance even on the steep
        // ramp of hmin near v = 1, where the networks smear the jump to the cup (at one point
        // there 1e-5 of the range missed by 1.5e-5 relative), and round-off ~ 1e-16 |y| / h ~ 1e-9.
        const Eigen::MatrixXd fd = centralDifference(f, x, j, 1e-6 * range[j]);
        for (int i = 0; i < 6; ++i) {
            const double scale = fd.row(i).cwiseAbs().maxCoeff() + 1e-12;
            for (int c = 0; c < x.cols(); ++c)
                EXPECT_NEAR(J(6 * i + j, c), fd(i, c), 1e-5 * scale) << "d y" << i << " / d x" << j << " at column " << c;
        }
    }
    // Outputs that do not depend on an input have exactly zero derivative (D on mu, b2, etam, Fext).
    for (int j : {1, 3, 4, 5}) EXPECT_EQ(J.row(j).cwiseAbs().maxCoeff(), 0.0);
    // The equilibrium and stretching outputs do not see etam.
    for (int i : {1, 2, 3, 4}) EXPECT_EQ(J.row(6 * i + 4).cwiseAbs().maxCoeff(), 0.0);
}

TEST(SurrogateGradient, VectorJacobianProductIsTheWeightedJacobian) {
    const Surrogate s = Surrogate::load(std::string(TRBC_TEST_DATA) + "/../../data/surrogates");
    const Eigen::MatrixXd x = interiorPoints(300, 11);  // more than one block of 256 columns
    std::mt19937_64 rng(3);
    std::normal_distribution<double> nd;
    Eigen::MatrixXd w(6, x.cols());
    for (Eigen::Index k = 0; k < w.size(); ++k) w(k) = nd(rng);
    const Eigen::MatrixXd g = s.inputGradient(x, w), J = s.inputJacobian(x);
    for (int c = 0; c < x.cols(); ++c) {
        const Eigen::Matrix<double, 6, 6, Eigen::RowMajor> Jc = Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(J.col(c).data());
        const Eigen::VectorXd expected = Jc.transpose() * w.col(c);
        for (int j = 0; j < 6; ++j) EXPECT_NEAR(g(j, c), expected(j), 1e-12 * (1.0 + std::abs(expected(j))));
    }
    EXPECT_THROW(s.inputGradient(x, w.leftCols(3)), InputError);
}

TEST(SurrogateGradient, TransformsScalingsAndEnsembleMatchFiniteDifferences) {
    TrainedNetwork t;
    t.net = Mlp::glorotUniform({3, 8, 8, 2}, 5);
    t.ensemble.push_back({Mlp::glorotUniform({3, 8, 8, 2}, 6), 6, 0.0});
    t.inputTransforms = {VariableTransform::Log, VariableTransform::Sqrt, VariableTransform::Identity};
    t.outputTransforms = {VariableTransform::Log, VariableTransform::Identity};
    t.inputScaling.mean = (Eigen::VectorXd(3) << 0.5, 1.2, -0.3).finished();
    t.inputScaling.sd = (Eigen::VectorXd(3) << 0.7, 0.4, 2.0).finished();
    t.outputScaling.mean = (Eigen::VectorXd(2) << 0.1, 3.0).finished();
    t.outputScaling.sd = (Eigen::VectorXd(2) << 0.3, 1.5).finished();
    Eigen::MatrixXd x(3, 5);
    x << 0.5, 1.0, 2.0, 4.0, 8.0,  //
        0.3, 1.0, 2.5, 0.7, 3.3,   //
        -1.0, 0.0, 0.5, 2.0, -2.5;
    const Eigen::MatrixXd w = (Eigen::MatrixXd(2, 5) << 1.0, -0.5, 2.0, 0.0, 1.5, 0.3, 1.0, -1.0, 2.0, 0.0).finished();
    const Eigen::MatrixXd g = t.inputGradient(x, w);
    auto weighted = [&](const Eigen::MatrixXd& z) {
        return Eigen::MatrixXd((t.evaluate(z).array() * w.array()).colwise().sum());
    };
    for (int j = 0; j < 3; ++j) {
        const Eigen::MatrixXd fd = centralDifference(weighted, x, j, 1e-6);
        for (int c = 0; c < x.cols(); ++c) EXPECT_NEAR(g(j, c), fd(0, c), 1e-6 * (1.0 + std::abs(fd(0, c)))) << "input " << j << ", column " << c;
    }
}

}  // namespace
}  // namespace trbc
