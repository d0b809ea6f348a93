// Measurement primitives of docs/FORWARD_MODEL.md, measurements: the sliced ray casting on meshes with degenerate
// slices, the equilibrium observables of the Evans-Fung cell and of convex shapes against closed
// forms, their invariances, the stretch observables and deformation index of ellipsoids, and the
// Hochmuth fit on synthetic data.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numbers>
#include <numeric>
#include <random>
#include <vector>

#include "core/error.hpp"
#include "experiments/hochmuth.hpp"
#include "experiments/observables.hpp"
#include "mesh/icosphere.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

double thickness(const ThicknessProfile& p, std::size_t k) { return p.zHigh[k] - p.zLow[k]; }

double maxEdgeLength(const Vertices& X, const Faces& F) {
    double l = 0.0;
    for (Eigen::Index f = 0; f < F.cols(); ++f)
        for (int a = 0; a < 3; ++a) l = std::max(l, (X.col(F(a, f)) - X.col(F((a + 1) % 3, f))).norm());
    return l;
}

// Error bound for the thickness of a mesh whose vertices lie on the axisymmetric surface
// z = +-f(r). Linear interpolation on a triangle errs by at most M R^2 / 2 (Waldron 1998), R the
// radius of its smallest enclosing circle (<= l/sqrt 3 for longest edge l) and M the largest second
// directional derivative over it; the Hessian of f(|x|) has eigenvalues f'' and f'/r, and a triangle
// hit at radius r lies within [r - l, r + l]. Two surfaces: |h - 2 f| <= l^2/3 max(|f''|, |f'/r|).
double interpolationBound(const std::function<double(double)>& f, double r, double l, double rMax) {
    const double d = 1e-5;
    double M = 0.0;
    const double a = std::max(r - l, 10 * d), b = std::min(r + l, rMax - d);
    for (double s = a; s <= b; s += l / 50) {
        const double f2 = (f(s + d) - 2 * f(s) + f(s - d)) / (d * d), f1 = (f(s + d) - f(s - d)) / (2 * d);
        M = std::max({M, std::abs(f2), std::abs(f1 / s)});
    }
    return l * l / 3 * M;
}

Mesh relabelled(const Mesh& m, unsigned seed) {
    std::vector<int> perm(static_cast<std::size_t>(m.numVertices()));
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), std::mt19937(seed));  // old i -> new perm[i]
    Mesh out{Vertices(3, m.numVertices()), Faces(3, m.numFaces())};
    for (Eigen::Index i = 0; i < m.numVertices(); ++i) out.X.col(perm[static_cast<std::size_t>(i)]) = m.X.col(i);
    for (Eigen::Index f = 0; f < m.numFaces(); ++f)
        for (int a = 0; a < 3; ++a) out.F(a, f) = perm[static_cast<std::size_t>(m.F(a, f))];
    return out;
}

Mesh rigidlyMovedAndRelabelled(const Mesh& m, unsigned seed) {
    Mesh out = relabelled(m, seed);
    out.X = (test::randomRotation(seed) * out.X).colwise() + Eigen::Vector3d(3.0, -1.5, 7.25);
    return out;
}

/// Octahedron with vertices (+-a,0,0), (0,+-b,0), (0,0,+-c), turned by phi about z.
Mesh octahedron(double a, double b, double c, double phi = 0.0) {
    Mesh m{Vertices(3, 6), Faces(3, 8)};
    m.X << a, -a, 0, 0, 0, 0,  //
        0, 0, b, -b, 0, 0,     //
        0, 0, 0, 0, c, -c;
    m.X = Eigen::AngleAxisd(phi, Eigen::Vector3d::UnitZ()).toRotationMatrix() * m.X;
    int f = 0;
    for (int i : {0, 1})
        for (int j : {2, 3})
            for (int k : {4, 5}) m.F.col(f++) = Eigen::Vector3i(i, j, k);  // orientation is irrelevant here
    return m;
}

// --- sliced ray casting -------------------------------------------------------------------------

