// The in-plane laws beside Lim (docs/MEMBRANE_MODEL.md, in-plane laws): neo-Hookean and Skalak.
// Analytic gradients against central finite differences, Cauchy tensions of uniform biaxial
// stretches against their closed forms, the small-strain shear and area-dilation moduli, the
// parameter checks and `trbc forces --law`.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

#include "core/error.hpp"
#include "membrane/kernels.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/io.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

using test::meshPath;

MembraneParameters lawParameters(InPlaneLaw law, double Gs, double C = 0.0) {
    MembraneParameters p;
    p.law = law;
    p.capsule = {Gs, C};
    return p;
}

// W(lambda1, lambda2) of a law, and the Cauchy tension T1 = (1/lambda2) dW/dlambda1 (force per
// deformed length along the lambda2 direction, acting along lambda1); T2 by symmetry.
struct Law {
    InPlaneLaw law;
    double Gs, C;
    const char* name;
};

double energyDensity(const Law& l, double l1, double l2) {
    const double I1 = l1 * l1 + l2 * l2 - 2.0, I2 = l1 * l1 * l2 * l2 - 1.0;
    if (l.law == InPlaneLaw::NeoHookean) return 0.5 * l.Gs * (I1 - 1.0 + 1.0 / (I2 + 1.0));
    return 0.25 * l.Gs * (I1 * I1 + 2.0 * I1 - 2.0 * I2 + l.C * I2 * I2);
}

// Neo-Hookean: T1 = Gs/(l1 l2) (l1^2 - 1/(l1 l2)^2);
// Skalak:      T1 = Gs l1/l2 (l1^2 - 1 + C l2^2 (l1^2 l2^2 - 1)).
double cauchyTension(const Law& l, double l1, double l2) {
    const double J = l1 * l2;
    if (l.law == InPlaneLaw::NeoHookean) return l.Gs / J * (l1 * l1 - 1.0 / (J * J));
    return l.Gs * l1 / l2 * (l1 * l1 - 1.0 + l.C * l2 * l2 * (J * J - 1.0));
}

const Law kLaws[] = {{InPlaneLaw::NeoHookean, 1.3, 0.0, "neo_hookean"},
                     {InPlaneLaw::Skalak, 0.8, 1.7, "skalak_c1.7"},
                     {InPlaneLaw::Skalak, 1.1, -0.3, "skalak_c-0.3"}};

MembraneParameters lawParameters(const Law& l) { return lawParameters(l.law, l.Gs, l.C); }

// A flat patch [0, L] x [0, H] (z = 0) as a closed surface: two sheets of n x n squares with
// opposite orientations and different diagonals that share the boundary vertices (a flattened
// closed surface; without bending its dihedral angles play no part). Interior vertices of each
// sheet are jittered in the plane so that the triangles are irregular.
struct Patch {
    Mesh mesh;
    std::vector<int> left, right, bottom, top, interior;  // boundary sides include the corners
    double L, H;
};

