// Thermal fluctuations of a cell in Stokes flow (flow/cell_flow.hpp, ThermalOptions): the Lanczos
// square root against a dense one, and at rest the equipartition of a quasi-spherical capsule's
// shape modes l = 2..6 for the discrete energy (docs/FLOW_THERMAL.md).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <Eigen/Dense>
#include <cmath>
#include <numbers>
#include <random>

#include "core/error.hpp"
#include "flow/capsule.hpp"
#include "flow/cell_flow.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "solvers/krylov_sqrt.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

LinearMap denseMap(const MatrixXd& A) {
    return [A](const VectorXd& x, VectorXd& y) { y = A * x; };
}

TEST(KrylovSqrt, MatchesTheDenseSquareRootOfASymmetricPositiveMatrix) {
    std::mt19937_64 rng(3);
    std::normal_distribution<double> n(0.0, 1.0);
    const int N = 80;
    MatrixXd B(N, N);
    for (int i = 0; i < N; ++i)
        for (int j = 0; j < N; ++j) B(i, j) = n(rng);
    const MatrixXd A = B * B.transpose() / N + 0.05 * MatrixXd::Identity(N, N);  // condition ~ 100
    VectorXd z(N);
    for (int i = 0; i < N; ++i) z[i] = n(rng);
    const VectorXd exact = Eigen::SelfAdjointEigenSolver<MatrixXd>(A).operatorSqrt() * z;
    const KrylovSqrtResult r = krylovSqrt(denseMap(A), z, {1e-10, 200});
    ASSERT_TRUE(r.converged);
    EXPECT_LT((r.value - exact).norm(), 1e-8 * exact.norm());
    EXPECT_LT(r.iterations, N);  // converges before the whole space
    EXPECT_GT(r.smallestRitzValue, 0.0);
    // The tolerance bounds the error of the estimate (the iteration converges faster than linearly).
    const KrylovSqrtResult loose = krylovSqrt(denseMap(A), z, {1e-3, 200});
    EXPECT_LT((loose.value - exact).norm(), 1e-2 * exact.norm());
    EXPECT_LT(loose.iterations, r.iterations);
}

TEST(KrylovSqrt, ExactOnAnInvariantSubspaceAndZeroForZero) {
    // diag(4, 9, 0, ...): z in the span of the first two axes is an invariant space of dimension 2.
    MatrixXd A = MatrixXd::Zero(6, 6);
    A(0, 0) = 4.0;
    A(1, 1) = 9.0;
    VectorXd z = VectorXd::Zero(6);
    z[0] = 1.0;
    z[1] = -2.0;
    const KrylovSqrtResult r = krylovSqrt(denseMap(A), z);
    ASSERT_TRUE(r.converged);
    EXPECT_LE(r.iterations, 2);
    EXPECT_NEAR(r.value[0], 2.0, 1e-12);
    EXPECT_NEAR(r.value[1], -6.0, 1e-12);
    EXPECT_NEAR(r.value.tail(4).norm(), 0.0, 1e-12);
    const KrylovSqrtResult zero = krylovSqrt(denseMap(A), VectorXd::Zero(6));
    EXPECT_TRUE(zero.converged);
    EXPECT_EQ(zero.value.norm(), 0.0);
}

/// Real spherical harmonics (without normalisation: the same linear map is applied to the run and
/// to the prediction) at the unit direction n.
double realHarmonic(int l, int m, const Eigen::Vector3d& n) {
    const double theta = std::acos(std::clamp(n.z(), -1.0, 1.0)), phi = std::atan2(n.y(), n.x());
    const double p = std::assoc_legendre(static_cast<unsigned>(l), static_cast<unsigned>(std::abs(m)), std::cos(theta));
    if (m > 0) return p * std::cos(m * phi);
    if (m < 0) return p * std::sin(-m * phi);
    return p;
}