TEST(ThicknessProfile, ExactOnPolyhedraWithVerticesEdgesAndFacesInTheRayPlane) {
    {   // Axis-aligned octahedron: 4 vertices and 4 edges in y = 0, last ray exactly through (1,0,0).
        const Mesh m = octahedron(1, 1, 1);
        const ThicknessProfile p = thicknessProfile(m.X, m.F, 2.0, 21);  // r_k = k/10
        ASSERT_EQ(p.r.size(), 11u);                                     // rays beyond r = 1 miss
        EXPECT_EQ(p.r.back(), 1.0);
        for (std::size_t k = 0; k < p.r.size(); ++k) {
            EXPECT_NEAR(p.zHigh[k], 1.0 - p.r[k], 1e-15);
            EXPECT_NEAR(p.zLow[k], p.r[k] - 1.0, 1e-15);
        }
    }
    {   // Shifted to x in [1, 3]: rays exactly through both x-extreme vertices, where every slice
        // segment ends (inclusive bounds on both sides); rays at r = 0 and 4 miss.
        Mesh m = octahedron(1, 1, 1);
        m.X.row(0).array() += 2.0;
        const ThicknessProfile p = thicknessProfile(m.X, m.F, 4.0, 5);
        ASSERT_EQ(p.r.size(), 3u);
        for (std::size_t k = 0; k < 3; ++k) {
            EXPECT_EQ(p.r[k], 1.0 + static_cast<double>(k));
            EXPECT_NEAR(thickness(p, k), k == 1 ? 2.0 : 0.0, 1e-15);
        }
    }
    {   // Turned by 45 degrees: the slice has edge crossings and a vertex-plus-crossing case; the
        // last ray passes exactly through the crossing point (c, 0, 0).
        const double c = std::sqrt(0.5);
        Mesh m = octahedron(1, 1, 1, std::numbers::pi / 4);
        m.X(1, 4) = m.X(1, 5) = 0.0;  // the poles exactly in the plane
        m.X.col(0) << c, c, 0;        // and the rim exactly symmetric about it
        m.X.col(1) << -c, -c, 0;
        m.X.col(2) << -c, c, 0;
        m.X.col(3) << c, -c, 0;
        const ThicknessProfile p = thicknessProfile(m.X, m.F, c, 11);
        ASSERT_EQ(p.r.size(), 11u);
        for (std::size_t k = 0; k < p.r.size(); ++k) EXPECT_NEAR(thickness(p, k), 2.0 * (1.0 - p.r[k] / c), 1e-15);
        EXPECT_EQ(thickness(p, 10), 0.0);
    }
    {   // Tetrahedron with a whole face in y = 0: the slice is that face, h(r) = 2 - r on [0, 2].
        Mesh m{Vertices(3, 4), Faces(3, 4)};
        m.X << 0, 2, -1, 0,  //
            0, 0, 0, 1,      //
            -1, 1, 1, 0;
        m.F << 0, 0, 0, 1,  //
            2, 1, 3, 2,     //
            1, 3, 2, 3;
        const ThicknessProfile p = thicknessProfile(m.X, m.F, 2.0, 9);
        ASSERT_EQ(p.r.size(), 9u);
        for (std::size_t k = 0; k < p.r.size(); ++k) {
            EXPECT_NEAR(p.zLow[k], p.r[k] - 1.0, 1e-15);
            EXPECT_NEAR(p.zHigh[k], 1.0, 1e-15);
        }
    }
    const Mesh m = octahedron(1, 1, 1);
    EXPECT_THROW(thicknessProfile(m.X, m.F, 1.0, 1), InputError);
    EXPECT_THROW(thicknessProfile(m.X, m.F, 0.0), InputError);
    EXPECT_THROW(thicknessProfile(m.X, m.F, std::nan("")), InputError);
    Faces badF = m.F;
    badF(1, 2) = 6;
    EXPECT_THROW(thicknessProfile(m.X, badF, 1.0), InputError);
    Vertices badX = m.X;
    badX(1, 0) = std::nan("");
    EXPECT_THROW(thicknessProfile(badX, m.F, 1.0), NumericalError);
}