Patch flatPatch(int n, double L, double H, unsigned seed) {
    Patch p;
    p.L = L;
    p.H = H;
    const int nb = (n + 1) * (n + 1), ni = (n - 1) * (n - 1);
    const auto top = [&](int i, int j) { return j * (n + 1) + i; };
    const auto onBoundary = [&](int i, int j) { return i == 0 || j == 0 || i == n || j == n; };
    const auto bottom = [&](int i, int j) { return onBoundary(i, j) ? top(i, j) : nb + (j - 1) * (n - 1) + (i - 1); };
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-0.3, 0.3);
    p.mesh.X.resize(3, nb + ni);
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const double x = L * i / n, y = H * j / n;
            const bool inner = !onBoundary(i, j);
            p.mesh.X.col(top(i, j)) << x + (inner ? u(rng) * L / n : 0.0), y + (inner ? u(rng) * H / n : 0.0), 0.0;
            if (inner) p.mesh.X.col(bottom(i, j)) << x + u(rng) * L / n, y + u(rng) * H / n, 0.0;
            if (i == 0) p.left.push_back(top(i, j));
            if (i == n) p.right.push_back(top(i, j));
            if (j == 0) p.bottom.push_back(top(i, j));
            if (j == n) p.top.push_back(top(i, j));
        }
    for (int v = nb; v < nb + ni; ++v) p.interior.push_back(v);
    for (int j = 1; j < n; ++j)
        for (int i = 1; i < n; ++i) p.interior.push_back(top(i, j));
    p.mesh.F.resize(3, 4 * n * n);
    int f = 0;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            // Top sheet, counter-clockwise seen from +z, diagonal 00-11.
            p.mesh.F.col(f++) << top(i, j), top(i + 1, j), top(i + 1, j + 1);
            p.mesh.F.col(f++) << top(i, j), top(i + 1, j + 1), top(i, j + 1);
            // Bottom sheet, clockwise seen from +z, diagonal 10-01.
            p.mesh.F.col(f++) << bottom(i, j), bottom(i, j + 1), bottom(i + 1, j);
            p.mesh.F.col(f++) << bottom(i + 1, j), bottom(i, j + 1), bottom(i + 1, j + 1);
        }
    return p;
}

Vertices stretched(const Vertices& X, double l1, double l2) {
    return Eigen::Vector3d(l1, l2, 1.0).asDiagonal() * X;
}

double sumComponent(const Vertices& g, const std::vector<int>& vertices, int k) {
    double s = 0.0;
    for (int v : vertices) s += g(k, v);
    return s;
}

// --- Kernel: invariants and energy of one triangle -------------------------------------------------------------

TEST(InPlaneLawKernel, InvariantsAndEnergyOfARotatedBiaxialMap) {
    // Principal stretches (l1, l2) along axes at angle phi in the plane of a random triangle, then
    // rotated in space: I1 = l1^2 + l2^2 - 2, I2 = l1^2 l2^2 - 1 and U_t = A0 W(l1, l2).
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const Eigen::Matrix3d R = test::randomRotation(8);
    for (const auto& [l1, l2] : {std::pair{1.3, 0.9}, std::pair{0.7, 0.7}, std::pair{2.0, 1.0}, std::pair{1.05, 1.0 / 1.05}}) {
        for (int trial = 0; trial < 4; ++trial) {
            const Eigen::Vector3d Xi(u(rng), u(rng), 0), Xj(u(rng), u(rng), 0), Xk(u(rng), u(rng), 0);
            const double phi = u(rng) * std::numbers::pi;
            Eigen::Matrix3d Q;
            Q << std::cos(phi), -std::sin(phi), 0, std::sin(phi), std::cos(phi), 0, 0, 0, 1;
            const Eigen::Matrix3d Fmap = R * Q * Eigen::Vector3d(l1, l2, 1).asDiagonal() * Q.transpose();
            const Eigen::Vector3d a = Fmap * (Xj - Xi), b = Fmap * (Xk - Xi);
            const auto r = kernels::limReference(Xi, Xj, Xk);
            const double area = 0.5 * a.cross(b).norm();
            const Law nh = kLaws[0], sk = kLaws[1];
            const auto fn = kernels::capsuleFace<InPlaneLaw::NeoHookean>({nh.Gs, 0.0}, r, a, b, area);
            const auto fs = kernels::capsuleFace<InPlaneLaw::Skalak>({sk.Gs, sk.C}, r, a, b, area);
            const double I1 = l1 * l1 + l2 * l2 - 2.0, I2 = l1 * l1 * l2 * l2 - 1.0;
            for (const auto* fc : {&fn, &fs}) {
                EXPECT_NEAR(fc->I1, I1, 1e-12 * std::max(1.0, std::abs(I1)));
                EXPECT_NEAR(fc->I2, I2, 1e-12 * std::max(1.0, std::abs(I2)));
            }
            EXPECT_NEAR(fn.energy, r.area0 * energyDensity(nh, l1, l2), 1e-12 * std::max(1.0, std::abs(fn.energy)));
            EXPECT_NEAR(fs.energy, r.area0 * energyDensity(sk, l1, l2), 1e-12 * std::max(1.0, std::abs(fs.energy)));
        }
    }
}

