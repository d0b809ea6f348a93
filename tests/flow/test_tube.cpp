// One cell in a straight circular microtube (flow/tube.hpp, docs/FLOW_TUBE.md): the wall
// discretisation against exact and classical results, a short coupled run, bad input.
//  * rigid sphere translating along the axis of a tube in fluid at rest: drag
//    F = 6 pi mu a U K(beta), beta = a / R, Haberman & Sayre (1958) wall correction
//    K = (1 - 0.75857 b^5) / (1 - 2.1050 b + 2.0865 b^3 - 1.7068 b^5 + 0.72603 b^6);
//  * freely suspended rigid sphere on the axis of Poiseuille flow: velocity
//    U / U_c = (1 - 2/3 b^2 - 0.20217 b^5) / (1 - 0.75857 b^5) (Haberman & Sayre 1958; the
//    b^2 term is Faxen's law);
//  * no slip of the total flow u_P + u' at wall points between the collocation nodes;
//  * truncation of the tube.
// The tables of docs/flow_verification.md come from bench/tube_convergence_table.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>

#include "core/error.hpp"
#include "core/scratch_dir.hpp"
#include "flow/boundary_integral.hpp"
#include "flow/cell_flow.hpp"
#include "flow/stokes_verification.hpp"
#include "flow/tube.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;

using stokes_verification::dragError;
using stokes_verification::freeSphereError;
using stokes_verification::habermanFreeSpeed;
using stokes_verification::habermanK;
using stokes_verification::sphereOps;

TEST(TubeGeometry, CapsuleCriterionAndMesh) {
    // V_max(R) = R A / 2 - 2 pi R^3 / 3: a capsule of radius R and cylinder length l has
    // A = 4 pi R^2 + 2 pi R l, V = 4/3 pi R^3 + pi R^2 l.
    const double R = 1.2, l = 3.0, A = 4 * kPi * R * R + 2 * kPi * R * l, V = 4.0 / 3.0 * kPi * R * R * R + kPi * R * R * l;
    EXPECT_NEAR(maxVolumeInTube(A, R), V, 1e-12 * V);
    EXPECT_NEAR(minimumTubeRadius(A, V), R, 1e-10);
    // The cell of docs/FLOW.md (A0 = 135 um^2, V0 = 94 um^3) needs R >= 1.497 um.
    EXPECT_NEAR(minimumTubeRadius(135.0, 94.0), 1.4966, 2e-4);
    EXPECT_THROW(minimumTubeRadius(135.0, 200.0), InputError);
    // The wall: a closed, outward oriented prism of 24 flat strips with two polygonal caps.
    const Mesh m = tubeMesh(1.0, 3.0, 24);
    EXPECT_NO_THROW(BoundaryIntegralOperators{m});  // validates the closed manifold
    // Between the inscribed prism and the circular cylinder (staggered rings: the lateral faces
    // are tilted, so neither bound is attained).
    const double chord = 2.0 * std::sin(kPi / 24), polygon = 0.5 * 24 * chord * std::cos(kPi / 24);
    const double area = totalArea(m.X, m.F), volume = enclosedVolume(m.X, m.F);
    EXPECT_GT(area, 6.0 * 24 * chord + 2.0 * polygon);
    EXPECT_LT(area, 6.0 * 2.0 * kPi + 2.0 * kPi);
    EXPECT_GT(volume, 6.0 * polygon);
    EXPECT_LT(volume, 6.0 * kPi);
    EXPECT_NEAR(m.X.row(0).minCoeff(), -3.0, 1e-12);
    EXPECT_NEAR(m.X.row(0).maxCoeff(), 3.0, 1e-12);
    const Eigen::VectorXd fa = faceAreas(m.X, m.F);
    EXPECT_GT(fa.minCoeff(), 0.2 * fa.maxCoeff());
}

