#include "flow/stokes_solver.hpp"

#include <fmt/format.h>

#include <cmath>
#include <functional>
#include <memory>
#include <numbers>
#include <string>

#include "core/error.hpp"
#include "solvers/gmres.hpp"

namespace trbc {
namespace {

using Eigen::Index;
using Eigen::Matrix3Xd;
using Eigen::Vector3d;
using Eigen::VectorXd;

constexpr double kPi = std::numbers::pi;

void checkViscosity(double mu) {
    if (!(mu > 0.0) || !std::isfinite(mu))
        throw InputError(fmt::format("viscosity = {}: must be finite and > 0", mu));
}

void checkGmres(const GmresOptions& o) {
    if (!(o.tolerance > 0.0) || !(o.tolerance < 1.0))
        throw InputError(fmt::format("GMRES tolerance = {}: must be in (0, 1)", o.tolerance));
    if (o.restart < 1) throw InputError(fmt::format("GMRES restart = {}: must be >= 1", o.restart));
    if (o.maxIterations < 1)
        throw InputError(fmt::format("GMRES maxIterations = {}: must be >= 1", o.maxIterations));
}

bool useDense(const GmresOptions& o, Index nv) {
    return o.mode == OperatorMode::Dense || (o.mode == OperatorMode::Auto && 3 * nv <= o.denseLimit);
}

/// Solves A x = b by trbc's GMRES (no preconditioner); throws NumericalError naming `what` when
/// the tolerance is not reached.
GmresReport solveOrThrow(const LinearMap& A, const VectorXd& b, VectorXd& x, const GmresOptions& o,
                         const std::string& what, const VectorXd* initialGuess = nullptr) {
    const GmresResult r = gmres(A, LinearMap{}, b, x, {o.tolerance, o.restart, o.maxIterations}, initialGuess);
    if (!r.converged)
        throw NumericalError(fmt::format(
            "GMRES ({}) did not converge: relative residual {:.3e} after {} iterations (tolerance "
            "{:.1e}, restart {}, maxIterations {})",
            what, r.residual, r.iterations, o.tolerance, o.restart, o.maxIterations));
    return {r.iterations, r.residual};
}

Eigen::Map<const Matrix3Xd> asField(const VectorXd& v, Index nv) { return {v.data(), 3, nv}; }

/// A single- or double-layer apply, dense (assembled once) or matrix-free.
using LayerApply = std::function<Matrix3Xd(const Matrix3Xd&)>;

LayerApply layerApply(const BoundaryIntegralOperators& ops, bool dense, bool doubleLayer) {
    if (dense) {
        auto M = std::make_shared<Eigen::MatrixXd>(doubleLayer ? ops.assembleDoubleLayer()
                                                               : ops.assembleSingleLayer());
        const Index nv = ops.numVertices();
        return [M, nv](const Matrix3Xd& f) {
            Matrix3Xd y(3, nv);
            Eigen::Map<VectorXd>(y.data(), 3 * nv).noalias() =
                *M * Eigen::Map<const VectorXd>(f.data(), 3 * nv);
            return y;
        };
    }
    if (doubleLayer) return [&ops](const Matrix3Xd& u) { return ops.doubleLayer(u); };
    return [&ops](const Matrix3Xd& f) { return ops.singleLayer(f); };
}

/// Weights w_j with int f . n dS = sum_j w_j . f_j (face normals, linear f).
Matrix3Xd normalFluxWeights(const BoundaryIntegralOperators& ops) {
    const Mesh& m = ops.mesh();
    Matrix3Xd w = Matrix3Xd::Zero(3, m.numVertices());
    for (Index t = 0; t < m.numFaces(); ++t)
        for (int k = 0; k < 3; ++k) w.col(m.F(k, t)) += ops.faceAreas()[t] / 3.0 * ops.faceNormals().col(t);
    return w;
}

/// The first-kind rigid-body operator f -> 1/(8 pi mu) S f + (L / (mu A)) nu_i <w, f>, with the
/// rank-one term removing the near-null traction f = n (nu: vertex normals, L = sqrt(A / 4 pi)).
struct SingleLayerSystem {
    LayerApply S;
    Matrix3Xd fluxWeights;
    double scale, deflation;
    const BoundaryIntegralOperators* ops;