// --- Model: gradient, net force and torque --------------------------------------------------------------------

struct GradientCase {
    std::string name;
    Mesh mesh;
    Vertices reference;
};

std::vector<GradientCase> gradientCases() {
    std::vector<GradientCase> cases;
    {
        Mesh ref = icosphere(2);
        ref.X *= 0.93;
        cases.push_back({"perturbed_L2", test::perturbedIcosphere(2, 0.15, 7), ref.X});
    }
    {
        Mesh m = test::perturbedIcosphere(3, 0.1, 11);
        m.X.row(2) *= 0.4;  // flattened: strong compression and shear
        cases.push_back({"perturbed_flat_L3", m, icosphere(3).X});
    }
    cases.push_back({"rbc_642", readOff(meshPath("rbc_642.off")), readOff(meshPath("sphere_642.off")).X});
    return cases;
}

class InPlaneLawGradient : public ::testing::TestWithParam<std::tuple<int, int, bool>> {
protected:
    static const std::vector<GradientCase>& cases() {
        static const std::vector<GradientCase> c = gradientCases();
        return c;
    }
    const GradientCase& testCase() const { return cases()[std::get<1>(GetParam())]; }
    const Law& law() const { return kLaws[std::get<0>(GetParam())]; }
    // With `full`, bending and the global penalties are on too (the law shares the face passes).
    MembraneParameters parameters() const {
        MembraneParameters p = lawParameters(law());
        if (std::get<2>(GetParam())) {
            const Mesh& m = testCase().mesh;
            p.bending.kb = 0.2;
            p.penalty = {2.0, 0.9 * totalArea(m.X, m.F), 3.0, 0.8 * enclosedVolume(m.X, m.F)};
        }
        return p;
    }
};

TEST_P(InPlaneLawGradient, AnalyticGradientMatchesCentralFiniteDifferences) {
    const GradientCase& c = testCase();
    const MembraneModel m(c.mesh.F, c.mesh.numVertices(), parameters(), &c.reference);
    Vertices g;
    EnergyTerms terms;
    const double e = m.evaluate(c.mesh.X, &g, &terms);
    ASSERT_TRUE(std::isfinite(e));
    ASSERT_GT(terms.capsule, 0.0);
    EXPECT_EQ(terms.lim, 0.0);
    const Vertices gfd = test::finiteDifferenceGradient(m, c.mesh.X, 1e-5 * test::meanEdgeLength(c.mesh));
    const double err = test::relativeMaxError(g, gfd);
    EXPECT_LE(err, 1e-6) << law().name << " on " << c.name;
    RecordProperty("relative_fd_error", std::to_string(err));
}

TEST_P(InPlaneLawGradient, ForcesSumToZeroAndExertNoTorque) {
    const GradientCase& c = testCase();
    Vertices g;
    MembraneModel(c.mesh.F, c.mesh.numVertices(), parameters(), &c.reference).evaluate(c.mesh.X, &g);
    const Eigen::Vector3d centre = centroid(c.mesh.X);
    Eigen::Vector3d net = g.rowwise().sum(), torque = Eigen::Vector3d::Zero();
    double scaleF = 0.0, scaleT = 0.0;
    for (Eigen::Index i = 0; i < g.cols(); ++i) {
        const Eigen::Vector3d r = c.mesh.X.col(i) - centre;
        torque += r.cross(g.col(i));
        scaleF += g.col(i).norm();
        scaleT += r.norm() * g.col(i).norm();
    }
    EXPECT_LE(net.norm(), 1e-12 * scaleF);
    EXPECT_LE(torque.norm(), 1e-12 * scaleT);
}