TEST(TubeWallOperators, OffSurfaceSingleLayerMatchesOnSurfaceFarAndResolvesNearTargets) {
    // Unit sphere: S[n] = int G . n dS = 0 at every point, and the uniform traction
    // f = -3 mu U / (2 a) of a translating sphere gives its exterior flow u = -S f / (8 pi mu)
    // (the double layer of a rigid motion vanishes outside). Targets 0.5 to 0.001 from the sphere.
    const BoundaryIntegralOperators s = sphereOps(3, 1.0);
    Eigen::Matrix3Xd targets(3, 4);
    targets << 1.5, 0.0, 0.0, 1.001,  //
        0.0, 1.2, 0.9, 0.01,             //
        0.0, 0.0, 0.5, 0.0;              // distances 0.5, 0.2, 0.03, 0.001 from the sphere
    const Eigen::Matrix3Xd un = s.singleLayerAt(targets, s.vertexNormals());
    EXPECT_LT(un.cwiseAbs().maxCoeff(), 2e-2) << un;
    const double a = 1.0;
    const Eigen::Vector3d U(1, 0, 0);
    const Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Constant(3, s.numVertices(), 0.0).colwise() + (-1.5 / a) * U;
    const Eigen::Matrix3Xd u = -s.singleLayerAt(targets, f) / (8.0 * kPi);
    for (int t = 0; t < targets.cols(); ++t) {
        const Eigen::Vector3d x = targets.col(t);
        const double r = x.norm();
        const Eigen::Vector3d ex = 0.75 * a / r * (U + x * x.dot(U) / (r * r)) +
                                   0.25 * a * a * a / (r * r * r) * (U - 3.0 * x * x.dot(U) / (r * r));
        EXPECT_LT((u.col(t) - ex).norm(), 1e-2) << t << " " << u.col(t).transpose() << " vs " << ex.transpose();
    }
    // The dense matrix is the same operator.
    const Eigen::MatrixXd A = s.assembleSingleLayerAt(targets);
    const Eigen::VectorXd v = A * Eigen::Map<const Eigen::VectorXd>(f.data(), f.size());
    EXPECT_LT((Eigen::Map<const Eigen::VectorXd>(v.data(), v.size()) * (-1.0 / (8 * kPi)) -
               Eigen::Map<const Eigen::VectorXd>(u.data(), u.size()))
                  .norm(),
              1e-12);
}

TEST(TubeWall, TranslatingSphereDragHabermanSayre) {
    // The towed sphere pushes all the displaced fluid back through the gap against the pressure
    // jump carried by the caps: the most demanding case for the wall (the error falls like
    // N^-2.7 with the points per ring, docs/flow_verification.md). 32 points per ring.
    for (const auto& [beta, tol] : {std::pair{0.3, 0.03}, std::pair{0.5, 0.05}}) {
        const TubeWall wall(1.0, beta + 2.5, 32);
        const double e = dragError(sphereOps(2, beta), wall, beta);
        std::printf("drag beta %.2f: K error %.3e (wall %ld vertices)\n", beta, e, static_cast<long>(wall.numVertices()));
        EXPECT_LT(std::abs(e), tol) << beta;
    }
}

TEST(TubeWall, FreeSphereInPoiseuilleFlowAndNoSlip) {
    const double beta = 0.4;
    const TubeWall wall(1.0, beta + 2.5, 24);
    const BoundaryIntegralOperators sphere = sphereOps(3, beta);
    RigidBodyResult r;
    const double e = freeSphereError(sphere, wall, beta, &r);
    std::printf("free sphere beta %.2f: U/Uc = %.5f, error %.3e\n", beta, r.velocity.x(), e);
    EXPECT_LT(std::abs(e), 0.01);
    EXPECT_LT(r.velocity.tail<2>().norm(), 1e-6);
    EXPECT_LT(r.angularVelocity.norm(), 1e-6);
    // No slip between the collocation nodes: total flow u_P + u' at face centroids of the wall
    // (at most 2 R from the sphere), u' = -1/(8 pi) (S_sphere f - S_wall q).
    const auto coupling = wall.couple(sphere, 0.0);
    const Vertices q = coupling->wallDensity(r.traction);
    const Mesh& wm = wall.operators().mesh();
    Eigen::Matrix3Xd targets(3, 0);
    for (Eigen::Index f = 0; f < wm.numFaces(); ++f) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int k = 0; k < 3; ++k) c += wm.X.col(wm.F(k, f)) / 3.0;
        if (std::abs(c.x()) > 2.0) continue;
        c.tail<2>() *= 1.0 / c.tail<2>().norm();  // on the circle (the continuous wall)
        targets.conservativeResize(3, targets.cols() + 1);
        targets.col(targets.cols() - 1) = c;
    }
    const Vertices u = poiseuilleVelocity(targets, 1.0, 1.0) -
                       (sphere.singleLayerAt(targets, r.traction) - wall.operators().singleLayerAt(targets, q)) / (8 * kPi);
    const double slip = u.colwise().norm().maxCoeff();
    std::printf("no-slip: max |u| at %ld wall face centroids = %.3e U_c\n", static_cast<long>(targets.cols()), slip);
    EXPECT_LT(slip, 0.01);
}