/// Central-difference Hessian of f (a gradient map) at X, symmetrised.
template <class Gradient>
MatrixXd denseHessian(const Gradient& gradient, const Vertices& X) {
    const Eigen::Index n = X.size();
    MatrixXd H(n, n);
    const double eps = 1e-5;
    for (Eigen::Index k = 0; k < n; ++k) {
        Vertices Xp = X, Xm = X;
        Xp.data()[k] += eps;
        Xm.data()[k] -= eps;
        const Vertices d = (gradient(Xp) - gradient(Xm)) / (2.0 * eps);
        H.col(k) = Eigen::Map<const VectorXd>(d.data(), n);
    }
    return 0.5 * (H + H.transpose());
}

/// A basis of the shape space at X: orthogonal to the volume gradient, the translations and the
/// rotations.
MatrixXd shapeBasis(const Vertices& X, const Vertices& volumeGradient) {
    const Eigen::Index nv = X.cols(), n = X.size();
    MatrixXd C(n, 7);
    C.col(0) = Eigen::Map<const VectorXd>(volumeGradient.data(), n);
    const Eigen::Vector3d c = X.rowwise().mean();
    for (int a = 0; a < 3; ++a) {
        Vertices t = Vertices::Zero(3, nv), r(3, nv);
        t.row(a).setOnes();
        for (Eigen::Index i = 0; i < nv; ++i) r.col(i) = Eigen::Vector3d::Unit(a).cross(X.col(i) - c);
        C.col(1 + a) = Eigen::Map<const VectorXd>(t.data(), n);
        C.col(4 + a) = Eigen::Map<const VectorXd>(r.data(), n);
    }
    const Eigen::HouseholderQR<MatrixXd> qr(C);
    const MatrixXd Q = qr.householderQ();
    return Q.rightCols(n - 7);
}