std::string gradientTestName(const ::testing::TestParamInfo<InPlaneLawGradient::ParamType>& info) {
    const char* meshes[] = {"perturbed_L2", "perturbed_flat_L3", "rbc_642"};
    std::string name = std::string(kLaws[std::get<0>(info.param)].name) + "_" + meshes[std::get<1>(info.param)] +
                       (std::get<2>(info.param) ? "_full" : "");
    for (char& ch : name)
        if (ch == '.' || ch == '-') ch = '_';
    return name;
}

INSTANTIATE_TEST_SUITE_P(AllLaws, InPlaneLawGradient,
                         ::testing::Combine(::testing::Range(0, 3), ::testing::Range(0, 3), ::testing::Bool()),
                         gradientTestName);

TEST(InPlaneLaw, EnergyAndForcesVanishOnTheReference) {
    const Mesh m = readOff(meshPath("rbc_642.off"));
    for (const Law& l : kLaws) {
        const MembraneModel model(m.F, m.numVertices(), lawParameters(l), &m.X);
        Vertices g;
        EXPECT_NEAR(model.evaluate(m.X, &g), 0.0, 1e-13) << l.name;
        EXPECT_LT(g.cwiseAbs().maxCoeff(), 1e-12) << l.name;
    }
}

// --- Analytic tensions of uniform stretches -------------------------------------------------------------------

// The flat patch under x -> diag(l1, l2) x: every face has the principal stretches (l1, l2), so the
// discrete forces are those of the uniform continuum stress exactly. The force that holds the
// side x = L is -sum f_x = 2 (sheets) T1 (l2 H) (deformed length of the side); the side y = H
// likewise carries 2 T2 (l1 L). Interior vertices are in equilibrium.
TEST(InPlaneLawTension, UniformBiaxialStretchOfAFlatPatchGivesTheCauchyTensions) {
    const Patch p = flatPatch(5, 2.0, 1.3, 17);
    // (l1, 1): the strip stretched (or compressed) along x with its width held; then general (l1, l2).
    const std::pair<double, double> stretches[] = {{1.3, 1.0}, {2.0, 1.0}, {0.8, 1.0}, {1.2, 0.9}, {0.85, 1.4}};
    for (const Law& l : kLaws) {
        const MembraneModel model(p.mesh.F, p.mesh.numVertices(), lawParameters(l), &p.mesh.X);
        for (const auto& [l1, l2] : stretches) {
            Vertices g;
            EnergyTerms terms;
            model.evaluate(stretched(p.mesh.X, l1, l2), &g, &terms);
            const double T1 = cauchyTension(l, l1, l2), T2 = cauchyTension(l, l2, l1);
            const std::string what = fmt::format("{} at ({}, {})", l.name, l1, l2);
            EXPECT_NEAR(terms.capsule, 2.0 * p.L * p.H * energyDensity(l, l1, l2),
                        1e-12 * 2.0 * p.L * p.H * std::abs(energyDensity(l, l1, l2)))
                << what;
            EXPECT_NEAR(sumComponent(g, p.right, 0), 2.0 * T1 * l2 * p.H, 1e-10 * std::abs(2.0 * T1 * l2 * p.H)) << what;
            EXPECT_NEAR(sumComponent(g, p.left, 0), -2.0 * T1 * l2 * p.H, 1e-10 * std::abs(2.0 * T1 * l2 * p.H)) << what;
            EXPECT_NEAR(sumComponent(g, p.top, 1), 2.0 * T2 * l1 * p.L, 1e-10 * std::abs(2.0 * T2 * l1 * p.L)) << what;
            const double scale = std::abs(T1) + std::abs(T2);
            for (int v : p.interior) EXPECT_LT(g.col(v).norm(), 1e-11 * scale) << what << ", vertex " << v;
        }
    }
}