TEST(ThicknessProfile, NoRayLostOnTheMirrorPlaneOfTheEvansFungMesh) {
    // Unaligned Evans-Fung icosphere: y = 0 is a mirror plane of the mesh, so many vertices and edges
    // lie exactly in the ray plane, and the last ray passes exactly through the rim vertex (R0, 0, 0).
    const EvansFung ef;
    for (int level : {3, 4}) {
        const Mesh s = icosphere(level);
        const Vertices X = evansFungMap(s.X);
        ASSERT_GT((X.row(1).array() == 0.0).count(), 0);
        const ThicknessProfile p = thicknessProfile(X, s.F, ef.R0);
        ASSERT_EQ(p.r.size(), 2000u) << "level " << level;
        EXPECT_EQ(thickness(p, 1999), 0.0);
        for (std::size_t k = 0; k < p.r.size(); ++k) EXPECT_NEAR(p.zHigh[k], -p.zLow[k], 1e-14);  // z-mirror
    }
}

// --- equilibrium observables ------- ----------------------------------------------------------------

TEST(EquilibriumObservables, EvansFungCellMatchesTheAnalyticProfile) {
    const EvansFung ef;
    const auto f = [&](double r) { return 0.5 * evansFungThickness(r, ef); };
    double hMaxExact = 0.0, rMaxExact = 0.0;  // analytic maximum by dense sampling (error ~1e-9)
    for (int i = 0; i <= 100000; ++i) {
        const double r = ef.R0 * i / 100000;
        if (evansFungThickness(r) > hMaxExact) {
            hMaxExact = evansFungThickness(r);
            rMaxExact = r;
        }
    }
    for (int level : {4, 5}) {
        const Mesh s = icosphere(level);
        const Vertices X = evansFungMap(s.X);
        const double l = maxEdgeLength(X, s.F);
        ThicknessProfile p;
        const EquilibriumObservables o = equilibriumObservables(X, s.F, &p);
        EXPECT_NEAR(o.D, 2 * ef.R0, 0.01 * 2 * ef.R0);
        // Every ray hits, except perhaps the last, at r = D/2, which touches the rim at one point: the
        // rounding of the build's instruction set decides whether its slice reaches it.
        EXPECT_GE(p.r.size(), 1999u);
        EXPECT_LE(p.r.size(), 2000u);
        // Pointwise against h = 2 f inside 0.9 R0 (beyond it f'' ~ (R0 - r)^{-3/2} and the bound is void).
        double worstRatio = 0.0, tolExtrema = 0.0;
        for (std::size_t k = 0; k < p.r.size() && p.r[k] <= 0.9 * ef.R0; ++k) {
            const double tol = interpolationBound(f, p.r[k], l, ef.R0);
            const double err = std::abs(thickness(p, k) - evansFungThickness(p.r[k]));
            EXPECT_LE(err, tol) << "level " << level << " r = " << p.r[k];
            worstRatio = std::max(worstRatio, err / tol);
            tolExtrema = std::max(tolExtrema, tol);
        }
        // h >= h(0) up to r* and h_EF(r*) >= max h_EF - 2 tol, so the same bound covers the extrema.
        EXPECT_NEAR(o.hmin, evansFungThickness(0.0), tolExtrema) << "level " << level;
        EXPECT_NEAR(o.hmax, hMaxExact, tolExtrema) << "level " << level;
        EXPECT_NEAR(o.rAtHmax, rMaxExact, std::sqrt(4 * tolExtrema / 1.75) + l) << "level " << level;  // |h''| = 1.75 there
        EXPECT_LT(o.rAtHmax, 0.8 * ef.R0);
        RecordProperty("worst_error_over_bound_L" + std::to_string(level), std::to_string(worstRatio));
    }
}

