// Boundary-integral Stokes flow around one closed surface, against exact solutions on the unit
// sphere (radius a = 1, vertices of the icosphere on the sphere):
//  * operator identities: int G dS = 16 pi a/3 I, int G . n dS = 0, double layer of rigid motions;
//  * rigid sphere translating: drag F = -6 pi mu a U; rotating: torque -8 pi mu a^3 Omega;
//  * drop (viscosity ratio lambda) driven by a force F: Hadamard-Rybczynski velocity;
//  * freely suspended rigid sphere in simple shear: Omega = -gamma/2 e_z, U = 0.
// Production resolution: icosphere level 3 (642 vertices), every case within 1 %. The level 1-4
// table of docs/flow_verification.md comes from bench/stokes_convergence_table.
#include <gtest/gtest.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "core/error.hpp"
#include "core/simd.hpp"
#include "flow/boundary_integral.hpp"
#include "flow/stokes_kernels.hpp"
#include "flow/stokes_solver.hpp"
#include "flow/stokes_verification.hpp"
#include "mesh/icosphere.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kProductionLevel = 3;


using stokes_verification::hadamardRybczynskiErrors;
using stokes_verification::rotatingSphereError;
using stokes_verification::shearedSphereErrors;
using stokes_verification::translatingSphereError;

// ---- Kernels and operators.

TEST(StokesKernels, StokesletAndStressletAreSymmetricAndHomogeneous) {
    const Eigen::Vector3d d(0.3, -1.2, 0.7), n(0.1, 0.4, -0.9);
    const Eigen::Matrix3d G = stokes::stokeslet(d), K = stokes::stressletNormal(d, n);
    EXPECT_LT((G - G.transpose()).norm(), 1e-15);
    EXPECT_LT((K - K.transpose()).norm(), 1e-15);
    // G is homogeneous of degree -1, T of degree -2.
    EXPECT_LT((stokes::stokeslet(2.0 * d) - 0.5 * G).norm(), 1e-14);
    EXPECT_LT((stokes::stressletNormal(2.0 * d, n) - 0.25 * K).norm(), 1e-14);
    // K_ij = T_ijk n_k.
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double s = 0.0;
            for (int k = 0; k < 3; ++k) s += stokes::stresslet(d, i, j, k) * n[k];
            EXPECT_NEAR(K(i, j), s, 1e-14);
        }
    // Scalar form used by the loops.
    const Eigen::Vector3d g(1.0, 2.0, -0.5);
    double ux = 0, uy = 0, uz = 0;
    stokes::addStokeslet(d.x(), d.y(), d.z(), 1.0 / d.norm(), 0.7, g.x(), g.y(), g.z(), ux, uy, uz);
    EXPECT_LT((Eigen::Vector3d(ux, uy, uz) - 0.7 * G * g).norm(), 1e-14);
    const double c = stokes::doubleLayerCoefficient(d.x(), d.y(), d.z(), 1.0 / d.norm(), 0.7 * n.x(),
                                                    0.7 * n.y(), 0.7 * n.z());
    EXPECT_LT((c * d * d.transpose() - 0.7 * K).norm(), 1e-14);
}