TEST(TubeWall, Truncation) {
    // Free sphere (the cell is force-free too): margin 1.5 R, 2.5 R and 4 R beyond the sphere.
    const double beta = 0.4;
    const BoundaryIntegralOperators sphere = sphereOps(2, beta);
    const double e15 = freeSphereError(sphere, TubeWall(1.0, beta + 1.5, 24), beta);
    const double e25 = freeSphereError(sphere, TubeWall(1.0, beta + 2.5, 24), beta);
    const double e40 = freeSphereError(sphere, TubeWall(1.0, beta + 4.0, 24), beta);
    std::printf("truncation: free sphere error %.3e (margin 1.5 R), %.3e (2.5 R), %.3e (4 R)\n", e15, e25, e40);
    EXPECT_LT(std::abs(e25 - e40), 2e-4);
}

// ---- The coupled cell ---------------------------------------------------------------------------


const std::filesystem::path& tubeCache() {
    static const std::filesystem::path d = processTemporaryDirectory("trbc_test_tube_cache_");
    return d;
}

TEST(TubeEnvironmentTest, RepulsionGradientAndFit) {
    TubeSetup s;
    s.radius = 1.0;
    s.centreLineSpeed = 1.0;
    s.halfLength = 2.0;
    s.pointsPerRing = 12;
    s.repulsionRange = 0.1;
    s.repulsionPressure = 3.0;
    s.vertexWeight = 0.01;
    const TubeEnvironment env(s);
    Vertices X(3, 3);
    X << 0.1, 0.2, -0.3, 0.95, 0.1, 0.0, 0.0, -0.93, 0.5;  // two vertices inside the range
    Vertices g = Vertices::Zero(3, 3);
    env.addExternalGradient(X, g);
    const double h = 1e-7;
    for (int i = 0; i < 3; ++i)
        for (int a = 0; a < 3; ++a) {
            Vertices Xp = X, Xm = X;
            Xp(a, i) += h;
            Xm(a, i) -= h;
            EXPECT_NEAR(g(a, i), (env.repulsionEnergy(Xp) - env.repulsionEnergy(Xm)) / (2 * h), 1e-5 * (1 + std::abs(g(a, i))));
        }
    EXPECT_GT(g(1, 0), 0.0);  // the force -g pushes the vertex at y = 0.95 towards the axis
    EXPECT_EQ(g.col(2).norm(), 0.0);
    // The Table 1 cell (level 2, equilibrium, disc plane x-z) fitted into a 6.6 um tube.
    const ShearCell c = prepareShearCell(paperTable1Cell(), 2, tubeCache());
    const Vertices Y = fitIntoTube(c.initial, c.faces, 3.3, 0.33, cell::area, cell::volume);
    EXPECT_GE(wallClearance(Y, 3.3), 0.33 - 1e-9);
    EXPECT_NEAR(totalArea(Y, c.faces), cell::area, 1e-8 * cell::area);
    EXPECT_NEAR(enclosedVolume(Y, c.faces), cell::volume, 1e-8 * cell::volume);
    EXPECT_GT(extents(Y).x(), extents(c.initial).x());  // stretched along the axis
    EXPECT_THROW(fitIntoTube(c.initial, c.faces, 1.4, 0.1, cell::area, cell::volume), NumericalError);
}