TEST(InPlaneLawTension, NeoHookeanUniaxialTensionHasNoLateralForceAtLambda2EqualsLambda1ToMinusOneHalf) {
    // Free sides: T2 = 0 <=> l2^2 = 1/(l1 l2)^2 <=> l2 = l1^(-1/2).
    const Patch p = flatPatch(4, 1.0, 1.0, 3);
    const Law& l = kLaws[0];
    const MembraneModel model(p.mesh.F, p.mesh.numVertices(), lawParameters(l), &p.mesh.X);
    for (double l1 : {1.5, 3.0}) {
        const double l2 = 1.0 / std::sqrt(l1);
        Vertices g;
        model.evaluate(stretched(p.mesh.X, l1, l2), &g);
        const double T1 = l.Gs / (l1 * l2) * (l1 * l1 - 1.0 / (l1 * l1 * l2 * l2));
        EXPECT_NEAR(sumComponent(g, p.right, 0), 2.0 * T1 * l2 * p.H, 1e-10 * 2.0 * T1 * l2 * p.H);
        EXPECT_LT(std::abs(sumComponent(g, p.top, 1)), 1e-12 * T1);
    }
}

// A sphere scaled by lambda: every face has the stretches (lambda, lambda). With U = A0 W(lambda, lambda)
// and the isotropic tension T = (1/lambda) dW/dlambda1 at (lambda, lambda), dU/dlambda = A0 2 lambda T,
// and the virtual work of the uniform dilation x -> (1 + d) x is sum_i x_i . dU/dx_i = lambda dU/dlambda
// = 2 A T with A = lambda^2 A0 the deformed area (the Laplace law T = p R / 2 of a sphere).
// Neo-Hookean: T = Gs (1 - lambda^-6); Skalak: T = Gs (lambda^2 - 1)(1 + C lambda^2 (lambda^2 + 1)).
TEST(InPlaneLawTension, InflatedSphereCarriesTheEquibiaxialTension) {
    const Mesh s = icosphere(3);
    const double A0 = totalArea(s.X, s.F);
    for (const Law& l : kLaws) {
        const MembraneModel model(s.F, s.numVertices(), lawParameters(l), &s.X);
        for (double lambda : {0.9, 1.1, 1.6}) {
            const Vertices X = lambda * s.X;
            Vertices g;
            const double U = model.evaluate(X, &g);
            const double L2 = lambda * lambda;
            const double T = l.law == InPlaneLaw::NeoHookean ? l.Gs * (1.0 - 1.0 / (L2 * L2 * L2))
                                                             : l.Gs * (L2 - 1.0) * (1.0 + l.C * L2 * (L2 + 1.0));
            EXPECT_NEAR(T, cauchyTension(l, lambda, lambda), 1e-13 * std::abs(T));
            EXPECT_NEAR(U, A0 * energyDensity(l, lambda, lambda), 1e-12 * std::abs(U)) << l.name;
            const double work = (X.array() * g.array()).sum(), expected = 2.0 * L2 * A0 * T;
            EXPECT_NEAR(work, expected, 1e-10 * std::abs(expected)) << l.name << " at " << lambda;
        }
    }
}

// --- Small-strain moduli ---------------------------------------------------------------------------------------

// U(eps) of the flat patch (area 2 L H) under the pure shear diag(e^eps, e^-eps) and the dilation
// diag(1 + eps, 1 + eps): W = 2 G_s eps^2 + O(eps^4) and W = 2 K_s eps^2 + O(eps^3), so
// G_s = W''(0)/4 and K_s = W''(0)/4, W'' from a central second difference (odd orders cancel).
struct Moduli {
    double shear, dilation;
};