TEST(StokesOperators, SphereIdentities) {
    const BoundaryIntegralOperators ops(icosphere(kProductionLevel));
    const Eigen::Index nv = ops.numVertices();
    // int G dS = 16 pi a / 3 I at points of the sphere (uniform density).
    const Eigen::Vector3d e(0.2, -0.6, 1.0);
    const Eigen::Matrix3Xd S1 = ops.singleLayer(e.replicate(1, nv));
    const double sRef = 16.0 * kPi / 3.0;
    EXPECT_LT((S1.colwise() - sRef * e).colwise().norm().maxCoeff() / (sRef * e.norm()), 5e-3);
    // int G . n dS = 0.
    const Eigen::Matrix3Xd Sn = ops.singleLayer(ops.vertexNormals());
    EXPECT_LT(Sn.colwise().norm().maxCoeff() / sRef, 5e-3);
    // Double layer of rigid-body motions: -4 pi u (exact for translations by construction).
    const Eigen::Matrix3Xd Dt = ops.doubleLayer(e.replicate(1, nv));
    EXPECT_LT((Dt + 4.0 * kPi * e.replicate(1, nv)).norm(), 1e-10 * Dt.norm());
    Eigen::Matrix3Xd rot(3, nv);
    for (Eigen::Index i = 0; i < nv; ++i) rot.col(i) = e.cross(ops.mesh().X.col(i));
    // (for a rotation u(x) - u(x0) = w x (x - x0) is orthogonal to x - x0, so the subtracted
    // integrand vanishes pointwise and the result is exact as well).
    const Eigen::Matrix3Xd Dr = ops.doubleLayer(rot);
    EXPECT_LT((Dr + 4.0 * kPi * rot).norm(), 1e-10 * Dr.norm());
    // Double layer of the normal field: on a sphere n is an eigenfunction with eigenvalue +4 pi
    // (int n(x) . T(x - x0) . n(x) dS = 4 pi n(x0)). The flat faces miss the O(h^2) curvature
    // terms of (n(x) - n(x0)) . T . n near x0: 1.5 % at level 3, 0.6 % at level 4.
    const Eigen::Matrix3Xd Dn = ops.doubleLayer(ops.vertexNormals());
    EXPECT_LT((Dn - 4.0 * kPi * ops.vertexNormals()).colwise().norm().maxCoeff() / (4.0 * kPi), 2e-2);
}

TEST(StokesOperators, DenseAssemblyEqualsMatrixFreeApply) {
    const BoundaryIntegralOperators ops(icosphere(2));
    const Eigen::Index nv = ops.numVertices();
    Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Random(3, nv);
    const Eigen::Map<const Eigen::VectorXd> fv(f.data(), 3 * nv);
    const Eigen::Matrix3Xd S = ops.singleLayer(f), D = ops.doubleLayer(f);
    const Eigen::VectorXd Sd = ops.assembleSingleLayer() * fv, Dd = ops.assembleDoubleLayer() * fv;
    EXPECT_LT((Eigen::Map<const Eigen::VectorXd>(S.data(), 3 * nv) - Sd).norm(), 1e-12 * Sd.norm());
    EXPECT_LT((Eigen::Map<const Eigen::VectorXd>(D.data(), 3 * nv) - Dd).norm(), 1e-12 * Dd.norm());
}

TEST(StokesOperators, FusedPassAndSymmetricBlockProductsEqualTheSeparateForms) {
    const BoundaryIntegralOperators ops(icosphere(2));
    const Eigen::Index nv = ops.numVertices();
    const Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Random(3, nv), u = Eigen::Matrix3Xd::Random(3, nv);
    Eigen::Matrix3Xd Sf, Du;
    ops.layers(f, u, Sf, Du);
    const Eigen::Matrix3Xd S = ops.singleLayer(f), D = ops.doubleLayer(u);
    EXPECT_LT((Sf - S).norm(), 1e-13 * S.norm());
    EXPECT_LT((Du - D).norm(), 1e-13 * D.norm());
    // The block product against the full matrix it stands for.
    const SymmetricBlockMatrix B = ops.assembleDoubleLayerBlocks();
    Eigen::Matrix3Xd Bu(3, nv);
    B.multiply(u.data(), Bu.data());
    const Eigen::VectorXd Fu = B.toDense() * Eigen::Map<const Eigen::VectorXd>(u.data(), 3 * nv);
    EXPECT_LT((Eigen::Map<const Eigen::VectorXd>(Bu.data(), 3 * nv) - Fu).norm(), 1e-13 * Fu.norm());
    EXPECT_LT((Bu - D).norm(), 1e-12 * D.norm());
}