// At rest, the fluctuating capsule (neo-Hookean, bending, membrane viscosity, volume held) samples
// the Gibbs distribution of its discrete energy: the mean power of its radial shape modes l = 2..6
// (material frame, so rigid turns do not count) matches kT tr(P_l (Q^T H_L Q)^-1 P_l^T), with H_L the
// Hessian of the energy minus the pressure times that of the volume, Q the shape space, P_l the
// linearised mode map. Both noises (the fluid's through the Lanczos root, the membrane viscosity's on
// the edges) enter; lambda = 1 makes the mobility c S M^-1, lambda = 0.1 adds the double layer.
void checkEquipartition(double viscosityRatio) {
    const Mesh sphere = icosphere(2);
    CapsuleCase cc;
    cc.capillary = 1.0;           // G_s = 1
    cc.bending = 0.02;            // E_b / (a^2 G_s)
    cc.membraneViscosity = 0.5;   // eta_m / (eta a)
    cc.viscosityRatio = viscosityRatio;
    MembraneFlowSpec spec = capsuleFlowSpec(cc);
    spec.shearRate = 0.0;
    const CellFlowModel model(spec, sphere.F, sphere.X);
    const Faces& F = sphere.F;
    const auto gradient = [&](const Vertices& X) {
        Vertices g(3, X.cols());
        model.membrane().evaluate(X, &g);
        return g;
    };
    const double V0 = model.targetVolume();
    // The discrete minimum near the icosphere: Newton in the shape space, then back onto V0.
    Vertices Xmin = sphere.X;
    for (int it = 0; it < 6; ++it) {
        const AreaVolume av = areaVolumeWithGradients(Xmin, F);
        const MatrixXd Q = shapeBasis(Xmin, av.volumeGradient);
        const MatrixXd H = denseHessian(gradient, Xmin);
        const Vertices g = gradient(Xmin);
        const VectorXd step = Q * (Q.transpose() * H * Q).ldlt().solve(Q.transpose() * Eigen::Map<const VectorXd>(g.data(), g.size()));
        Xmin -= Eigen::Map<const Vertices>(step.data(), 3, Xmin.cols());
        const AreaVolume av2 = areaVolumeWithGradients(Xmin, F);
        Xmin -= ((av2.volume - V0) / av2.volumeGradient.squaredNorm()) * av2.volumeGradient;
    }
    const AreaVolume av = areaVolumeWithGradients(Xmin, F);
    const Vertices g = gradient(Xmin);
    const double pressure = (g.array() * av.volumeGradient.array()).sum() / av.volumeGradient.squaredNorm();
    const auto volumeGradient = [&](const Vertices& X) { return areaVolumeWithGradients(X, F).volumeGradient; };
    const MatrixXd HL = denseHessian(gradient, Xmin) - pressure * denseHessian(volumeGradient, Xmin);
    const MatrixXd Q = shapeBasis(Xmin, av.volumeGradient);
    const double kT = 2e-4;
    const MatrixXd C = kT * Q * (Q.transpose() * HL * Q).inverse() * Q.transpose();

    // The linear mode map: delta r_i = n_i . (dx_i - mean dx), a_lm = sum_i w_i Y_lm(n_i) delta r_i.
    const Eigen::Index nv = Xmin.cols();
    const Eigen::Vector3d c0 = Xmin.rowwise().mean();
    Vertices dirs(3, nv);
    VectorXd r0(nv);
    for (Eigen::Index i = 0; i < nv; ++i) {
        r0[i] = (Xmin.col(i) - c0).norm();
        dirs.col(i) = (Xmin.col(i) - c0) / r0[i];
    }
    const VectorXd w = vertexAreas(Xmin, F);
    const int lMin = 2, lMax = 6;
    std::vector<MatrixXd> Y;  // per l: (2l+1) x nv weights w_i Y_lm(n_i)
    std::vector<MatrixXd> P;  // per l: (2l+1) x 3nv, the linearised map of the positions
    MatrixXd centre = MatrixXd::Zero(3 * nv, 3 * nv);
    for (Eigen::Index i = 0; i < nv; ++i)
        for (Eigen::Index j = 0; j < nv; ++j) centre.block(3 * i, 3 * j, 3, 3) = Eigen::Matrix3d::Identity() / double(nv);
    const MatrixXd centred = MatrixXd::Identity(3 * nv, 3 * nv) - centre;
    for (int l = lMin; l <= lMax; ++l) {
        MatrixXd Yl(2 * l + 1, nv), Nl = MatrixXd::Zero(2 * l + 1, 3 * nv);
        for (int m = -l; m <= l; ++m)
            for (Eigen::Index i = 0; i < nv; ++i) {
                Yl(m + l, i) = w[i] * realHarmonic(l, m, dirs.col(i));
                Nl.block(m + l, 3 * i, 1, 3) = Yl(m + l, i) * dirs.col(i).transpose();
            }
        Y.push_back(Yl);
        P.push_back(Nl * centred);
    }
    std::vector<double> expected;
    for (const MatrixXd& Pl : P) expected.push_back((Pl * C * Pl.transpose()).trace());

    CellFlowOptions o;
    o.thermal.kT = kT;
    o.thermal.seed = 11;
    o.thermal.step = 1.0;
    o.frameInterval = 1.0;
    const int burnIn = 50, samples = 1500;
    o.tEnd = (burnIn + samples) * o.frameInterval;
    o.keepFrames = false;
    std::vector<std::vector<double>> power(Y.size());
    int frame = 0;
    const CellFlowResult res = integrateCellFlow(model, Xmin, o, [&](double, const Vertices& X) {
        if (frame++ < burnIn) return;
        const Eigen::Vector3d c = X.rowwise().mean();
        VectorXd dr(nv);
        for (Eigen::Index i = 0; i < nv; ++i) dr[i] = (X.col(i) - c).norm() - r0[i];
        for (std::size_t k = 0; k < Y.size(); ++k) power[k].push_back((Y[k] * dr).squaredNorm());
    });
    ASSERT_TRUE(res.completed) << res.message;
    EXPECT_LT(res.maxVolumeDrift, 1e-10);
    for (std::size_t k = 0; k < Y.size(); ++k) {
        const std::vector<double>& p = power[k];
        // Batch means (30 batches of 50 frames) for the error of the mean.
        const int batches = 30;
        const std::size_t per = p.size() / batches;
        std::vector<double> means;
        for (int b = 0; b < batches; ++b) {
            double s = 0.0;
            for (std::size_t j = b * per; j < (b + 1) * per; ++j) s += p[j];
            means.push_back(s / double(per));
        }
        double mean = 0.0, var = 0.0;
        for (double m : means) mean += m / batches;
        for (double m : means) var += (m - mean) * (m - mean) / (batches - 1);
        const double se = std::sqrt(var / batches);
        const int l = lMin + static_cast<int>(k);
        std::printf("l = %d: <sum_m a_lm^2> = %.5e +- %.2e, equipartition %.5e (ratio %.3f +- %.3f)\n", l, mean, se,
                    expected[k], mean / expected[k], se / expected[k]);
        EXPECT_NEAR(mean, expected[k], 3.5 * se) << "l = " << l;
        EXPECT_LT(se, 0.08 * expected[k]) << "l = " << l << ": too few samples to test";
    }
    std::printf("steps %d, Lanczos iterations per step %.1f (max %d), GMRES %.1f\n", res.steps,
                double(res.sqrtIterations) / res.steps, res.maxSqrtIterations, double(res.gmresIterations) / res.steps);
}

