#include "flow/coupled_system.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <numbers>

#include "core/random.hpp"
#include "mesh/geometry.hpp"
#include "solvers/krylov_sqrt.hpp"

namespace trbc::cellflow {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr std::uint64_t kThermalStream = 0x74686572;  // "ther": the thermal noise's streams

}  // namespace

Eigen::SparseMatrix<double> cotanLaplacian(const Vertices& X, const Faces& F) {
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(static_cast<std::size_t>(12 * F.cols()));
    for (Index f = 0; f < F.cols(); ++f)
        for (int c = 0; c < 3; ++c) {
            const int o = F(c, f), i = F((c + 1) % 3, f), j = F((c + 2) % 3, f);
            const Eigen::Vector3d a = X.col(i) - X.col(o), b = X.col(j) - X.col(o);
            const double w = 0.5 * a.dot(b) / std::max(a.cross(b).norm(), 1e-300);
            trip.emplace_back(i, i, w);
            trip.emplace_back(j, j, w);
            trip.emplace_back(i, j, -w);
            trip.emplace_back(j, i, -w);
        }
    Eigen::SparseMatrix<double> L(X.cols(), X.cols());
    L.setFromTriplets(trip.begin(), trip.end());
    return L;
}

CoupledSystem::CoupledSystem(const CellFlowModel& model, const Vertices& Xs, double alpha, const CellFlowOptions& opt,
                             PreconditionerFactor& factor, const FlowEnvironment* env)
    : model_(model), Xs_(Xs), alpha_(alpha), opt_(opt), env_(env), precFactor_(factor), ops_(Mesh{Xs, model.faces()}, opt.quadrature) {
    if (env_) wall_ = env_->wallOperator(Xs, ops_);
    const double lambda = model.viscosityRatio();
    c_ = 1.0 / (4.0 * kPi * (1.0 + lambda));
    k_ = (1.0 - lambda) / (4.0 * kPi * (1.0 + lambda));
    invArea_ = ops_.vertexAreas().cwiseInverse();
    const Index nv = Xs.cols();
    dense_ = opt.operators == OperatorMode::Dense ||
             (opt.operators == OperatorMode::Auto && 3 * nv <= opt.denseLimit);
    if (dense_) {
        Sd_ = ops_.assembleSingleLayerBlocks();
        if (k_ != 0.0) Dd_ = ops_.assembleDoubleLayerBlocks();
    }
    gp_.resize(3, nv);
    gm_.resize(3, nv);
    const AreaVolume av = areaVolumeWithGradients(Xs, model.faces());
    area_ = av.area;
    volume_ = av.volume;
    areaGradient_ = av.areaGradient;
    volumeGradient_ = av.volumeGradient;
    gNorm_ = areaGradient_.norm();
    vNorm_ = volumeGradient_.norm();
    w_ = forceVelocity(areaGradient_);
    wNorm_ = w_.norm();
    normals_ = ops_.vertexNormals() / ops_.vertexNormals().norm();
    areaConstrained_ = model.areaConstraint();
    if (opt.preconditioner) buildPreconditioner();
}

void CoupledSystem::gradient(const Vertices& X, Vertices& g) const {
    model_.membrane().evaluate(X, &g);
    if (env_) env_->addExternalGradient(X, g);
}

Vertices CoupledSystem::hessianTimes(const Vertices& v) const {
    const double vmax = v.colwise().norm().maxCoeff();
    if (!(vmax > 0.0)) return Vertices::Zero(3, v.cols());
    const double eps = 1e-6 / vmax;  // largest vertex displacement 1e-6 R_A
    gradient(Xs_ + eps * v, gp_);
    gradient(Xs_ - eps * v, gm_);
    return (gp_ - gm_) / (2.0 * eps);
}