TEST(TubeFlow, ShortCoupledRunMovesAlongTheAxisAndKeepsAreaAndVolume) {
    const CellParameters p = paperTable1Cell();
    const ShearCell c = prepareShearCell(p, 2, tubeCache());
    const double R = 3.3, pg = 30.0, V = pg / 45.0 * 1e4, T = R / V;
    FlowConditions fc;
    fc.etaOut = 1.003;
    fc.etaIn = 1.003;
    fc.shearRate = 0.0;
    fc.timeScale = T;
    const CellFlowModel model(p, fc, c.faces, c.reference);
    const double L = model.scales().length;
    const Vertices X0 = fitIntoTube(c.initial, c.faces, R, 0.1 * R, fc.A0, fc.V0);
    TubeSetup s;
    s.radius = R / L;
    s.centreLineSpeed = pg * 1.33322e5 * std::pow(R * 1e-6, 2) / (4.0 * 1.003e-3) * 1e6 * T / L;
    s.halfLength = (1.15 * X0.row(0).cwiseAbs().maxCoeff() + 2.0 * R) / L;
    s.pointsPerRing = 12;
    s.repulsionRange = 0.1 / L;
    s.vertexWeight = model.targetArea() / static_cast<double>(X0.cols());
    const TubeEnvironment env(s);
    CellFlowOptions opt;
    opt.tEnd = 3.0;
    opt.frameInterval = 0.5;
    opt.dtMax = 5.0;
    const CellFlowResult r = integrateCellFlow(model, model.toInternal(X0), opt, {}, &env);
    ASSERT_TRUE(r.completed) << r.message;
    const Eigen::Vector3d c0 = centroid(r.frames.front()), c1 = centroid(r.frames.back());
    const double v = (c1.x() - c0.x()) / (r.times.back() - r.times.front());  // in units of R_A / (R/V)
    std::printf("coupled run: %d steps, mean velocity %.3f cm/s, off axis %.2e um, clearance %.3f um\n", r.steps,
                v * L / T * 1e-4, c1.tail<2>().norm() * L, env.minClearance() * L);
    EXPECT_GT(v, 0.3 * s.centreLineSpeed);  // along +x, slower than the centre line
    EXPECT_LT(v, s.centreLineSpeed);
    EXPECT_LT(c1.tail<2>().norm() * L, 1e-3);  // stays on the axis (um)
    EXPECT_LT(env.maxOffAxis() * L, 1e-3);
    EXPECT_GT(env.minClearance(), 0.0);
    for (std::size_t k = 0; k < r.frames.size(); ++k) {
        EXPECT_LT(std::abs(r.areaDrift[k]), 5e-3);
        EXPECT_LT(std::abs(r.volumeDrift[k]), 5e-3);
    }
}

// docs/FLOW_TUBE.md post-processing on synthetic frames with known answers: a spheroid (semi-axes
// a along the axis x, b across) translating at speed U, first rigidly, then with its membrane
// turning about the axis at rate w (the shape, hence length and width, unchanged): the
// co-moving-frame path of the fastest vertex over the second half is the number of frame
// intervals there times 2 rho_max sin(w dt / 2), rho_max = b.
TEST(TubeObservablesTest, LengthWidthVelocityPlateauAndCellFrameMotionOfSyntheticFrames) {
    Mesh m = icosphere(2);
    const double a = 4.0, b = 2.5, U = 3.0, w = 0.1;
    m.X.row(0) *= a;
    m.X.row(1) *= b;
    m.X.row(2) *= b;
    const int n = 41;
    for (const double rate : {0.0, w}) {
        std::vector<double> t(n);
        std::vector<Vertices> frames(n);
        for (int k = 0; k < n; ++k) {
            t[k] = 0.5 * k;
            const double phi = rate * t[k];
            Vertices X = m.X;
            X.row(1) = std::cos(phi) * m.X.row(1) - std::sin(phi) * m.X.row(2);
            X.row(2) = std::sin(phi) * m.X.row(1) + std::cos(phi) * m.X.row(2);
            X.row(0).array() += U * t[k];
            frames[k] = X;
        }
        const TubeObservables o = analyzeTubeFrames(t, frames);
        EXPECT_NEAR(o.velocity, U, 1e-12);
        EXPECT_NEAR(o.length, 2.0 * a, 1e-12);
        EXPECT_NEAR(o.widthY, 2.0 * b, 0.05 * b);  // the icosphere's extent turns with the vertices
        EXPECT_LT(o.lengthChange, 1e-12);
        EXPECT_LT(o.velocityChange, 1e-12);
        EXPECT_NEAR(o.travel, U * (t[n - 1] - t[n / 2]), 1e-9);
        const double expected = (n - 1 - n / 2) * 2.0 * b * std::sin(0.5 * rate * (t[1] - t[0]));
        EXPECT_NEAR(o.cellFrameMotion, expected, rate == 0.0 ? 1e-9 : 0.02 * expected) << "rate " << rate;
    }
    // A cell that grows: the plateau check sees it.
    std::vector<double> t(n);
    std::vector<Vertices> frames(n);
    for (int k = 0; k < n; ++k) {
        t[k] = k;
        frames[k] = m.X;
        frames[k].row(0) *= 1.0 + 0.01 * k;
    }
    EXPECT_GT(analyzeTubeFrames(t, frames).lengthChange, 0.05);
    EXPECT_THROW(analyzeTubeFrames(std::vector<double>(10), std::vector<Vertices>(10, m.X)), InputError);
}