TEST(StokesOperators, CornerCentroidAndFaceRulesAgreeToTheQuadratureError) {
    // Both far rules are of degree 2; on the level-3 sphere they differ by ~5e-5 of the largest
    // value, far less than the flat-face error (~4e-3, docs/flow_verification.md), and they do differ.
    QuadratureOptions faces;
    faces.farRule = FarRule::FacePoints;
    const BoundaryIntegralOperators a(icosphere(kProductionLevel)), b(icosphere(kProductionLevel), faces);
    EXPECT_EQ(a.numQuadraturePoints(), a.numVertices() + a.mesh().numFaces());
    EXPECT_EQ(b.numQuadraturePoints(), 3 * b.mesh().numFaces());
    Eigen::Matrix3Xd f(3, a.numVertices());
    for (Eigen::Index i = 0; i < f.cols(); ++i) {
        const Eigen::Vector3d x = a.mesh().X.col(i);
        f.col(i) = Eigen::Vector3d(x.y() * x.z(), 1.0 + x.x(), x.x() * x.y());
    }
    const Eigen::Matrix3Xd Sa = a.singleLayer(f), Sb = b.singleLayer(f);
    const Eigen::Matrix3Xd Da = a.doubleLayer(f), Db = b.doubleLayer(f);
    EXPECT_LT((Sa - Sb).cwiseAbs().maxCoeff(), 2e-4 * Sb.cwiseAbs().maxCoeff());
    EXPECT_LT((Da - Db).cwiseAbs().maxCoeff(), 2e-4 * Db.cwiseAbs().maxCoeff());
    EXPECT_GT((Sa - Sb).cwiseAbs().maxCoeff(), 1e-9 * Sb.cwiseAbs().maxCoeff());
}

/// The cell-like test geometry of the single-precision tests: flattened to 0.3 in y, moved off
/// the origin by 5 in x (8 x 2.4 x 8 for the unit sphere).
void flattenOffCentre(Mesh& m) {
    m.X.row(1) *= 0.3;
    m.X.row(0).array() += 5.0;
}
/// Smooth densities on the vertices: f for the single layer, u for the double layer.
void smoothDensities(const Eigen::Matrix3Xd& X, Eigen::Matrix3Xd& f, Eigen::Matrix3Xd& u) {
    f.resize(3, X.cols());
    u.resize(3, X.cols());
    for (Eigen::Index i = 0; i < X.cols(); ++i) {
        const Eigen::Vector3d x = X.col(i);
        f.col(i) = Eigen::Vector3d(x.y() * x.z(), 1.0 + x.x(), x.x() * x.y());
        u.col(i) = Eigen::Vector3d(std::sin(x.z()), x.x() * x.x() - 2.0, std::cos(x.y()));
    }
}

TEST(StokesOperators, SinglePrecisionFarSumAgreesWithDoubleToItsRounding) {
    // A flattened, off-centre cell (8 x 2.4 x 8 in R_A-like units) at the production level, smooth
    // densities: the float far sum moves S f and D u by 8e-8 and 5e-8 of their largest value
    // (measured), far below the flat-face error (~4e-3, docs/flow_verification.md).
    Mesh m = icosphere(kProductionLevel);
    flattenOffCentre(m);
    QuadratureOptions single;
    single.singlePrecisionFar = true;
    const BoundaryIntegralOperators a(m), b(m, single);
    const Eigen::Index nv = a.numVertices();
    Eigen::Matrix3Xd f, u, rot(3, nv);
    smoothDensities(m.X, f, u);
    const Eigen::Vector3d w(0.3, -1.0, 0.5), e(0.2, -0.6, 1.0);
    for (Eigen::Index i = 0; i < nv; ++i) rot.col(i) = w.cross(Eigen::Vector3d(m.X.col(i)));
    Eigen::Matrix3Xd Sa, Da, Sb, Db;
    a.layers(f, u, Sa, Da);
    b.layers(f, u, Sb, Db);
    const double sErr = (Sa - Sb).cwiseAbs().maxCoeff() / Sa.cwiseAbs().maxCoeff();
    const double dErr = (Da - Db).cwiseAbs().maxCoeff() / Da.cwiseAbs().maxCoeff();
    EXPECT_LT(sErr, 5e-7);
    EXPECT_LT(dErr, 5e-7);
    EXPECT_GT(sErr, 1e-12);  // the float path did run
    // Rigid-body motions keep D = -4 pi: exact for translations (u_q - u0 vanishes in float too),
    // to the rounding for rotations.
    EXPECT_LT((b.doubleLayer(e.replicate(1, nv)) + 4.0 * kPi * e.replicate(1, nv)).norm(), 1e-10 * 4.0 * kPi * e.norm() * nv);
    const Eigen::Matrix3Xd Dr = b.doubleLayer(rot);
    EXPECT_LT((Dr + 4.0 * kPi * rot).cwiseAbs().maxCoeff(), 5e-7 * (4.0 * kPi * rot).cwiseAbs().maxCoeff());  // 4e-8
    // Linear to the rounding (9e-8): S(f + 2u) = S f + 2 S u, which GMRES at 1e-6 relies on.
    const Eigen::Matrix3Xd lin = b.singleLayer(f + 2.0 * u) - b.singleLayer(f) - 2.0 * b.singleLayer(u);
    EXPECT_LT(lin.cwiseAbs().maxCoeff(), 5e-7 * b.singleLayer(f + 2.0 * u).cwiseAbs().maxCoeff());
}