Moduli smallStrainModuli(const MembraneModel& model, const Patch& p) {
    const double h = 1e-4, area = 2.0 * p.L * p.H;
    const auto second = [&](const std::function<Vertices(double)>& map) {
        return (model.evaluate(map(h)) - 2.0 * model.evaluate(map(0.0)) + model.evaluate(map(-h))) / (h * h) / area;
    };
    const double shear = second([&](double e) { return stretched(p.mesh.X, std::exp(e), std::exp(-e)); });
    const double dilation = second([&](double e) { return stretched(p.mesh.X, 1.0 + e, 1.0 + e); });
    return {0.25 * shear, 0.25 * dilation};
}

TEST(InPlaneLawModuli, SmallStrainShearAndAreaDilationModuli) {
    const Patch p = flatPatch(4, 1.5, 1.0, 29);
    for (const Law& l : kLaws) {
        const MembraneModel model(p.mesh.F, p.mesh.numVertices(), lawParameters(l), &p.mesh.X);
        const Moduli m = smallStrainModuli(model, p);
        const double Ks = l.law == InPlaneLaw::NeoHookean ? 3.0 * l.Gs : l.Gs * (1.0 + 2.0 * l.C);
        EXPECT_NEAR(m.shear, l.Gs, 1e-5 * l.Gs) << l.name;
        EXPECT_NEAR(m.dilation, Ks, 1e-5 * Ks) << l.name;
    }
    // Lim, for comparison: G_s = mu, K_s = Kalpha (a3, a4, b1, b2 only act beyond second order).
    MembraneParameters lim;
    lim.lim = {2.7, -2.0, 8.0, 1.1, 0.7, 1.5};
    const Moduli m = smallStrainModuli(MembraneModel(p.mesh.F, p.mesh.numVertices(), lim, &p.mesh.X), p);
    EXPECT_NEAR(m.shear, 1.1, 1e-5 * 1.1);
    EXPECT_NEAR(m.dilation, 2.7, 1e-4 * 2.7);
}

// --- Lim stays the default -------------------------------------------------------------------------------------