CoupledSystem::Solution CoupledSystem::solve(const Vertices& Fexp, double areaRate, double volumeRate, const Vertices* extraVelocity) const {
    const Index nv = Xs_.cols(), n = 3 * nv;
    VectorXd b(n + 2);
    Eigen::Map<Vertices>(b.data(), 3, nv) =
        (2.0 / (1.0 + model_.viscosityRatio())) * (env_ ? env_->background(Xs_) : model_.background().at(Xs_)) +
        forceVelocity(Fexp);
    if (extraVelocity) Eigen::Map<Vertices>(b.data(), 3, nv) += *extraVelocity;
    b[n] = areaConstrained_ ? areaRate / gNorm_ : 0.0;
    b[n + 1] = volumeRate / vNorm_;
    const LinearMap A = [&](const VectorXd& x, VectorXd& y) {
        y.resize(n + 2);
        const Eigen::Map<const Vertices> u(x.data(), 3, nv);
        Eigen::Map<Vertices> yu(y.data(), 3, nv);
        const Vertices f = implicitForce(u) * invArea_.asDiagonal();
        Vertices Sf, Du;
        layers(f, u, Sf, Du);
        if (wall_) Sf += wall_(f);
        yu = u - c_ * Sf;
        if (k_ != 0.0) yu -= k_ * Du;
        // Without the area constraint the tension row is the identity and its column zero.
        if (areaConstrained_) {
            yu += (x[n] / wNorm_) * w_ - x[n + 1] * normals_;
            y[n] = (areaGradient_.array() * u.array()).sum() / gNorm_;
        } else {
            yu -= x[n + 1] * normals_;
            y[n] = x[n];
        }
        y[n + 1] = (volumeGradient_.array() * u.array()).sum() / vNorm_;
    };
    const LinearMap Minv = [&](const VectorXd& x, VectorXd& y) {
        if (!opt_.preconditioner) {
            y = x;
            return;
        }
        y.resize(n + 2);
        y.head(n) = velocityPreconditioner(x.head(n));
        if (!eliminateMultipliers_) {
            y.tail<2>() = x.tail<2>();
            return;
        }
        const Eigen::Vector2d ys = schurLu_.solve(constraintRows(y.head(n)) - x.tail<2>());
        y.head(n) -= precB_ * ys;
        y.tail<2>() = ys;
    };
    VectorXd x;
    Solution sol;
    sol.gmres = trbc::gmres(A, Minv, b, x, {effectiveGmresTolerance(opt_), opt_.gmresRestart, opt_.gmresMaxIterations});
    sol.u = Eigen::Map<const Vertices>(x.data(), 3, nv);
    sol.tension = x[n] / wNorm_;
    sol.fluxCorrection = x[n + 1] / ops_.vertexNormals().norm();
    return sol;
}

Vertices CoupledSystem::mobility(const Vertices& F, double tolerance, long& iterations) const {
    const Vertices v = forceVelocity(F);
    if (k_ == 0.0) return v;
    const Index nv = Xs_.cols();
    const LinearMap A = [&](const VectorXd& x, VectorXd& y) {
        const Eigen::Map<const Vertices> u(x.data(), 3, nv);
        y.resize(x.size());
        Eigen::Map<Vertices>(y.data(), 3, nv) = u - k_ * doubleLayer(u);
    };
    VectorXd x;
    const GmresResult g = trbc::gmres(A, {}, Eigen::Map<const VectorXd>(v.data(), v.size()), x, {tolerance, 60, 600});
    iterations += g.iterations;
    if (!g.converged)
        throw NumericalError(fmt::format("cell flow: the thermal mobility's GMRES did not converge (relative residual "
                                         "{:.3e})", g.residual));
    return Eigen::Map<const Vertices>(x.data(), 3, nv);
}

Vertices CoupledSystem::doubleLayer(const Vertices& u) const {
    if (!dense_) return ops_.doubleLayer(u);
    Vertices y(3, u.cols());
    Dd_.multiply(u.data(), y.data());
    return y;
}

VectorXd CoupledSystem::velocityPreconditioner(Eigen::Ref<const VectorXd> r) const {
    const Index nv = Xs_.cols();
    VectorXd t(3 * nv);
    for (Index i = 0; i < nv; ++i) t.segment<3>(3 * i) = precBlocks_[i] * r.segment<3>(3 * i);
    VectorXd y = precFactor_.velocity.solve(t);
    if (!bending_) return y;
    // K = K1 + N Q N^T (K1 the one-ring matrix, Q the bending stiffness): after y = K1^-1 t
    // the residual is -N Q N^T y; its normal part is corrected with the normal block
    // N^T K1 N + Q of K.
    VectorXd yn(nv);
    for (Index i = 0; i < nv; ++i) yn[i] = unitNormals_.col(i).dot(y.segment<3>(3 * i));
    const VectorXd z = precFactor_.normal.solve(-(bendingL_ * yn));
    for (Index i = 0; i < nv; ++i) y.segment<3>(3 * i) += z[i] * unitNormals_.col(i);
    return y;
}

Eigen::Vector2d CoupledSystem::constraintRows(Eigen::Ref<const VectorXd> u) const {
    const Eigen::Map<const VectorXd> g(areaGradient_.data(), u.size()), v(volumeGradient_.data(), u.size());
    return {areaConstrained_ ? g.dot(u) / gNorm_ : 0.0, v.dot(u) / vNorm_};
}

Vertices CoupledSystem::single(const Vertices& f) const {
    if (!dense_) return ops_.singleLayer(f);
    Vertices y(3, f.cols());
    Sd_.multiply(f.data(), y.data());
    return y;
}