/// With AVX2 + FMA the float far sum takes the targets two at a time and the odd last one alone; an
/// icosphere has an even vertex count, so one face is split at its centroid (lifted onto the
/// sphere): 163 vertices, the last one on the one-target path, the last points in a partial
/// chunk of eight; then flattened off-centre.
Mesh oddVertexCell() {
    Mesh m = icosphere(2);
    const Eigen::Index nv0 = m.X.cols(), nf0 = m.F.cols();
    const Eigen::Vector3i f0 = m.F.col(0);
    m.X.conservativeResize(3, nv0 + 1);
    m.X.col(nv0) = (m.X.col(f0[0]) + m.X.col(f0[1]) + m.X.col(f0[2])).normalized();
    m.F.conservativeResize(3, nf0 + 2);
    m.F.col(0) = Eigen::Vector3i(f0[0], f0[1], int(nv0));
    m.F.col(nf0) = Eigen::Vector3i(f0[1], f0[2], int(nv0));
    m.F.col(nf0 + 1) = Eigen::Vector3i(f0[2], f0[0], int(nv0));
    flattenOffCentre(m);
    return m;
}

TEST(StokesOperators, SinglePrecisionFarSumOnAnOddVertexCountAgreesWithDouble) {
    const Mesh m = oddVertexCell();
    QuadratureOptions single;
    single.singlePrecisionFar = true;
    const BoundaryIntegralOperators a(m), b(m, single);
    const Eigen::Index nv = a.numVertices();
    ASSERT_EQ(nv % 2, 1);
    ASSERT_NE(a.numQuadraturePoints() % 8, 0);
    Eigen::Matrix3Xd f, u;
    smoothDensities(m.X, f, u);
    Eigen::Matrix3Xd Sa, Da, Sb, Db;
    a.layers(f, u, Sa, Da);
    b.layers(f, u, Sb, Db);
    EXPECT_LT((Sa - Sb).cwiseAbs().maxCoeff(), 5e-7 * Sa.cwiseAbs().maxCoeff());
    EXPECT_LT((Da - Db).cwiseAbs().maxCoeff(), 5e-7 * Da.cwiseAbs().maxCoeff());
    // The last target (alone) and its neighbour in index (in a pair) to the same precision.
    for (const Eigen::Index i : {nv - 2, nv - 1}) {
        EXPECT_LT((Sa.col(i) - Sb.col(i)).norm(), 5e-7 * Sa.cwiseAbs().maxCoeff()) << i;
        EXPECT_LT((Da.col(i) - Db.col(i)).norm(), 5e-7 * Da.cwiseAbs().maxCoeff()) << i;
    }
    EXPECT_TRUE(Sb.allFinite() && Db.allFinite());
}

TEST(StokesOperators, EverySimdPathTheCpuOffersAgreesWithThePortablePath) {
    // The far sums' paths (core/simd.hpp) forced one by one on the odd-vertex cell: each agrees with
    // the portable path to the float rounding, and a path other than the portable one changes the
    // last bits (it ran).
    const Mesh m = oddVertexCell();
    QuadratureOptions single;
    single.singlePrecisionFar = true;
    const BoundaryIntegralOperators ops(m, single);
    Eigen::Matrix3Xd f, u;
    smoothDensities(m.X, f, u);
    const simd::Path saved = simd::active();
    Eigen::Matrix3Xd S0, D0;
    simd::force(simd::Path::portable);
    ops.layers(f, u, S0, D0);
    int tried = 0;
    for (const simd::Path p : {simd::Path::avx2}) {
        if (!simd::cpuOffers(p)) continue;
        ++tried;
        simd::force(p);
        Eigen::Matrix3Xd S, D;
        ops.layers(f, u, S, D);
        const Eigen::Matrix3Xd Sf = ops.singleLayer(f), Du = ops.doubleLayer(u);
        EXPECT_LT((S - S0).cwiseAbs().maxCoeff(), 5e-7 * S0.cwiseAbs().maxCoeff()) << simd::name(p);
        EXPECT_LT((D - D0).cwiseAbs().maxCoeff(), 5e-7 * D0.cwiseAbs().maxCoeff()) << simd::name(p);
        EXPECT_GT((S - S0).cwiseAbs().maxCoeff(), 0.0) << simd::name(p);
        EXPECT_LT((Sf - S).cwiseAbs().maxCoeff(), 5e-7 * S0.cwiseAbs().maxCoeff()) << simd::name(p);
        EXPECT_LT((Du - D).cwiseAbs().maxCoeff(), 5e-7 * D0.cwiseAbs().maxCoeff()) << simd::name(p);
    }
    simd::force(saved);
    if (tried == 0) GTEST_SKIP() << "this CPU offers the portable path only";
}