TEST(EquilibriumObservables, InvariantUnderRigidMotionAndRelabelling) {
    // A slightly elliptic Evans-Fung cell has a well-defined principal frame, so everything is
    // invariant to round-off. The sign of the aligned x axis (the half-line) is arbitrary, but the
    // mesh is mirror-symmetric in x, so both half-lines see the same profile.
    const Mesh s = icosphere(4);
    Mesh cell{evansFungMap(s.X), s.F};
    cell.X.row(1) *= 0.9;
    const EquilibriumObservables ref = equilibriumObservables(cell.X, cell.F);
    for (unsigned seed : {1u, 2u, 3u}) {
        const Mesh moved = rigidlyMovedAndRelabelled(cell, seed);
        const EquilibriumObservables o = equilibriumObservables(moved.X, moved.F);
        EXPECT_NEAR(o.D, ref.D, 1e-9);
        EXPECT_NEAR(o.hmin, ref.hmin, 1e-9);
        EXPECT_NEAR(o.hmax, ref.hmax, 1e-9);
        EXPECT_NEAR(o.rAtHmax, ref.rAtHmax, 1e-9);
    }
    // The axisymmetric cell has an isotropic in-plane covariance: the in-plane axes, and with them
    // the half-line, are chosen by round-off. The observables then vary with the azimuth only at the
    // discretisation level: D by the chord sag of the rim polygon (< l^2/R0 for the two sides), the
    // thicknesses by the interpolation bound of the analytic-profile test over r <= 0.8 R0.
    const EvansFung ef;
    const auto f = [&](double r) { return 0.5 * evansFungThickness(r, ef); };
    const Mesh round{evansFungMap(s.X), s.F};
    const double l = maxEdgeLength(round.X, round.F);
    double tol = 0.0;
    for (double r = 0.0; r <= 0.8 * ef.R0; r += 0.01) tol = std::max(tol, interpolationBound(f, r, l, ef.R0));
    const EquilibriumObservables a = equilibriumObservables(round.X, round.F);
    for (unsigned seed : {4u, 5u, 6u}) {
        const Mesh moved = rigidlyMovedAndRelabelled(round, seed);
        const EquilibriumObservables o = equilibriumObservables(moved.X, moved.F);
        EXPECT_NEAR(o.D, a.D, l * l / ef.R0);
        EXPECT_NEAR(o.hmin, a.hmin, 2 * tol);
        EXPECT_NEAR(o.hmax, a.hmax, 2 * tol);
    }
}

TEST(EquilibriumObservables, ConvexShapesHaveNoDimple) {
    {   // Octahedron with distinct axes: h(r) = 2 (1 - r/2) along x, largest at the centre.
        const Mesh m = rigidlyMovedAndRelabelled(octahedron(2.0, 1.5, 1.0), 7);
        ThicknessProfile p;
        const EquilibriumObservables o = equilibriumObservables(m.X, m.F, &p);
        EXPECT_NEAR(o.D, 3.5, 1e-12);
        EXPECT_NEAR(o.hmax, 2.0, 1e-12);
        EXPECT_EQ(o.hmin, o.hmax);
        EXPECT_EQ(o.rAtHmax, 0.0);
        ASSERT_EQ(p.r.size(), 2000u);
        for (std::size_t k = 0; k < p.r.size(); ++k) EXPECT_NEAR(thickness(p, k), 2.0 - p.r[k], 1e-12);
    }
    {   // Sphere of radius 2: h(r) = 2 sqrt(R^2 - r^2) up to the interpolation bound. The polyhedron
        // is not exactly largest on the axis, so r* and hmax - hmin are only small, not zero.
        const double R = 2.0;
        const Mesh s = icosphere(4);
        const Mesh m = rigidlyMovedAndRelabelled(Mesh{R * s.X, s.F}, 8);
        const double l = maxEdgeLength(m.X, m.F);
        const auto f = [&](double r) { return std::sqrt(std::max(R * R - r * r, 0.0)); };
        ThicknessProfile p;
        const EquilibriumObservables o = equilibriumObservables(m.X, m.F, &p);
        EXPECT_NEAR(o.D, 2 * R, l * l / R);  // rim vertices of a chord polygon
        for (std::size_t k = 0; k < p.r.size() && p.r[k] <= 0.9 * R; ++k)
            EXPECT_NEAR(thickness(p, k), 2 * f(p.r[k]), interpolationBound(f, p.r[k], l, R)) << p.r[k];
        const double tol0 = interpolationBound(f, 0.0, l, R);
        EXPECT_NEAR(o.hmax, 2 * R, tol0);
        EXPECT_LE(o.hmax - o.hmin, tol0);
        EXPECT_LE(o.rAtHmax, std::sqrt(2 * R * tol0));  // where 2 f(r) has dropped by tol0
    }
}