void CoupledSystem::layers(const Vertices& f, const Vertices& u, Vertices& Sf, Vertices& Du) const {
    if (k_ == 0.0) {
        Sf = single(f);
        return;
    }
    if (!dense_) return ops_.layers(f, u, Sf, Du);
    Sf = single(f);
    Du.resize(3, u.cols());
    Dd_.multiply(u.data(), Du.data());
}

Vertices CoupledSystem::implicitForce(const Vertices& u) const {
    Vertices f = membraneViscousForce(Xs_, u, model_.edgeFriction(), model_.membrane().topology());
    if (alpha_ > 0.0) f -= alpha_ * hessianTimes(u);
    return f;
}

Vertices CoupledSystem::forceVelocity(const Vertices& F) const {
    const Vertices f = F * invArea_.asDiagonal();
    if (!wall_) return c_ * single(f);
    return c_ * (single(f) + wall_(f));
}

Eigen::Matrix3d CoupledSystem::selfBlock(Index i) const {
    if (dense_) return Sd_.block(i, i);
    const double rho = std::sqrt(3.0 * ops_.vertexAreas()[i] / kPi);
    const Eigen::Vector3d nrm = ops_.vertexNormals().col(i);
    return kPi * rho * (1.5 * Eigen::Matrix3d::Identity() - 0.5 * nrm * nrm.transpose());
}

void CoupledSystem::buildPreconditioner() {
    const Index nv = Xs_.cols(), n = 3 * nv;
    const Topology& T = model_.membrane().topology();
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(static_cast<std::size_t>(9 * (nv + 4 * T.numEdges())));
    precBlocks_.clear();
    precBlocks_.reserve(static_cast<std::size_t>(nv));
    for (Index i = 0; i < nv; ++i) {
        // M_i B_i^-1 / c (symmetrised).
        Eigen::Matrix3d Bi = selfBlock(i);
        Bi = 0.5 * (Bi + Bi.transpose());
        const Eigen::Matrix3d K = Bi.inverse() / (opt_.preconditionerScale * c_ * invArea_[i]);
        for (int a = 0; a < 3; ++a)
            for (int bb = 0; bb < 3; ++bb) trip.emplace_back(3 * i + a, 3 * i + bb, K(a, bb));
        precBlocks_.push_back(K);
    }
    // The implicit bending force alpha H u, normal to the surface: the bending stiffness
    // kb L M^-1 L of a flat patch (L the cotan Laplacian, M the vertex areas) on the normal
    // components, through a scalar factor of its own (two-ring pattern; velocityPreconditioner).
    // It is taken at steps where it is stiff at the grid scale against the single layer's
    // self-blocks and against the in-plane stiffness (bendingPreconditionerRatio,
    // bendingOverShearRatio; docs/FLOW_SOLVER.md, "Preconditioner").
    // An infinite ratio is never reached: the Laplacian and the ratios are then not formed.
    const MembraneParameters& mp = model_.membrane().parameters();
    const double gamma = model_.edgeFriction();
    bending_ = false;
    if (alpha_ > 0.0 && mp.bending.kb > 0.0 && std::isfinite(opt_.bendingPreconditionerRatio) &&
        std::isfinite(opt_.bendingOverShearRatio)) {
        const Eigen::SparseMatrix<double> L = cotanLaplacian(Xs_, model_.faces());
        const double kb = alpha_ * mp.bending.kb;
        double overSelf = 0.0, overShear = 0.0;
        for (Index i = 0; i < nv; ++i) {
            const double Lii = L.coeff(i, i);
            overSelf = std::max(overSelf, kb * Lii * Lii * invArea_[i] / (precBlocks_[i].trace() / 3.0));
            overShear += mp.bending.kb * Lii * invArea_[i] / static_cast<double>(nv);  // kb L_ii / A_i, averaged
        }
        const double shear = mp.law == InPlaneLaw::Lim ? mp.lim.mu : mp.capsule.Gs;
        overShear = shear > 0.0 ? overShear / shear : std::numeric_limits<double>::infinity();
        bending_ = overSelf >= opt_.bendingPreconditionerRatio && overShear >= opt_.bendingOverShearRatio;
        if (bending_) bendingL_ = kb * (L * invArea_.asDiagonal() * L);
    }
    for (Index e = 0; e < T.numEdges(); ++e) {
        const int a = T.edges(0, e), bq = T.edges(1, e);
        const Eigen::Vector3d d = (Xs_.col(a) - Xs_.col(bq)).normalized();
        const Eigen::Matrix3d G = gamma * d * d.transpose();
        for (int p = 0; p < 3; ++p)
            for (int q = 0; q < 3; ++q) {
                trip.emplace_back(3 * a + p, 3 * a + q, G(p, q));
                trip.emplace_back(3 * bq + p, 3 * bq + q, G(p, q));
                trip.emplace_back(3 * a + p, 3 * bq + q, -G(p, q));
                trip.emplace_back(3 * bq + p, 3 * a + q, -G(p, q));
            }
    }
    Eigen::SparseMatrix<double> Kp(n, n);
    Kp.setFromTriplets(trip.begin(), trip.end());
    precFactor_.velocity.factorize(Kp);
    if (bending_) factorizeNormal(Kp);
    if (!opt_.eliminateMultipliers) return;
    // The multipliers' columns B = (w / |w|, -n), P^-1 B and the Schur complement C P^-1 B
    // (C the two constraint rows); a near-singular complement keeps the block-diagonal form.
    precB_.resize(n, 2);
    precB_.col(0) = areaConstrained_ ? velocityPreconditioner(Eigen::Map<const VectorXd>(w_.data(), n) / wNorm_)
                                      : VectorXd::Zero(n);
    precB_.col(1) = velocityPreconditioner(-Eigen::Map<const VectorXd>(normals_.data(), n));
    // Without the area constraint the system's multiplier block is diag(1, 0) (the tension row
    // is the identity), so the complement C P^-1 B - diag(1, 0) has -1 in its first entry.
    Eigen::Matrix2d schur;
    schur.col(0) = areaConstrained_ ? constraintRows(precB_.col(0)) : Eigen::Vector2d(-1.0, 0.0);
    schur.col(1) = constraintRows(precB_.col(1));
    schurLu_.compute(schur);
    eliminateMultipliers_ = schur.allFinite() && std::abs(schur.determinant()) > 1e-12 * schur.squaredNorm();
}