TEST(InPlaneLaw, LimIsTheDefaultAndTheCapsuleModuliDoNotTouchIt) {
    const Mesh m = readOff(meshPath("rbc_642.off")), s = readOff(meshPath("sphere_642.off"));
    MembraneParameters lim;
    lim.bending.kb = 0.3;
    lim.lim = {1.0, -2.0, 8.0, 1.0, 0.7, 0.75};
    EXPECT_EQ(lim.law, InPlaneLaw::Lim);
    EXPECT_TRUE(lim.hasLim());
    EXPECT_FALSE(lim.hasCapsuleLaw());
    MembraneParameters withCapsule = lim;
    withCapsule.capsule = {2.0, 0.5};  // ignored under the Lim law
    Vertices g1, g2;
    EnergyTerms t1, t2;
    const double e1 = MembraneModel(m.F, m.numVertices(), lim, &s.X).evaluate(m.X, &g1, &t1);
    const double e2 = MembraneModel(m.F, m.numVertices(), withCapsule, &s.X).evaluate(m.X, &g2, &t2);
    EXPECT_EQ(e1, e2);
    EXPECT_EQ(t1.lim, t2.lim);
    EXPECT_EQ(t2.capsule, 0.0);
    EXPECT_EQ((g1 - g2).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_NEAR(t1.lim, 5.901502527, 1e-8 * 5.901502527);  // ReferenceValues.LimEnergyOfRbc642AgainstSphere642

    // Under another law the Lim moduli are off, and the capsule energy goes to EnergyTerms::capsule.
    MembraneParameters nh = lim;
    nh.law = InPlaneLaw::NeoHookean;
    nh.capsule.Gs = 2.0;
    EXPECT_FALSE(nh.hasLim());
    EXPECT_TRUE(nh.hasCapsuleLaw());
    EnergyTerms t3;
    MembraneModel(m.F, m.numVertices(), nh, &s.X).evaluate(m.X, nullptr, &t3);
    EXPECT_EQ(t3.lim, 0.0);
    EXPECT_GT(t3.capsule, 0.0);
    EXPECT_EQ(t3.bending, t1.bending);
}

TEST(InPlaneLaw, ModelWithoutReferenceIsRejected) {
    const Mesh m = readOff(meshPath("rbc_642.off"));
    try {
        [[maybe_unused]] const MembraneModel model(m.F, m.numVertices(), lawParameters(InPlaneLaw::Skalak, 1.0, 0.5));
        FAIL() << "no InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("Skalak in-plane term needs a stress-free reference"), std::string::npos)
            << e.what();
    }
    MembraneModel model(m.F, m.numVertices(), MembraneParameters{});
    EXPECT_THROW(model.setParameters(lawParameters(InPlaneLaw::NeoHookean, 1.0)), InputError);
}

// --- Parameter checks ------------------------------------------------------------------------------------------

void expectInputError(const MembraneParameters& p, const std::string& fragment) {
    try {
        checkedMembraneParameters(p, false, 0.0, false, 0.0, "--");
        ADD_FAILURE() << "no InputError, expected one with '" << fragment << "'";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
}

TEST(InPlaneLawParameters, BadModuliAndModuliOfAnotherLawAreRejected) {
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    expectInputError(lawParameters(InPlaneLaw::NeoHookean, -1.0), "--Gs = -1 is out of range");
    expectInputError(lawParameters(InPlaneLaw::NeoHookean, nan), "--Gs must be a finite number");
    expectInputError(lawParameters(InPlaneLaw::Skalak, inf, 1.0), "--Gs must be a finite number");
    expectInputError(lawParameters(InPlaneLaw::Skalak, 1.0, -0.5), "--skalak-c = -0.5 is out of range");
    expectInputError(lawParameters(InPlaneLaw::Skalak, 1.0, -0.5), "> -1/2");
    expectInputError(lawParameters(InPlaneLaw::Skalak, 1.0, nan), "--skalak-c must be a finite number");
    // Moduli of a law that is not the chosen one.
    expectInputError(lawParameters(InPlaneLaw::Lim, 1.0), "--Gs = 1 is a modulus of the neo-hookean and skalak laws, but --law is lim");
    expectInputError(lawParameters(InPlaneLaw::NeoHookean, 1.0, 0.3), "--skalak-c = 0.3 is a modulus of the skalak law, but --law is neo-hookean");
    MembraneParameters p = lawParameters(InPlaneLaw::Skalak, 1.0, 0.3);
    p.lim.mu = 2.0;
    expectInputError(p, "--mu = 2 is a modulus of the lim law, but --law is skalak");
    p.lim = {0.0, 0.0, 0.0, 0.0, 0.0, 1.5};
    expectInputError(p, "--b2 = 1.5 is a modulus of the lim law");

    // Accepted: each law with its own moduli, Skalak C just above -1/2, Gs = 0 (term off).
    EXPECT_NO_THROW(checkedMembraneParameters(lawParameters(InPlaneLaw::NeoHookean, 2.0), false, 0, false, 0));
    EXPECT_NO_THROW(checkedMembraneParameters(lawParameters(InPlaneLaw::Skalak, 2.0, -0.499), false, 0, false, 0));
    EXPECT_NO_THROW(checkedMembraneParameters(lawParameters(InPlaneLaw::Skalak, 0.0, 0.0), false, 0, false, 0));
    MembraneParameters lim;
    lim.lim = {1, -2, 8, 1, 0.7, 0.75};
    EXPECT_NO_THROW(checkedMembraneParameters(lim, false, 0, false, 0));
    EXPECT_STREQ(inPlaneLawName(InPlaneLaw::NeoHookean), "neo-hookean");
}

// --- trbc forces --law -----------------------------------------------------------------------------------------

Vertices readForces(const std::filesystem::path& path, Eigen::Index nv) {
    std::ifstream in(path);
    std::string line;
    do std::getline(in, line);  // past the provenance line
    while (!line.empty() && line[0] == '#');
    EXPECT_EQ(line, "fx,fy,fz");
    Vertices f(3, nv);
    Eigen::Index i = 0;
    while (std::getline(in, line) && i < nv) {
        std::stringstream ss(line);
        std::string tok;
        for (int k = 0; k < 3 && std::getline(ss, tok, ','); ++k) f(k, i) = std::stod(tok);
        ++i;
    }
    EXPECT_EQ(i, nv);
    return f;
}

TEST(CliForcesLaw, NeoHookeanAndSkalakMatchTheLibrary) {
    test::TempDir tmp;
    const std::string mesh = meshPath("rbc_642.off"), ref = meshPath("sphere_642.off");
    const Mesh m = readOff(mesh), s = readOff(ref);
    struct Row {
        std::string args, key;
        MembraneParameters p;
    };
    const Row rows[] = {{"--law neo-hookean --Gs 1.3", "neo-hookean", lawParameters(InPlaneLaw::NeoHookean, 1.3)},
                        {"--law skalak --Gs 0.8 --skalak-c 1.7", "skalak", lawParameters(InPlaneLaw::Skalak, 0.8, 1.7)}};
    for (const Row& r : rows) {
        const auto out = tmp.path() / (r.key + ".csv");
        const auto run = test::runTrbc("forces --mesh " + mesh + " --reference " + ref + " " + r.args + " --out " +
                                           test::shellQuote(out.string()),
                                       tmp.path());
        ASSERT_EQ(run.status, 0) << run.err;
        const auto j = nlohmann::json::parse(run.out);
        const MembraneModel model(m.F, m.numVertices(), r.p, &s.X);
        Vertices g;
        const double e = model.evaluate(m.X, &g);
        EXPECT_NEAR(j["energy"].get<double>(), e, 1e-12 * e) << r.key;
        EXPECT_NEAR(j["terms"][r.key].get<double>(), e, 1e-12 * e) << r.key;
        EXPECT_FALSE(j["terms"].contains("lim"));
        EXPECT_LE(test::relativeMaxError(readForces(out, m.numVertices()), -g), 1e-14) << r.key;
    }
}

TEST(CliForcesLaw, BadLawOptionsExitTwoNamingTheOption) {
    test::TempDir tmp;
    const std::string base = "forces --mesh " + meshPath("rbc_642.off") + " --reference " + meshPath("sphere_642.off") +
                             " --out " + test::shellQuote((tmp.path() / "f.csv").string()) + " ";
    const std::pair<std::string, std::string> cases[] = {
        {"--law hooke --Gs 1", "--law"},
        {"--law neo-hookean --Gs -1", "--Gs"},
        {"--law skalak --Gs 1 --skalak-c -0.5", "--skalak-c"},
        {"--law skalak --Gs 1 --skalak-c nan", "--skalak-c"},
        {"--Gs 1", "--Gs = 1 is a modulus of the neo-hookean and skalak laws, but --law is lim"},
        {"--law neo-hookean --Gs 1 --skalak-c 2", "--skalak-c = 2 is a modulus of the skalak law"},
        {"--law skalak --Gs 1 --mu 1", "--mu = 1 is a modulus of the lim law, but --law is skalak"},
    };
    for (const auto& [args, fragment] : cases) {
        const auto run = test::runTrbc(base + args, tmp.path());
        EXPECT_EQ(run.status, 2) << args;
        EXPECT_NE(run.err.find(fragment), std::string::npos) << args << ": " << run.err;
    }
    const auto noRef = test::runTrbc("forces --mesh " + meshPath("rbc_642.off") + " --law skalak --Gs 1 --out " +
                                         test::shellQuote((tmp.path() / "g.csv").string()),
                                     tmp.path());
    EXPECT_EQ(noRef.status, 2);
    EXPECT_NE(noRef.err.find("--reference"), std::string::npos) << noRef.err;
}

}  // namespace
}  // namespace trbc