// The settling criterion of `flow tube --settle`: a length relaxing as L(t) = a (1 + 0.2 e^(-t/5))
// varies over [t - 10, t] by 0.2 a e^(-t/5) (e^2 - 1) relative to ~a, below 2e-3 from t = 32.3 on;
// a steady shape changing along y or z only is not settled.
TEST(TubeObservablesTest, ShapeSettlesWhenLengthAndWidthStopChanging) {
    Mesh m = icosphere(2);
    std::vector<double> t;
    std::vector<Vertices> frames;
    double settledAt = -1.0;
    for (int k = 0; k <= 120; ++k) {
        t.push_back(0.5 * k);
        Vertices X = m.X;
        X.row(0) *= 4.0 * (1.0 + 0.2 * std::exp(-t.back() / 5.0));
        X.row(0).array() += 3.0 * t.back();
        frames.push_back(X);
        if (settledAt < 0.0 && tubeShapeSettled(t, frames, 10.0, 2e-3)) settledAt = t.back();
    }
    EXPECT_GE(settledAt, 32.0);
    EXPECT_LE(settledAt, 33.5);
    // A steady shape is not called settled before the record spans the window; a growing width is seen.
    const std::vector<Vertices> still(5, m.X);
    EXPECT_FALSE(tubeShapeSettled({0, 1, 2, 3, 4}, still, 10.0, 2e-3));
    EXPECT_TRUE(tubeShapeSettled({0, 3, 6, 9, 12}, still, 10.0, 2e-3));
    std::vector<Vertices> wider = still;
    wider.back().row(1) *= 1.01;
    EXPECT_FALSE(tubeShapeSettled({0, 3, 6, 9, 12}, wider, 10.0, 2e-3));
    std::vector<Vertices> thicker = still;
    thicker.back().row(2) *= 1.01;
    EXPECT_FALSE(tubeShapeSettled({0, 3, 6, 9, 12}, thicker, 10.0, 2e-3));
}

