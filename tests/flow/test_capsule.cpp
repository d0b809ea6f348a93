// An initially spherical capsule in simple shear (flow/capsule.hpp), the solver's check on a
// deformable membrane: the equivalent ellipsoid on exact shapes, and at level 3 the small-
// deformation law of Barthes-Biesel & Rallison (1981), D12 = (5/8)(3 + G_s/K_s) Ca, with its
// angle and membrane frequency, its independence of the viscosity ratio, the finite-Ca
// neo-Hookean deformation and the bending case against the published values
// (docs/flow_verification.md, capsules). A run without the area constraint keeps the volume.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "core/error.hpp"
#include "flow/capsule.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;

TEST(EquivalentEllipsoid, AStretchedAndTurnedIcosphereGivesItsAxesAndAngle) {
    // The subdivided icosahedron keeps the icosahedral symmetry, so its tensor of second moments
    // is isotropic; a linear stretch diag(1.2, 0.8, 1) then turned by 30 deg about z has exactly
    // L / B = 1.5, D12 = 0.2, W / L = 1 / 1.2 and the inclination 30 deg.
    const Mesh s = icosphere(3);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(kPi / 6.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Vertices X = (R * Eigen::Vector3d(1.2, 0.8, 1.0).asDiagonal() * s.X).colwise() + Eigen::Vector3d(0.3, -2.0, 1.0);
    const EquivalentEllipsoid e = equivalentEllipsoid(X, s.F);
    EXPECT_NEAR(e.L / e.B, 1.5, 1e-12);
    EXPECT_NEAR(taylorDeformation(e), 0.2, 1e-12);
    EXPECT_NEAR(e.W / e.L, 1.0 / 1.2, 1e-12);
    EXPECT_NEAR(e.inclination, kPi / 6.0, 1e-12);
    EXPECT_NEAR(e.volume, enclosedVolume(X, s.F), 1e-12 * e.volume);
    // A uniform ellipsoid's second moment V a^2 / 5: the semi-axes of the polyhedron approach those
    // of the smooth ellipsoid it is inscribed in.
    EXPECT_NEAR(e.L, 1.2, 0.01);
    // Turned by -60 deg the long axis keeps e_x > 0: inclination in (-90, 90].
    const Eigen::Matrix3d R2 = Eigen::AngleAxisd(-kPi / 3.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    EXPECT_NEAR(equivalentEllipsoid(R2 * Eigen::Vector3d(1.2, 0.8, 1.0).asDiagonal() * s.X, s.F).inclination, -kPi / 3.0, 1e-12);
}

TEST(CapsuleFlow, BadCasesAreRefusedWithTheirRange) {
    CapsuleCase c;
    c.capillary = 0.0;
    EXPECT_THROW(validateCapsuleCase(c), InputError);
    c = CapsuleCase{};
    c.skalakC = -0.5;
    EXPECT_THROW(validateCapsuleCase(c), InputError);
    c = CapsuleCase{};
    c.viscosityRatio = -1.0;
    EXPECT_THROW(validateCapsuleCase(c), InputError);
    c = CapsuleCase{};
    c.strain = 200.0;  // 2e5 frames: more than the 1e5 allowed
    c.frameInterval = 1e-3;
    EXPECT_THROW(validateCapsuleCase(c), InputError);
    c = CapsuleCase{};
    c.level = 6;
    EXPECT_THROW(validateCapsuleCase(c), InputError);
}

// Runs without a bending modulus of their own carry EB = 1e-3 (scripts/capsule_verification.py):
// without bending the compressed part of the membrane wrinkles at the grid scale and D12 does not
// settle (docs/flow_verification.md, capsules).
constexpr double kRegularisingBending = 1e-3;

CapsuleResult run(InPlaneLaw law, double ca, double lambda, double bending = kRegularisingBending, double strain = 6.0) {
    CapsuleCase c;
    c.law = law;
    c.capillary = ca;
    c.viscosityRatio = lambda;
    c.bending = bending;
    c.level = 3;
    c.strain = strain;
    return runCapsule(c);
}

struct SmallDeformationCase {
    InPlaneLaw law;
    double lambda;
    double slope;  ///< (5/8)(3 + G_s / K_s)
};

class CapsuleSmallDeformation : public ::testing::TestWithParam<SmallDeformationCase> {};

TEST_P(CapsuleSmallDeformation, FollowsBarthesBiesel) {
    const SmallDeformationCase p = GetParam();
    const CapsuleResult r = run(p.law, 0.01, p.lambda);
    ASSERT_TRUE(r.completed) << r.message;
    EXPECT_TRUE(r.steady) << r.d12Variation;
    EXPECT_NEAR(r.taylorD12 / 0.01, p.slope, 0.03 * p.slope);
    // 45 deg as Ca -> 0; at Ca = 0.01 the O(Ca) correction grows with lambda (44.3, 43.9 and 41.9 deg
    // for lambda = 0.2, 1 and 5 at level 4).
    EXPECT_NEAR(r.inclinationDeg, 45.0, p.lambda > 1.0 ? 4.0 : 2.0);
    EXPECT_NEAR(r.membraneFrequencyOverRate, 0.5, 0.02);
}

INSTANTIATE_TEST_SUITE_P(
    Laws, CapsuleSmallDeformation,
    ::testing::Values(SmallDeformationCase{InPlaneLaw::NeoHookean, 1.0, 25.0 / 12.0},
                      SmallDeformationCase{InPlaneLaw::Skalak, 1.0, 25.0 / 12.0},
                      SmallDeformationCase{InPlaneLaw::Lim, 1.0, 2.5},
                      SmallDeformationCase{InPlaneLaw::NeoHookean, 0.2, 25.0 / 12.0},
                      SmallDeformationCase{InPlaneLaw::NeoHookean, 5.0, 25.0 / 12.0}),
    [](const ::testing::TestParamInfo<SmallDeformationCase>& i) {
        const char* law = i.param.law == InPlaneLaw::Lim ? "Lim" : i.param.law == InPlaneLaw::Skalak ? "Skalak" : "NeoHookean";
        return std::string(law) + "_lambda" + (i.param.lambda == 0.2 ? "0_2" : std::to_string(int(i.param.lambda)));
    });

TEST(CapsuleFlow, FiniteDeformationNeoHookeanLiesInThePublishedRange) {
    // Ca = 0.075, lambda = 1: about 0.150 by boundary integrals (Ramanujan & Pozrikidis 1998) and 0.163
    // by front tracking (Doddi & Bagchi 2008); trbc gives 0.1523 at level 3 and 0.1528 at level 4.
    const CapsuleResult r = run(InPlaneLaw::NeoHookean, 0.075, 1.0, kRegularisingBending, 8.0);
    ASSERT_TRUE(r.completed) << r.message;
    EXPECT_TRUE(r.steady) << r.d12Variation;
    EXPECT_GE(r.taylorD12, 0.150);
    EXPECT_LE(r.taylorD12, 0.163);
    EXPECT_LT(r.inclinationDeg, 40.0);  // below the small-deformation angle of 45 deg
    EXPECT_LT(std::abs(r.areaChange), 0.05);
}

TEST(CapsuleFlow, BendingCaseLiesInThePublishedRange) {
    // Neo-Hookean, Ca_E = 0.05 (Ca = 0.15), E_b / (a^2 E_s) = 0.0375 (EB = 0.1125): 0.143 (Pozrikidis
    // 2001), 0.146 (Le 2010), 0.133 (Guckenberger et al. 2016). trbc gives 0.1330 at level 3 and
    // 0.1333 at level 4, at the low end of that range; the bound below leaves the level-3 value room
    // for the last digits of another machine's arithmetic.
    const CapsuleResult r = run(InPlaneLaw::NeoHookean, 0.15, 1.0, 0.1125, 8.0);
    ASSERT_TRUE(r.completed) << r.message;
    EXPECT_TRUE(r.steady) << r.d12Variation;
    EXPECT_GE(r.taylorD12, 0.1325);
    EXPECT_LE(r.taylorD12, 0.146);
}

TEST(CapsuleFlow, TheVolumeIsHeldAndTheAreaFollowsTheLaw) {
    // No area constraint: the area grows with the deformation (an ellipsoid of the sphere's volume
    // has more area), the volume stays at the sphere's.
    const CapsuleResult r = run(InPlaneLaw::NeoHookean, 0.3, 1.0, kRegularisingBending, 3.0);
    ASSERT_TRUE(r.completed) << r.message;
    EXPECT_GT(r.areaChange, 0.01);
    EXPECT_GT(r.taylorD12, 0.3);
}

}  // namespace
}  // namespace trbc
