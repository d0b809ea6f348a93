#include "flow/stokes_verification.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "flow/stokes_solver.hpp"
#include "mesh/icosphere.hpp"

namespace trbc::stokes_verification {
namespace {

constexpr double kPi = std::numbers::pi;

double relErr(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return (a - b).norm() / b.norm(); }

}  // namespace

/// Rigid unit sphere translating with U = (0.3, -0.2, 1) in fluid at rest: F = -6 pi mu a U.
double translatingSphereError(const BoundaryIntegralOperators& ops, int* iterations) {
    const double mu = 1.7;
    const Eigen::Vector3d U(0.3, -0.2, 1.0);
    const RigidBodyResult r =
        solveRigidBodyResistance(ops, mu, U, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero());
    if (iterations) *iterations = r.gmres.iterations;
    return relErr(r.force, -6.0 * kPi * mu * U);
}

/// Rigid unit sphere rotating with Omega: torque -8 pi mu a^3 Omega.
double rotatingSphereError(const BoundaryIntegralOperators& ops) {
    const double mu = 0.8;
    const Eigen::Vector3d W(0.5, 1.0, -0.25);
    const RigidBodyResult r =
        solveRigidBodyResistance(ops, mu, Eigen::Vector3d::Zero(), W, Eigen::Vector3d::Zero());
    return relErr(r.torque, -8.0 * kPi * mu * W);
}

/// Freely suspended unit sphere in u = (gamma y, 0, 0), centred at c (mesh also rotated, so
/// that its symmetry axes are not aligned with the flow): Omega = (0, 0, -gamma/2),
/// U = u_inf(c) = (gamma c_y, 0, 0), and the stresslet (symmetric traceless part of the first
/// moment of the traction; the traction is f = 5 mu E . n up to a pressure) is
/// S = 20/3 pi mu a^3 E with E the rate of strain (Batchelor 1970). Returns the errors
/// {max(|Omega - Omega_exact|, |U - U_exact| / a) / (gamma/2), |S - S_exact| / |S_exact|}.
/// Omega and U alone would be exact up to the GMRES tolerance: the icosphere is centrally
/// symmetric, so the discrete strain-rotation coupling vanishes; the stresslet tests the quadrature.
std::pair<double, double> shearedSphereErrors(int level, int* iterations) {
    const double mu = 1.3, gamma = 2.0;
    const Eigen::Vector3d c(0.3, -0.4, 0.2);
    Mesh m = icosphere(level);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    m.X = (R * m.X).colwise() + c;
    const BoundaryIntegralOperators ops(m);
    const LinearFlow shear = LinearFlow::simpleShear(gamma);
    const RigidBodyResult r = solveRigidBodyMobility(ops, mu, c, shear, Eigen::Vector3d::Zero(),
                                                     Eigen::Vector3d::Zero());
    if (iterations) *iterations = r.gmres.iterations;
    const double w = (r.angularVelocity - Eigen::Vector3d(0, 0, -gamma / 2)).norm() / (gamma / 2);
    const double u = (r.velocity - Eigen::Vector3d(gamma * c.y(), 0, 0)).norm() / (gamma / 2);
    const Eigen::Matrix3d M = ops.firstMoment(r.traction, c);
    const Eigen::Matrix3d S = 0.5 * (M + M.transpose()) - M.trace() / 3.0 * Eigen::Matrix3d::Identity();
    const Eigen::Matrix3d E = 0.5 * (shear.gradient + shear.gradient.transpose());
    const Eigen::Matrix3d Sx = 20.0 / 3.0 * kPi * mu * E;
    return {std::max(w, u), (S - Sx).norm() / Sx.norm()};
}

/// Drop of viscosity ratio lambda driven by a force F (e.g. a uniform body force density F/V on
/// its contents, as for a sedimenting drop). Exact: with the modified inside pressure
/// P = p - (F/V) . x the body force moves into the traction jump, which becomes (modulo a
/// uniform pressure, whose single layer vanishes since int G . n dS = 0)
///     Delta f = (sigma_out - sigma_in) . n = -(F . x / V) n,       int Delta f dS = -F,
/// and the Hadamard-Rybczynski solution (Happel & Brenner 1965, 4-21) satisfies the normal and
/// tangential stress conditions on the undeformed sphere exactly for this Delta f and any surface
/// tension. It gives the drop velocity U = F (1 + lambda) / (2 pi mu a (2 + 3 lambda)) and the
/// interface velocity u = U - (I - n n) U / (2 (1 + lambda)) (tangential slip, lab frame).
/// Returns the relative errors of U (volume mean of the interface velocity) and of the field u
/// (max over vertices / |U|).
std::pair<double, double> hadamardRybczynskiErrors(const BoundaryIntegralOperators& ops, double lambda,
                                                   int* iterations) {
    const double mu = 1.4, a = 1.0;
    const Eigen::Vector3d F(0.2, 0.5, -1.0);
    const Eigen::Matrix3Xd& X = ops.mesh().X;
    const double V = 4.0 * kPi * a * a * a / 3.0;
    Eigen::Matrix3Xd df(3, X.cols());
    for (Eigen::Index i = 0; i < X.cols(); ++i) {
        const Eigen::Vector3d n = X.col(i).normalized();  // exact sphere normal
        df.col(i) = -(F.dot(X.col(i)) / V) * n;
    }
    const InterfaceResult r = solveInterfaceVelocity(ops, mu, lambda, df);
    if (iterations) *iterations = r.gmres.iterations;
    const Eigen::Vector3d U = F * (1.0 + lambda) / (2.0 * kPi * mu * a * (2.0 + 3.0 * lambda));
    double field = 0.0;
    for (Eigen::Index i = 0; i < X.cols(); ++i) {
        const Eigen::Vector3d n = X.col(i).normalized();
        const Eigen::Vector3d exact = U - (U - n * n.dot(U)) / (2.0 * (1.0 + lambda));
        field = std::max(field, (r.velocity.col(i) - exact).norm() / U.norm());
    }
    return {relErr(ops.volumeMeanVelocity(r.velocity), U), field};
}

double habermanK(double b) {
    return (1.0 - 0.75857 * std::pow(b, 5)) /
           (1.0 - 2.1050 * b + 2.0865 * std::pow(b, 3) - 1.7068 * std::pow(b, 5) + 0.72603 * std::pow(b, 6));
}
double habermanFreeSpeed(double b) {
    return (1.0 - 2.0 / 3.0 * b * b - 0.20217 * std::pow(b, 5)) / (1.0 - 0.75857 * std::pow(b, 5));
}

BoundaryIntegralOperators sphereOps(int level, double a) {
    Mesh m = icosphere(level);
    m.X *= a;
    return BoundaryIntegralOperators(m);
}

double dragError(const BoundaryIntegralOperators& sphere, const TubeWall& wall, double beta) {
    const double mu = 1.0, U = 1.0;
    const RigidBodyResult r = solveRigidBodyInTube(sphere, wall, mu, 0.0, Eigen::Vector3d::Zero(), false,
                                                   Eigen::Vector3d(U, 0, 0));
    const double exact = -6.0 * kPi * mu * beta * U * habermanK(beta);
    return r.force.x() / exact - 1.0;
}

double freeSphereError(const BoundaryIntegralOperators& sphere, const TubeWall& wall, double beta, RigidBodyResult* out) {
    const RigidBodyResult r = solveRigidBodyInTube(sphere, wall, 1.0, 1.0, Eigen::Vector3d::Zero(), true);
    if (out) *out = r;
    return r.velocity.x() / habermanFreeSpeed(beta) - 1.0;
}

}  // namespace trbc::stokes_verification