TEST(TubeFlowCli, BadInputExitsWithTwoNamingTheOption) {
    test::TempDir dir;
    const std::string cache = " --cache " + test::shellQuote(tubeCache().string());
    struct Case {
        std::string args, expect;
    };
    for (const Case& c : {Case{"--radius 0 --pressure-gradient 30", "--radius"},
                          Case{"--radius -2 --pressure-gradient 30", "--radius"},
                          Case{"--radius 1.2 --pressure-gradient 30", "--radius: 1.2 is out of range (valid: [1.4967, 100] um)"},  // cannot hold V0 with A0
                          Case{"--radius 3.3 --pressure-gradient 0", "--pressure-gradient"},
                          Case{"--radius 3.3 --pressure-gradient -5", "--pressure-gradient"},
                          Case{"--radius 3.3 --pressure-gradient 30 --eta-out 0", "--eta-out"},
                          Case{"--radius 3.3 --pressure-gradient 30 --viscosity-ratio 0", "--viscosity-ratio"},
                          Case{"--radius 3.3 --pressure-gradient 30 --viscosity-ratio 5", "--viscosity-ratio"},
                          Case{"--radius 3.3 --pressure-gradient 30 --mu -1", "mu"},
                          Case{"--radius 3.3 --pressure-gradient 30 --settle 5", "--settle"},
                          Case{"--radius 3.3 --pressure-gradient 30 --settle-relax 0", "--settle-relax"},
                          Case{"--radius 3.3 --pressure-gradient 30 --settle-relax 1 --settle-etam 0.01", "--settle-etam"}}) {
        // --max-steps 1: a check that failed to reject would not run a whole simulation.
        const test::CliRun r = test::runTrbc("flow tube --level 2 --max-steps 1 " + c.args + cache, dir.path());
        EXPECT_EQ(r.status, 2) << c.args << "\n" << r.out << r.err;
        EXPECT_NE(r.err.find(c.expect), std::string::npos) << c.args << "\n" << r.err;
        EXPECT_EQ(r.out.find("\"observables\""), std::string::npos) << c.args;
    }
    // A run stopped by the step limit: JSON with "status": "failed", exit 3.
    const test::CliRun r = test::runTrbc(
        "flow tube --level 2 --radius 3.3 --pressure-gradient 30 --wall-points 12 --max-steps 2" + cache, dir.path());
    EXPECT_EQ(r.status, 3) << r.out << r.err;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j.at("status"), "failed");
    EXPECT_NE(j.at("reason").get<std::string>().find("step limit"), std::string::npos);
    EXPECT_NE(j.at("reason").get<std::string>().find("settling stage"), std::string::npos) << j.at("reason");
    EXPECT_TRUE(j.at("observables").at("velocity_cm_per_s").is_null());
    // The settling viscosity of --settle-relax 1.5 (default): eta_m = 1.5 mu R / V, V = 30/45 cm/s.
    const nlohmann::json& settling = j.at("parameters").at("settling");
    const double mu = j.at("parameters").at("cell").at("mu_uN_per_m").get<double>();
    EXPECT_NEAR(settling.at("etam_Pa_s_um").get<double>(), 1.5 * mu * 3.3 / (30.0 / 45.0 * 1e4), 1e-12);
    // E = eta_m / (eta_out R_A), R_A = sqrt(A0 / 4 pi) = 3.2777 um for A0 = 135 um^2.
    EXPECT_NEAR(settling.at("membrane_viscosity_ratio_E").get<double>(),
                settling.at("etam_Pa_s_um").get<double>() / (1.003e-3 * std::sqrt(135.0 / (4.0 * M_PI))), 1e-9);
    EXPECT_EQ(settling.at("capped_at_cell_etam"), false);
    EXPECT_NEAR(settling.at("relaxation_time_R_over_V").get<double>(), 1.5, 1e-12);
    // The tube's default step tolerance (docs/FLOW_TUBE.md, "Step tolerance"); the shear's stays 1e-3.
    const std::string tubeHelp = test::runTrbc("flow tube --help", dir.path()).out;
    EXPECT_NE(tubeHelp.find("--step-tol FLOAT:(0, 1] R_A=6.25e-05"), std::string::npos) << tubeHelp;
    const std::string shearHelp = test::runTrbc("flow shear --help", dir.path()).out;
    EXPECT_NE(shearHelp.find("--step-tol FLOAT:(0, 1] R_A=0.001"), std::string::npos) << shearHelp;
    // --settle-etam replaces it; recorded as given.
    const nlohmann::json je = nlohmann::json::parse(
        test::runTrbc("flow tube --level 2 --radius 3.3 --pressure-gradient 30 --wall-points 12 --max-steps 2 "
                      "--settle-etam 0.05" + cache, dir.path()).out);
    EXPECT_DOUBLE_EQ(je.at("parameters").at("settling").at("etam_Pa_s_um").get<double>(), 0.05);
    EXPECT_TRUE(je.at("parameters").at("settling").at("relax_requested_R_over_V").is_null());
    // Its relaxation time eta_m / mu in units of R / V.
    EXPECT_NEAR(je.at("parameters").at("settling").at("relaxation_time_R_over_V").get<double>(),
                0.05 / (mu * 3.3 / (30.0 / 45.0 * 1e4)), 1e-9);
    // A requested relaxation time whose eta_m exceeds the cell's own is capped at the cell's eta_m.
    const nlohmann::json jc = nlohmann::json::parse(
        test::runTrbc("flow tube --level 2 --radius 3.3 --pressure-gradient 30 --wall-points 12 --max-steps 2 "
                      "--settle-relax 1e6" + cache, dir.path()).out);
    const nlohmann::json& sc = jc.at("parameters").at("settling");
    const double etamCell = jc.at("parameters").at("cell").at("etam_Pa_s_um").get<double>();
    EXPECT_EQ(sc.at("capped_at_cell_etam"), true);
    EXPECT_DOUBLE_EQ(sc.at("etam_Pa_s_um").get<double>(), etamCell);
    EXPECT_NEAR(sc.at("relaxation_time_R_over_V").get<double>(), etamCell / (mu * 3.3 / (30.0 / 45.0 * 1e4)), 1e-9);
    EXPECT_DOUBLE_EQ(sc.at("relax_requested_R_over_V").get<double>(), 1e6);
    const test::CliRun r0 = test::runTrbc(
        "flow tube --level 2 --radius 3.3 --pressure-gradient 30 --wall-points 12 --settle 0 --max-steps 2" + cache,
        dir.path());
    EXPECT_EQ(r0.status, 3) << r0.out << r0.err;
    EXPECT_NE(nlohmann::json::parse(r0.out).at("reason").get<std::string>().find("main stage"), std::string::npos);
    EXPECT_NEAR(j.at("parameters").at("minimum_radius_um").get<double>(), 1.4966, 1e-3);
}

}  // namespace
}  // namespace trbc