    Matrix3Xd apply(const Matrix3Xd& f) const {
        const double flux = (fluxWeights.array() * f.array()).sum();
        return scale * S(f) + (deflation * flux) * ops->vertexNormals();
    }
};

SingleLayerSystem singleLayerSystem(const BoundaryIntegralOperators& ops, double mu, const GmresOptions& o) {
    const double L = std::sqrt(ops.area() / (4.0 * kPi));
    return {layerApply(ops, useDense(o, ops.numVertices()), false), normalFluxWeights(ops),
            1.0 / (8.0 * kPi * mu), L / (mu * ops.area()), &ops};
}

Vector3d angularPart(const Vector3d& omega, const Vector3d& x, const Vector3d& c) {
    return omega.cross(x - c);
}

}  // namespace

Matrix3Xd LinearFlow::at(const Matrix3Xd& X) const {
    return (gradient * X).colwise() + velocity;
}

LinearFlow LinearFlow::uniform(const Vector3d& U) {
    LinearFlow f;
    f.velocity = U;
    return f;
}

LinearFlow LinearFlow::simpleShear(double rate) {
    LinearFlow f;
    f.gradient(0, 1) = rate;
    return f;
}

RigidBodyResult solveRigidBodyResistance(const BoundaryIntegralOperators& ops, double viscosity,
                                         const Vector3d& velocity, const Vector3d& angularVelocity,
                                         const Vector3d& center, const LinearFlow& background,
                                         const GmresOptions& opts) {
    checkViscosity(viscosity);
    checkGmres(opts);
    if (!velocity.allFinite() || !angularVelocity.allFinite() || !center.allFinite() ||
        !background.velocity.allFinite() || !background.gradient.allFinite())
        throw InputError(
            "rigid-body resistance: velocity, angular velocity, centre and background flow must be finite");
    const Index nv = ops.numVertices();
    const Matrix3Xd& X = ops.mesh().X;
    const SingleLayerSystem sys = singleLayerSystem(ops, viscosity, opts);

    Matrix3Xd rhs = background.at(X);
    for (Index i = 0; i < nv; ++i) rhs.col(i) -= velocity + angularPart(angularVelocity, X.col(i), center);
    const LinearMap A = [&](const VectorXd& x, VectorXd& y) {
        y.resize(3 * nv);
        Eigen::Map<Matrix3Xd>(y.data(), 3, nv) = sys.apply(asField(x, nv));
    };
    VectorXd sol = VectorXd::Zero(3 * nv);
    RigidBodyResult res;
    res.gmres = solveOrThrow(A, Eigen::Map<const VectorXd>(rhs.data(), 3 * nv), sol, opts, "rigid-body resistance");
    res.traction = asField(sol, nv);
    res.force = ops.integrate(res.traction);
    res.torque = ops.moment(res.traction, center);
    res.velocity = velocity;
    res.angularVelocity = angularVelocity;
    return res;
}

RigidBodyResult solveRigidBodyMobility(const BoundaryIntegralOperators& ops, double viscosity,
                                       const Vector3d& center, const LinearFlow& background,
                                       const Vector3d& externalForce, const Vector3d& externalTorque,
                                       const GmresOptions& opts) {
    checkViscosity(viscosity);
    checkGmres(opts);
    if (!center.allFinite() || !externalForce.allFinite() || !externalTorque.allFinite() ||
        !background.velocity.allFinite() || !background.gradient.allFinite())
        throw InputError(
            "rigid-body mobility: centre, external force, external torque and background flow must be finite");
    const Index nv = ops.numVertices(), n = 3 * nv + 6;
    const Matrix3Xd& X = ops.mesh().X;
    const SingleLayerSystem sys = singleLayerSystem(ops, viscosity, opts);
    // Unknowns [f; U; L Omega]; force rows scaled by 1/(mu L), torque rows by 1/(mu L^2), so
    // that all blocks are O(1) for velocities O(1) on a body of size L.
    const double L = std::sqrt(ops.area() / (4.0 * kPi));
    const double sF = 1.0 / (viscosity * L), sT = 1.0 / (viscosity * L * L);

    const LinearMap A = [&](const VectorXd& x, VectorXd& y) {
        y.resize(n);
        const auto f = asField(x, nv);
        const Vector3d U = x.segment<3>(3 * nv), Omega = x.segment<3>(3 * nv + 3) / L;
        Eigen::Map<Matrix3Xd> v(y.data(), 3, nv);
        v = sys.apply(f);
        for (Index i = 0; i < nv; ++i) v.col(i) += U + angularPart(Omega, X.col(i), center);
        y.segment<3>(3 * nv) = sF * ops.integrate(f);
        y.segment<3>(3 * nv + 3) = sT * ops.moment(f, center);
    };
    VectorXd b(n);
    Eigen::Map<Matrix3Xd>(b.data(), 3, nv) = background.at(X);
    b.segment<3>(3 * nv) = -sF * externalForce;
    b.segment<3>(3 * nv + 3) = -sT * externalTorque;
    VectorXd sol = VectorXd::Zero(n);
    RigidBodyResult res;
    res.gmres = solveOrThrow(A, b, sol, opts, "rigid-body mobility");
    res.traction = asField(sol, nv);
    res.velocity = sol.segment<3>(3 * nv);
    res.angularVelocity = sol.segment<3>(3 * nv + 3) / L;
    res.force = ops.integrate(res.traction);
    res.torque = ops.moment(res.traction, center);
    return res;
}

InterfaceResult solveInterfaceVelocity(const BoundaryIntegralOperators& ops, double viscosity,
                                       double viscosityRatio, const Matrix3Xd& tractionJump,
                                       const LinearFlow& background, const GmresOptions& opts,
                                       const Matrix3Xd* initialGuess) {
    checkViscosity(viscosity);
    checkGmres(opts);
    const double lambda = viscosityRatio;
    if (!(lambda > 0.0) || !std::isfinite(lambda))
        throw InputError(fmt::format("viscosity ratio lambda = {}: must be finite and > 0", lambda));
    const Index nv = ops.numVertices();
    if (tractionJump.cols() != nv)
        throw InputError(fmt::format("traction jump: {} columns given, the mesh has {} vertices",
                                     tractionJump.cols(), nv));
    if (!tractionJump.allFinite()) throw InputError("traction jump: all entries must be finite");
    if (!background.velocity.allFinite() || !background.gradient.allFinite())
        throw InputError("background flow: velocity and gradient must be finite");
    if (initialGuess && initialGuess->cols() != nv)
        throw InputError(fmt::format("initial guess: {} columns given, the mesh has {} vertices",
                                     initialGuess->cols(), nv));

    // Right-hand side: 2/(1+lambda) u_inf - 1/(4 pi mu (1+lambda)) S Delta f.
    Matrix3Xd rhs = (2.0 / (1.0 + lambda)) * background.at(ops.mesh().X);
    if (tractionJump.size() > 0 && !tractionJump.isZero(0.0))
        rhs -= (1.0 / (4.0 * kPi * viscosity * (1.0 + lambda))) * ops.singleLayer(tractionJump);
    InterfaceResult res;
    const double kappa = (1.0 - lambda) / (4.0 * kPi * (1.0 + lambda));
    if (kappa == 0.0) {  // lambda = 1: no double layer, u is the right-hand side
        res.velocity = rhs;
        return res;
    }
    const LayerApply D = layerApply(ops, useDense(opts, nv), true);
    // (I - kappa D) u = rhs.
    const LinearMap A = [&](const VectorXd& x, VectorXd& y) {
        y.resize(3 * nv);
        const auto u = asField(x, nv);
        Eigen::Map<Matrix3Xd>(y.data(), 3, nv) = u - kappa * D(u);
    };
    // Start from the given guess, or from the right-hand side (the solution without the double layer).
    const VectorXd start = initialGuess ? VectorXd(Eigen::Map<const VectorXd>(initialGuess->data(), 3 * nv))
                                        : VectorXd(Eigen::Map<const VectorXd>(rhs.data(), 3 * nv));
    VectorXd sol;
    res.gmres = solveOrThrow(A, Eigen::Map<const VectorXd>(rhs.data(), 3 * nv), sol, opts, "interface velocity", &start);
    res.velocity = asField(sol, nv);
    return res;
}

}  // namespace trbc