TEST(Simd, PathNamesParseAndBadNamesAreRefused) {
    EXPECT_EQ(simd::parse("portable", "--x"), simd::Path::portable);
    EXPECT_EQ(simd::parse("avx2", "--x"), simd::Path::avx2);
    try {
        simd::parse("avx9", "environment variable TRBC_SIMD");
        FAIL() << "avx9 accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("TRBC_SIMD: 'avx9' is not a SIMD path (valid: portable, avx2)"), std::string::npos)
            << e.what();
    }
    EXPECT_TRUE(simd::cpuOffers(simd::Path::portable));
    EXPECT_NE(simd::buildTarget().find(simd::name(simd::active())), std::string::npos) << simd::buildTarget();
}

TEST(StokesOperators, ResultDoesNotDependOnThreads) {
    for (const bool single : {false, true}) {
        QuadratureOptions q;
        q.singlePrecisionFar = single;
        const BoundaryIntegralOperators ops(icosphere(2), q);
        const Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Random(3, ops.numVertices());
        const int saved = omp_get_max_threads();
        omp_set_num_threads(1);
        const Eigen::Matrix3Xd S1 = ops.singleLayer(f), D1 = ops.doubleLayer(f);
        Eigen::Matrix3Xd L1s, L1d, L2s, L2d;
        ops.layers(f, f, L1s, L1d);
        omp_set_num_threads(2);
        const Eigen::Matrix3Xd S2 = ops.singleLayer(f), D2 = ops.doubleLayer(f);
        ops.layers(f, f, L2s, L2d);
        omp_set_num_threads(saved);
        EXPECT_EQ(S1, S2) << single;
        EXPECT_EQ(D1, D2) << single;
        EXPECT_EQ(L1s, L2s) << single;
        EXPECT_EQ(L1d, L2d) << single;
    }
}

// ---- Verification at the production level.

TEST(StokesRigidBody, TranslatingSphereHasStokesDrag) {
    const BoundaryIntegralOperators ops(icosphere(kProductionLevel));
    EXPECT_LT(translatingSphereError(ops), 0.01);
}

TEST(StokesRigidBody, RotatingSphereHasStokesTorque) {
    const BoundaryIntegralOperators ops(icosphere(kProductionLevel));
    EXPECT_LT(rotatingSphereError(ops), 0.01);
}

TEST(StokesRigidBody, FreeSphereInSimpleShearRotatesAtHalfTheShearRate) {
    const auto [motion, stresslet] = shearedSphereErrors(kProductionLevel);
    EXPECT_LT(motion, 0.01);
    EXPECT_LT(stresslet, 0.01);
}

TEST(StokesRigidBody, MatrixFreeAndDenseAgree) {
    const BoundaryIntegralOperators ops(icosphere(2));
    GmresOptions dense, free;
    dense.mode = OperatorMode::Dense;
    free.mode = OperatorMode::MatrixFree;
    const RigidBodyResult a = solveRigidBodyMobility(ops, 1.0, Eigen::Vector3d::Zero(),
                                                     LinearFlow::simpleShear(1.0), Eigen::Vector3d(0, 0, 1),
                                                     Eigen::Vector3d::Zero(), dense);
    const RigidBodyResult b = solveRigidBodyMobility(ops, 1.0, Eigen::Vector3d::Zero(),
                                                     LinearFlow::simpleShear(1.0), Eigen::Vector3d(0, 0, 1),
                                                     Eigen::Vector3d::Zero(), free);
    EXPECT_LT((a.velocity - b.velocity).norm(), 1e-7);
    EXPECT_LT((a.angularVelocity - b.angularVelocity).norm(), 1e-7);
    // Force balance holds and the sphere sediments at about F / (6 pi mu a).
    EXPECT_LT((a.force + Eigen::Vector3d(0, 0, 1)).norm(), 1e-7);
    EXPECT_NEAR(a.velocity.z(), 1.0 / (6.0 * kPi), 0.02 / (6.0 * kPi));
}