void CoupledSystem::factorizeNormal(const Eigen::SparseMatrix<double>& Kp) {
    const Index nv = Xs_.cols();
    unitNormals_ = ops_.vertexNormals().colwise().normalized();
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(static_cast<std::size_t>(Kp.nonZeros() + bendingL_.nonZeros()));
    for (Index j = 0; j < Kp.outerSize(); ++j)
        for (Eigen::SparseMatrix<double>::InnerIterator it(Kp, j); it; ++it)
            trip.emplace_back(it.row() / 3, j / 3,
                              unitNormals_(it.row() % 3, it.row() / 3) * it.value() * unitNormals_(j % 3, j / 3));
    for (Index j = 0; j < bendingL_.outerSize(); ++j)
        for (Eigen::SparseMatrix<double>::InnerIterator it(bendingL_, j); it; ++it) trip.emplace_back(it.row(), j, it.value());
    Eigen::SparseMatrix<double> Kn(nv, nv);
    Kn.setFromTriplets(trip.begin(), trip.end());
    precFactor_.normal.factorize(Kn);
}

ThermalNoise thermalNoise(const CoupledSystem& sys, const CellFlowModel& model, const Vertices& X, double h,
                          const ThermalOptions& th, long stepIndex, CellFlowResult& res) {
    const Index nv = X.cols();
    // The stream of step n depends on (seed, n) alone: a resumed run draws the same numbers.
    Rng rng(th.seed, static_cast<std::uint64_t>(stepIndex), kThermalStream);
    VectorXd xi(3 * nv);
    for (Index i = 0; i < xi.size(); ++i) xi[i] = rng.normal();
    ThermalNoise noise;
    noise.force = Vertices::Zero(3, nv);
    const double gamma = model.edgeFriction();
    if (gamma > 0.0) {
        const Topology& T = model.membrane().topology();
        const double a = std::sqrt(2.0 * th.kT * gamma / h);
        for (Index e = 0; e < T.numEdges(); ++e) {
            const int i = T.edges(0, e), j = T.edges(1, e);
            const Eigen::Vector3d f = a * rng.normal() * (X.col(i) - X.col(j)).normalized();
            noise.force.col(i) += f;
            noise.force.col(j) -= f;
        }
    }
    const LinearMap M = [&](const VectorXd& x, VectorXd& y) {
        const Vertices v = sys.mobility(Eigen::Map<const Vertices>(x.data(), 3, nv), th.mobilityTolerance,
                                        res.mobilityIterations);
        y = Eigen::Map<const VectorXd>(v.data(), v.size());
    };
    const KrylovSqrtResult r = krylovSqrt(M, xi, {th.sqrtTolerance, th.sqrtMaxIterations});
    res.sqrtIterations += r.iterations;
    res.maxSqrtIterations = std::max(res.maxSqrtIterations, r.iterations);
    if (!r.converged)
        throw NumericalError(fmt::format("cell flow: the Lanczos square root of the mobility did not converge in {} "
                                         "iterations (change {:.3e})",
                                         r.iterations, r.change));
    noise.velocity = sys.secondKind(std::sqrt(2.0 * th.kT / h) * Eigen::Map<const Vertices>(r.value.data(), 3, nv));
    return noise;
}

}  // namespace trbc::cellflow