// --- stretching / relaxation extents --------------------------------------------------------------------------

TEST(StretchObservables, EllipsoidExtentsAndDeformationIndex) {
    const Mesh s = icosphere(3);  // has the vertices (+-1,0,0), (0,+-1,0), (0,0,+-1)
    for (const Eigen::Vector3d& semi : {Eigen::Vector3d(3.0, 2.0, 1.0), Eigen::Vector3d(1.2, 4.0, 2.5)}) {
        const Mesh ell{semi.asDiagonal() * s.X, s.F};
        std::array<double, 3> e = {2 * semi[0], 2 * semi[1], 2 * semi[2]};
        std::sort(e.begin(), e.end(), std::greater<>());
        for (unsigned seed : {0u, 11u, 12u}) {
            const Mesh m = seed == 0 ? ell : rigidlyMovedAndRelabelled(ell, seed);
            const StretchObservables o = stretchObservables(m.X);
            EXPECT_NEAR(o.D1, e[0], 1e-9);
            EXPECT_NEAR(o.D0, e[1], 1e-9);
            EXPECT_NEAR(deformationIndex(m.X), e[0] / e[1], 1e-9);
        }
    }
    EXPECT_THROW(stretchObservables(Vertices(3, 0)), InputError);
    Vertices bad = s.X;
    bad(0, 3) = std::nan("");
    EXPECT_THROW(deformationIndex(bad), NumericalError);
}

// --- relaxation Hochmuth fit ---------------------------------------------------------------------------

/// 100 samples at 0.01 s intervals starting at t = 0.01 s (the fit uses t - t[0]).
std::vector<double> sampleTimes() {
    std::vector<double> t(100);
    for (std::size_t k = 0; k < t.size(); ++k) t[k] = 0.01 * static_cast<double>(k + 1);
    return t;
}

TEST(Hochmuth, LawMatchesTheLambdaForm) {
    const double z0 = 2.2, zInf = 1.1, tc = 0.169, L = (z0 + zInf) / (z0 - zInf);
    EXPECT_NEAR(hochmuthLaw(0.0, z0, zInf, tc), z0, 1e-15);
    EXPECT_NEAR(hochmuthLaw(100.0, z0, zInf, tc), zInf, 1e-15);
    for (double t : {0.01, 0.1, 0.5}) {
        const double e = std::exp(-t / tc);
        EXPECT_NEAR(hochmuthLaw(t, z0, zInf, tc), zInf * (L + e) / (L - e), 1e-14);
    }
    EXPECT_EQ(hochmuthLaw(0.3, 1.5, 1.5, tc), 1.5);  // regular at zInf = z0
}

TEST(Hochmuth, RecoversNoiseFreeParametersFromTheStandardGuess) {
    const std::vector<double> t = sampleTimes();
    for (double tc : {0.005, 0.015, 0.05, 0.169, 0.5, 2.0})
        for (double zInf : {0.8, 1.0, 1.5})
            for (double z0 : {1.2, 2.0, 3.0}) {
                std::vector<double> z(t.size());
                for (std::size_t k = 0; k < t.size(); ++k) z[k] = hochmuthLaw(t[k] - t[0], z0, zInf, tc);
                const HochmuthFit fit = fitHochmuth(t, z);
                ASSERT_TRUE(fit.converged) << tc << " " << zInf << " " << z0 << ": " << fit.message;
                EXPECT_NEAR(fit.tc / tc, 1.0, 1e-6) << tc << " " << zInf << " " << z0;
                EXPECT_NEAR(fit.zInf / zInf, 1.0, 1e-6) << tc << " " << zInf << " " << z0;
                EXPECT_EQ(fit.z0, z[0]);
                EXPECT_LT(fit.rms, 1e-9);
            }
}

