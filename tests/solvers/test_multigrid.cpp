// Multigrid H0 on the icosphere hierarchy (solvers/multigrid.hpp): the operator it inverts, the
// properties L-BFGS needs (symmetric, positive definite), its convergence as an iteration, and
// what it buys the static solves.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <utility>
#include <stdexcept>

#include "mesh/icosphere.hpp"
#include "solvers/multigrid.hpp"

namespace trbc {
namespace {

Vertices randomField(Eigen::Index n, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> g;
    Vertices X(3, n);
    for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = g(rng);
    return X;
}

double dot(const Vertices& a, const Vertices& b) { return (a.array() * b.array()).sum(); }

TEST(IcosphereMultigrid, OperatorIsTheStiffnessModelOnTheGraphLaplacian) {
    const Mesh m = icosphere(2);
    const StiffnessModel s{0.3, 2.0, 0.7};
    auto mg = IcosphereMultigrid::build(m.F, s);
    ASSERT_TRUE(mg.has_value());
    EXPECT_EQ(mg->levels(), 3);
    // P x by hand: L x_i = sum_j (x_i - x_j) over the neighbours, P = a0 I + a1 L + a2 L^2.
    const Vertices x = randomField(m.X.cols(), 1);
    std::vector<std::vector<int>> nb(std::size_t(m.X.cols()));
    for (Eigen::Index f = 0; f < m.F.cols(); ++f)
        for (int k = 0; k < 3; ++k) nb[std::size_t(m.F(k, f))].push_back(m.F((k + 1) % 3, f));  // each edge once per direction
    const auto lap = [&](const Vertices& y) {
        Vertices out = Vertices::Zero(3, y.cols());
        for (Eigen::Index i = 0; i < y.cols(); ++i)
            for (int j : nb[std::size_t(i)]) out.col(i) += y.col(i) - y.col(j);
        return out;
    };
    const Vertices expected = s.a0 * x + s.a1 * lap(x) + s.a2 * lap(lap(x));
    EXPECT_LT((mg->multiply(x) - expected).cwiseAbs().maxCoeff(), 1e-12 * expected.cwiseAbs().maxCoeff());
}

TEST(IcosphereMultigrid, VCycleIsSymmetricPositiveDefiniteAndConverges) {
    const Mesh m = icosphere(4);
    // Stiffness of the reference cell at level 4 in pN/um: a0 = 2 mu A_v / (0.5 um)^2, a1 = mu,
    // a2 = kb / l0^2 (bending-dominated smooth modes).
    auto mg = IcosphereMultigrid::build(m.F, {0.42 * 4.0, 4.0, 2.4});
    ASSERT_TRUE(mg.has_value());
    const Eigen::Index n = m.X.cols();
    const Vertices u = randomField(n, 2), w = randomField(n, 3);
    const double uBw = dot(u, mg->apply(w)), wBu = dot(w, mg->apply(u));
    EXPECT_NEAR(uBw, wBu, 1e-10 * std::abs(uBw));
    for (unsigned seed = 4; seed < 9; ++seed) {
        const Vertices z = randomField(n, seed);
        EXPECT_GT(dot(z, mg->apply(z)), 0.0);
    }
    // As a stationary iteration x += B (b - P x): measured factor 0.41 per cycle; a V-cycle that
    // lost its coarse correction or smoother would stall near 1.
    const Vertices b = randomField(n, 10);
    Vertices x = Vertices::Zero(3, n);
    double r0 = b.norm(), r = r0;
    for (int it = 0; it < 10; ++it) {
        x += mg->apply(Vertices(b - mg->multiply(x)));
        r = (b - mg->multiply(x)).norm();
    }
    EXPECT_LT(r / r0, std::pow(0.5, 10));
    // The vector interface is the same operator on interleaved coordinates.
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(b.data(), 3 * n);
    mg->apply(v);
    const Vertices Bb = mg->apply(b);
    EXPECT_EQ((Eigen::Map<const Vertices>(v.data(), 3, n) - Bb).cwiseAbs().maxCoeff(), 0.0);
}

TEST(IcosphereMultigrid, NewCoefficientsEqualAFreshBuild) {
    const Mesh m = icosphere(3);
    auto a = IcosphereMultigrid::build(m.F, {1.0, 2.0, 3.0});
    auto b = IcosphereMultigrid::build(m.F, {0.5, 7.0, 0.1});
    ASSERT_TRUE(a && b);
    a->setStiffness({0.5, 7.0, 0.1});
    const Vertices z = randomField(m.X.cols(), 11);
    EXPECT_LT((a->apply(z) - b->apply(z)).cwiseAbs().maxCoeff(), 1e-12 * b->apply(z).cwiseAbs().maxCoeff());
    EXPECT_THROW(a->setStiffness({0.0, 1.0, 1.0}), std::invalid_argument);
    EXPECT_THROW(a->setStiffness({1.0, -1.0, 1.0}), std::invalid_argument);
}

TEST(IcosphereMultigrid, OnlyForIcospheresAndAdmissibleCoefficients) {
    Mesh m = icosphere(3);
    EXPECT_FALSE(IcosphereMultigrid::build(m.F, {0.0, 1.0, 1.0}).has_value());
    EXPECT_FALSE(IcosphereMultigrid::build(m.F, {1.0, std::nan(""), 1.0}).has_value());
    EXPECT_FALSE(IcosphereMultigrid::build(icosphere(0).F, {1.0, 1.0, 1.0}).has_value());
    Faces relabelled = m.F;
    std::swap(relabelled(0, 0), relabelled(1, 0));  // same size, not the icosphere's connectivity
    EXPECT_FALSE(IcosphereMultigrid::build(relabelled, {1.0, 1.0, 1.0}).has_value());
}

TEST(IcosphereMultigrid, MembraneStiffnessModel) {
    const StiffnessModel s = membraneStiffness(4.0, 4.0, 0.17, 0.0527, 0.25, 0.5);
    EXPECT_DOUBLE_EQ(s.a0, 8.0 * 0.0527 / 0.25);
    EXPECT_DOUBLE_EQ(s.a1, 4.0);
    EXPECT_DOUBLE_EQ(s.a2, 0.17 / 0.0625);
}

}  // namespace
}  // namespace trbc