TEST(ThermalFlow, AQuasiSphericalCapsuleAtRestSamplesEquipartition) { checkEquipartition(1.0); }

TEST(ThermalFlow, AQuasiSphericalCapsuleAtRestSamplesEquipartitionAtViscosityRatioOneTenth) { checkEquipartition(0.1); }

TEST(ThermalFlow, BadOptionsAreRefused) {
    const Mesh sphere = icosphere(1);
    MembraneFlowSpec spec = capsuleFlowSpec(CapsuleCase{});
    const CellFlowModel model(spec, sphere.F, sphere.X);
    CellFlowOptions o;
    o.tEnd = 0.1;
    o.thermal.kT = -1.0;
    EXPECT_THROW(integrateCellFlow(model, sphere.X, o), InputError);
    o.thermal.kT = std::nan("");
    EXPECT_THROW(integrateCellFlow(model, sphere.X, o), InputError);
    o.thermal.kT = 1e-3;
    o.thermal.step = 0.0;
    EXPECT_THROW(integrateCellFlow(model, sphere.X, o), InputError);
}

// The ensemble start and the ramp from the command line: the start repeats with its seed and
// differs between seeds; the ramp reports its stages; bad rates exit 2 naming --rates.
TEST(ThermalFlowCli, RandomStartIsSeededAndTheRampReportsItsStages) {
    test::TempDir dir;
    const std::string shear = "flow shear --eta-out 23.9 --shear-rate 40 --level 1 --rotations 0.5 --no-cache --start random --out ";
    std::string shapes[3];
    int k = 0;
    for (const char* seed : {"3", "3", "4"}) {
        const std::filesystem::path out = dir.path() / ("s" + std::to_string(k));
        const test::CliRun r = test::runTrbc(shear + out.string() + " --seed " + seed, dir.path());
        ASSERT_EQ(r.status, 0) << r.err;
        shapes[k++] = test::slurp(out / "initial.vtk");
    }
    EXPECT_EQ(shapes[0], shapes[1]);
    EXPECT_NE(shapes[0], shapes[2]);

    const std::filesystem::path ramp = dir.path() / "ramp";
    const test::CliRun r = test::runTrbc("flow ramp --eta-out 30 --rates 2,20 --level 1 --rotations 1 --no-cache --out " + ramp.string(),
                                         dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(test::slurp(ramp / "ramp.json"));
    ASSERT_EQ(j["stages"].size(), 3u);
    EXPECT_EQ(j["stages"][2]["direction"], "down");
    EXPECT_DOUBLE_EQ(j["stages"][1]["shear_stress_Pa"].get<double>(), 0.6);
    EXPECT_TRUE(j["summary"]["completed"].get<bool>());

    const test::CliRun bad = test::runTrbc("flow ramp --eta-out 30 --rates 20,2 --level 1 --no-cache", dir.path());
    EXPECT_EQ(bad.status, 2);
    EXPECT_NE(bad.err.find("--rates"), std::string::npos) << bad.err;
}

}  // namespace
}  // namespace trbc