TEST(Hochmuth, NoisyDataWithinFourStandardErrors) {
    // Gaussian noise sigma = 0.01 on z (z0 = z[0] kept exact); the tolerance is 4 linearised standard
    // errors, sqrt(sigma^2 (J^T J)^{-1}) with J = d z(t_k)/d(tc, zInf) at the true parameters.
    const std::vector<double> t = sampleTimes();
    const double sigma = 0.01, z0 = 2.0;
    std::mt19937 rng(2024);
    std::normal_distribution<double> noise(0.0, sigma);
    for (const auto& [tc, zInf] : {std::pair{0.169, 1.1}, std::pair{0.03, 1.3}, std::pair{0.8, 1.0}}) {
        std::vector<double> z(t.size());
        Eigen::MatrixXd J(static_cast<Eigen::Index>(t.size()), 2);
        for (std::size_t k = 0; k < t.size(); ++k) {
            const double tau = t[k] - t[0], h = 1e-6;
            z[k] = hochmuthLaw(tau, z0, zInf, tc) + (k > 0 ? noise(rng) : 0.0);
            const auto i = static_cast<Eigen::Index>(k);
            J(i, 0) = (hochmuthLaw(tau, z0, zInf, tc * (1 + h)) - hochmuthLaw(tau, z0, zInf, tc * (1 - h))) / (2 * h * tc);
            J(i, 1) = (hochmuthLaw(tau, z0, zInf + h, tc) - hochmuthLaw(tau, z0, zInf - h, tc)) / (2 * h);
        }
        const Eigen::Matrix2d cov = sigma * sigma * (J.transpose() * J).inverse();
        const HochmuthFit fit = fitHochmuth(t, z);
        ASSERT_TRUE(fit.converged) << fit.message;
        EXPECT_NEAR(fit.tc, tc, 4 * std::sqrt(cov(0, 0))) << "tc " << tc;
        EXPECT_NEAR(fit.zInf, zInf, 4 * std::sqrt(cov(1, 1))) << "tc " << tc;
        EXPECT_NEAR(fit.rms, sigma, 0.3 * sigma);
    }
}

TEST(Hochmuth, BadInputsThrowAndDegenerateDataAreReported) {
    const std::vector<double> t = {0.0, 0.1, 0.2, 0.3}, z = {2.0, 1.6, 1.4, 1.3};
    EXPECT_THROW(fitHochmuth(t, {2.0, 1.6, 1.4}), InputError);                    // sizes differ
    EXPECT_THROW(fitHochmuth({0.0, 0.1}, {2.0, 1.5}), InputError);                // < 3 points
    EXPECT_THROW(fitHochmuth(t, {2.0, std::nan(""), 1.4, 1.3}), InputError);     // not finite
    EXPECT_THROW(fitHochmuth({0.0, 0.1, 0.1, 0.3}, z), InputError);               // t not increasing
    EXPECT_THROW(fitHochmuth({0.0, 0.2, 0.1, 0.3}, z), InputError);
    EXPECT_THROW(fitHochmuth(t, {1.0, 1.1, 1.2, 1.3}), InputError);               // z0 = zInf guess
    EXPECT_THROW(fitHochmuth(t, z, 0.0), InputError);                             // tc guess
    EXPECT_THROW(fitHochmuth(t, z, -0.015), InputError);
    // Data that do not relax: tc is undetermined, reported as such with finite numbers.
    const HochmuthFit flat = fitHochmuth(t, {1.5, 1.5, 1.5, 1.5});
    EXPECT_FALSE(flat.converged);
    EXPECT_FALSE(flat.message.empty());
    EXPECT_TRUE(std::isfinite(flat.tc) && std::isfinite(flat.zInf) && std::isfinite(flat.rms));
}

}  // namespace
}  // namespace trbc