TEST(StokesDrop, HadamardRybczynskiVelocity) {
    const BoundaryIntegralOperators ops(icosphere(kProductionLevel));
    for (const double lambda : {0.1, 1.0, 5.0}) {
        const auto [u, field] = hadamardRybczynskiErrors(ops, lambda);
        EXPECT_LT(u, 0.01) << "lambda = " << lambda;
        EXPECT_LT(field, 0.02) << "lambda = " << lambda;
    }
}

TEST(StokesDrop, InterfaceInUniformFlowMovesWithIt) {
    // No traction jump: the drop is advected, u = u_inf for any lambda (second-kind equation:
    // (I - kappa D) U = 2/(1+lambda) U since D U = -4 pi U).
    const BoundaryIntegralOperators ops(icosphere(2));
    const Eigen::Vector3d U(1.0, -2.0, 0.5);
    const InterfaceResult r = solveInterfaceVelocity(ops, 1.0, 3.0,
                                                     Eigen::Matrix3Xd::Zero(3, ops.numVertices()),
                                                     LinearFlow::uniform(U));
    EXPECT_LT((r.velocity.colwise() - U).norm(), 1e-6 * U.norm());
}

// ---- Errors.

TEST(StokesErrors, BadInputsThrowInputError) {
    const BoundaryIntegralOperators ops(icosphere(1));
    const Eigen::Vector3d z = Eigen::Vector3d::Zero();
    const Eigen::Matrix3Xd df = Eigen::Matrix3Xd::Zero(3, ops.numVertices());
    auto expectInput = [](auto&& call, const std::string& word) {
        try {
            call();
            ADD_FAILURE() << "no exception; expected one naming " << word;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    expectInput([&] { solveRigidBodyResistance(ops, 0.0, z, z, z); }, "viscosity");
    expectInput([&] { solveRigidBodyMobility(ops, -1.0, z); }, "viscosity");
    expectInput([&] { solveInterfaceVelocity(ops, std::nan(""), 1.0, df); }, "viscosity");
    expectInput([&] { solveInterfaceVelocity(ops, 1.0, 0.0, df); }, "lambda");
    expectInput([&] { solveInterfaceVelocity(ops, 1.0, -2.0, df); }, "lambda");
    expectInput([&] { solveInterfaceVelocity(ops, 1.0, 2.0, Eigen::Matrix3Xd::Zero(3, 5)); }, "traction jump");
    GmresOptions bad;
    bad.restart = 0;
    expectInput([&] { solveRigidBodyResistance(ops, 1.0, z, z, z, {}, bad); }, "restart");
    QuadratureOptions q;
    q.farPoints = 4;
    expectInput([&] { BoundaryIntegralOperators(icosphere(1), q); }, "farPoints");
    // Open mesh: one face removed.
    Mesh open = icosphere(1);
    open.F.conservativeResize(3, open.F.cols() - 1);
    EXPECT_THROW(BoundaryIntegralOperators{open}, InputError);
}

TEST(StokesErrors, GmresNonConvergenceThrowsNumericalError) {
    const BoundaryIntegralOperators ops(icosphere(2));
    GmresOptions g;
    g.maxIterations = 3;
    g.restart = 3;
    try {
        solveRigidBodyResistance(ops, 1.0, Eigen::Vector3d(1, 0, 0), Eigen::Vector3d::Zero(),
                                 Eigen::Vector3d::Zero(), {}, g);
        ADD_FAILURE() << "no exception";
    } catch (const NumericalError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("residual"), std::string::npos) << msg;
        EXPECT_NE(msg.find("3 iterations"), std::string::npos) << msg;
    }
}

}  // namespace
}  // namespace trbc

