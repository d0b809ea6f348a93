#include "flow/tube.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/error.hpp"
#include "mesh/geometry.hpp"

namespace trbc {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

constexpr double kPi = std::numbers::pi;

Eigen::Map<const VectorXd> flat(const Vertices& v) { return {v.data(), v.size()}; }

Vertices unflat(const VectorXd& v) { return Eigen::Map<const Vertices>(v.data(), 3, v.size() / 3); }

/// Least-squares slope of y(t).
double slope(const std::vector<double>& t, const std::vector<double>& y, std::size_t from, std::size_t to) {
    const double n = static_cast<double>(to - from);
    double st = 0.0, sy = 0.0;
    for (std::size_t k = from; k < to; ++k) {
        st += t[k];
        sy += y[k];
    }
    const double tm = st / n, ym = sy / n;
    double num = 0.0, den = 0.0;
    for (std::size_t k = from; k < to; ++k) {
        num += (t[k] - tm) * (y[k] - ym);
        den += (t[k] - tm) * (t[k] - tm);
    }
    return den > 0.0 ? num / den : 0.0;
}

}  // namespace

// ---- Geometry of the tube -----------------------------------------------------------------------

double maxVolumeInTube(double area, double radius) {
    const double RA = std::sqrt(area / (4.0 * kPi));
    if (radius >= RA) return area * RA / 3.0;  // the sphere: 4/3 pi RA^3 = A RA / 3
    return radius * area / 2.0 - 2.0 * kPi * radius * radius * radius / 3.0;
}

double minimumTubeRadius(double area, double volume) {
    if (!(area > 0.0) || !(volume > 0.0))
        throw InputError(fmt::format("tube: area {} and volume {} must be positive", area, volume));
    const double RA = std::sqrt(area / (4.0 * kPi));
    if (volume > maxVolumeInTube(area, RA) * (1.0 + 1e-12))
        throw InputError(fmt::format("tube: volume {} exceeds that of a sphere of area {}", volume, area));
    // V_max increases on (0, RA] (dV/dR = A/2 - 2 pi R^2 >= 0): bisection.
    double lo = 0.0, hi = RA;
    for (int it = 0; it < 200; ++it) {
        const double mid = 0.5 * (lo + hi);
        (maxVolumeInTube(area, mid) < volume ? lo : hi) = mid;
    }
    return hi;
}

namespace {

/// Triangles between two concentric polygons at x (outer ring `outer`, inner ring `inner`, vertex
/// ids with their angles in [0, 2 pi)), advancing around by the smaller next angle. Orientation
/// is fixed later.
void stitchRings(const std::vector<int>& outer, const std::vector<double>& ao, const std::vector<int>& inner,
                 const std::vector<double>& ai, std::vector<Eigen::Vector3i>& faces) {
    const int no = static_cast<int>(outer.size()), ni = static_cast<int>(inner.size());
    const auto mod2pi = [](double x) { return x - 2.0 * kPi * std::floor(x / (2.0 * kPi)); };
    // Angles unwrapped from outer[0]; the inner ring starts at its point nearest to outer[0].
    int j0 = 0;
    for (int j = 1; j < ni; ++j)
        if (std::abs(std::remainder(ai[j] - ao[0], 2.0 * kPi)) < std::abs(std::remainder(ai[j0] - ao[0], 2.0 * kPi))) j0 = j;
    const double base = std::remainder(ai[j0] - ao[0], 2.0 * kPi);
    std::vector<double> uo(no + 1), ui(ni + 1);
    for (int i = 0; i < no; ++i) uo[i] = mod2pi(ao[i] - ao[0]);
    uo[no] = 2.0 * kPi;
    for (int j = 0; j < ni; ++j) ui[j] = base + mod2pi(ai[(j0 + j) % ni] - ai[j0]);
    ui[ni] = base + 2.0 * kPi;
    int i = 0, j = 0;
    while (i < no || j < ni) {
        const int o0 = outer[i % no], i0 = inner[(j0 + j) % ni];
        if (i < no && (j == ni || uo[i + 1] <= ui[j + 1])) {
            faces.emplace_back(o0, outer[(i + 1) % no], i0);
            ++i;
        } else {
            faces.emplace_back(o0, inner[(j0 + j + 1) % ni], i0);
            ++j;
        }
    }
}

}  // namespace

Mesh tubeMesh(double radius, double halfLength, int pointsPerRing) {
    if (!(radius > 0.0) || !(halfLength > 0.0) || pointsPerRing < 6)
        throw InputError(fmt::format("tube mesh: radius {} and half-length {} must be > 0, points per ring {} >= 6",
                                     radius, halfLength, pointsPerRing));
    const int N = pointsPerRing;
    const double chord = 2.0 * radius * std::sin(kPi / N);
    const int K = std::max(2, static_cast<int>(std::lround(2.0 * halfLength / (0.5 * std::sqrt(3.0) * chord))) + 1);
    const double dx = 2.0 * halfLength / (K - 1);
    std::vector<Vector3d> X;
    std::vector<Eigen::Vector3i> F;
    for (int k = 0; k < K; ++k)
        for (int j = 0; j < N; ++j) {
            const double th = 2.0 * kPi * (j + 0.5 * (k % 2)) / N;
            X.emplace_back(-halfLength + k * dx, radius * std::cos(th), radius * std::sin(th));
        }
    const auto id = [N](int j, int k) { return k * N + ((j % N) + N) % N; };
    for (int k = 0; k + 1 < K; ++k)
        for (int j = 0; j < N; ++j) {
            if (k % 2 == 0) {  // ring k at integer positions, ring k + 1 shifted by +1/2
                F.emplace_back(id(j, k), id(j + 1, k), id(j, k + 1));
                F.emplace_back(id(j + 1, k), id(j + 1, k + 1), id(j, k + 1));
            } else {  // ring k shifted, ring k + 1 at integer positions
                F.emplace_back(id(j, k), id(j + 1, k), id(j + 1, k + 1));
                F.emplace_back(id(j, k), id(j + 1, k + 1), id(j, k + 1));
            }
        }
    // End caps: flat discs with concentric rings (radial spacing ~ sqrt(3)/2 chord, points per
    // ring in proportion to the radius) and a centre vertex; faces turned outward (-x, +x).
    const int M = std::max(1, static_cast<int>(std::lround(radius / (0.5 * std::sqrt(3.0) * chord))));
    for (int end = 0; end < 2; ++end) {
        const int k = end == 0 ? 0 : K - 1;
        const double x = end == 0 ? -halfLength : halfLength;
        std::vector<int> outer(N);
        std::vector<double> ao(N);
        for (int j = 0; j < N; ++j) {
            outer[j] = id(j, k);
            ao[j] = 2.0 * kPi * (j + 0.5 * (k % 2)) / N;
        }
        const std::size_t capStart = F.size();
        for (int m = M - 1; m >= 1; --m) {
            const int n = std::max(3, static_cast<int>(std::lround(static_cast<double>(N) * m / M)));
            std::vector<int> inner(n);
            std::vector<double> ai(n);
            for (int j = 0; j < n; ++j) {
                ai[j] = 2.0 * kPi * (j + 0.5 * (m % 2)) / n;
                inner[j] = static_cast<int>(X.size());
                X.emplace_back(x, radius * m / M * std::cos(ai[j]), radius * m / M * std::sin(ai[j]));
            }
            stitchRings(outer, ao, inner, ai, F);
            outer.swap(inner);
            ao.swap(ai);
        }
        const int centre = static_cast<int>(X.size());
        X.emplace_back(x, 0.0, 0.0);
        for (std::size_t j = 0; j < outer.size(); ++j) F.emplace_back(outer[j], outer[(j + 1) % outer.size()], centre);
        const double sign = end == 0 ? -1.0 : 1.0;
        for (std::size_t f = capStart; f < F.size(); ++f) {
            const Vector3d nrm = (X[F[f][1]] - X[F[f][0]]).cross(X[F[f][2]] - X[F[f][0]]);
            if (sign * nrm.x() < 0.0) std::swap(F[f][1], F[f][2]);
        }
    }
    Mesh m;
    m.X.resize(3, static_cast<Index>(X.size()));
    for (std::size_t i = 0; i < X.size(); ++i) m.X.col(static_cast<Index>(i)) = X[i];
    m.F.resize(3, static_cast<Index>(F.size()));
    for (std::size_t f = 0; f < F.size(); ++f) m.F.col(static_cast<Index>(f)) = F[f];
    return m;
}

// ---- The wall -----------------------------------------------------------------------------------

TubeWall::TubeWall(double radius, double halfLength, int pointsPerRing, const QuadratureOptions& quadrature)
    : radius_(radius), halfLength_(halfLength), pointsPerRing_(pointsPerRing) {
    const auto t0 = std::chrono::steady_clock::now();
    ops_ = std::make_unique<BoundaryIntegralOperators>(tubeMesh(radius, halfLength, pointsPerRing), quadrature);
    // S_WW + n (A n)^T: the single layer of a closed surface maps n to zero (int G . n dS = 0);
    // the rank-one term removes this null space and fixes int q . n dS = 0. The right-hand
    // sides S_Wc f carry no net flux through the wall (the cell's flow is divergence-free), so
    // they are compatible, and S_cW n = 0 inside: the cell does not see the choice.
    MatrixXd S = ops_->assembleSingleLayer();
    const Index nw = ops_->numVertices();
    const Vertices& n = ops_->vertexNormals();
    const VectorXd& a = ops_->vertexAreas();
    for (Index i = 0; i < nw; ++i)
        for (Index j = 0; j < nw; ++j) S.block<3, 3>(3 * i, 3 * j) += n.col(i) * (a[j] * n.col(j)).transpose();
    lu_.compute(S);
    setupSeconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double TubeWall::sagitta() const { return radius_ * (1.0 - std::cos(kPi / pointsPerRing_)); }

Vertices TubeWall::vertices(double centre) const {
    Vertices X = ops_->mesh().X;
    X.row(0).array() += centre;
    return X;
}

Vertices TubeWall::solveWall(const Vertices& v) const { return unflat(lu_.solve(flat(v))); }

std::shared_ptr<const TubeWall::Coupling> TubeWall::couple(const BoundaryIntegralOperators& surface,
                                                            double centre) const {
    const std::shared_ptr<SparePool> pool = spare_;
    const std::shared_ptr<Coupling> c(new Coupling, [pool](Coupling* p) {
        {
            const std::lock_guard<std::mutex> lock(pool->mutex);
            for (Eigen::MatrixXd* m : {&p->Scw, &p->Swc})
                if (pool->matrices.size() < 2) pool->matrices.push_back(std::move(*m));
        }
        delete p;
    });
    c->wall = this;
    c->centre = centre;
    {
        const std::lock_guard<std::mutex> lock(pool->mutex);
        for (Eigen::MatrixXd* m : {&c->Scw, &c->Swc})
            if (!pool->matrices.empty()) {
                *m = std::move(pool->matrices.back());
                pool->matrices.pop_back();
            }
    }
    Vertices targets = surface.mesh().X;  // the surface's vertices in the frame of the wall at x = 0
    targets.row(0).array() -= centre;
    ops_->assembleSingleLayerAt(targets, c->Scw);
    surface.assembleSingleLayerAt(vertices(centre), c->Swc);
    return c;
}

Vertices TubeWall::Coupling::wallDensity(const Vertices& f) const {
    const VectorXd v = Swc * flat(f);
    return unflat(wall->lu_.solve(v));
}

Vertices TubeWall::Coupling::apply(const Vertices& f) const {
    const VectorXd q = wall->lu_.solve(VectorXd(Swc * flat(f)));
    return unflat(VectorXd(-(Scw * q)));
}

Vertices poiseuilleVelocity(const Vertices& X, double radius, double centreLineSpeed) {
    Vertices u = Vertices::Zero(3, X.cols());
    u.row(0) = centreLineSpeed * (1.0 - (X.row(1).array().square() + X.row(2).array().square()) / (radius * radius));
    return u;
}

// ---- Rigid body in the tube (verification) -------------------------------------------------------

RigidBodyResult solveRigidBodyInTube(const BoundaryIntegralOperators& body, const TubeWall& wall, double viscosity,
                                     double centreLineSpeed, const Vector3d& center, bool freelySuspended,
                                     const Vector3d& velocity, const Vector3d& angularVelocity, double tubeCentre) {
    if (!(viscosity > 0.0)) throw InputError(fmt::format("viscosity = {}: must be > 0", viscosity));
    const Index nv = body.numVertices(), n = 3 * nv;
    const Vertices& X = body.mesh().X;
    const VectorXd& A = body.vertexAreas();
    const Vertices& nrm = body.vertexNormals();
    const double c = 1.0 / (8.0 * kPi * viscosity);
    // c (S + W) + n (A n)^T  (the rank-one term fixes int f . n dS = 0, the null space of S + W).
    const auto coupling = wall.couple(body, tubeCentre);
    MatrixXd K = body.assembleSingleLayer() - coupling->Scw * wall.solveWallMatrix(coupling->Swc);
    K *= c;
    for (Index i = 0; i < nv; ++i)
        for (Index j = 0; j < nv; ++j)
            K.block<3, 3>(3 * i, 3 * j) += nrm.col(i) * (A[j] * nrm.col(j)).transpose();
    const Vertices uP = poiseuilleVelocity(X, wall.radius(), centreLineSpeed);
    // Rigid-motion blocks: u_i = U + Omega x r_i = U - [r_i]x Omega.
    const auto cross = [](const Vector3d& r) {
        Eigen::Matrix3d m;
        m << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
        return m;
    };
    RigidBodyResult res;
    VectorXd f;
    if (!freelySuspended) {
        VectorXd b(n);
        for (Index i = 0; i < nv; ++i)
            b.segment<3>(3 * i) = uP.col(i) - velocity - angularVelocity.cross(X.col(i) - center);
        f = K.partialPivLu().solve(b);
        res.velocity = velocity;
        res.angularVelocity = angularVelocity;
    } else {
        MatrixXd M = MatrixXd::Zero(n + 6, n + 6);
        VectorXd b = VectorXd::Zero(n + 6);
        M.topLeftCorner(n, n) = K;
        for (Index i = 0; i < nv; ++i) {
            const Vector3d r = X.col(i) - center;
            M.block<3, 3>(3 * i, n).setIdentity();
            M.block<3, 3>(3 * i, n + 3) = -cross(r);
            b.segment<3>(3 * i) = uP.col(i);
            // Force and torque balance (lumped areas): sum A_i f_i = 0, sum A_i r_i x f_i = 0.
            M.block<3, 3>(n, 3 * i) = A[i] * Eigen::Matrix3d::Identity();
            M.block<3, 3>(n + 3, 3 * i) = A[i] * cross(r);
        }
        const VectorXd x = M.partialPivLu().solve(b);
        f = x.head(n);
        res.velocity = x.segment<3>(n);
        res.angularVelocity = x.segment<3>(n + 3);
    }
    res.traction = unflat(f);
    res.force = body.integrate(res.traction);
    res.torque = body.moment(res.traction, center);
    return res;
}

// ---- The environment ----------------------------------------------------------------------------

double wallClearance(const Vertices& X, double radius) {
    return radius - (X.row(1).array().square() + X.row(2).array().square()).sqrt().maxCoeff();
}

TubeEnvironment::TubeEnvironment(const TubeSetup& s, const QuadratureOptions& quadrature)
    : setup_(s), wall_(s.radius, s.halfLength, s.pointsPerRing, quadrature),
      minClearance_(std::numeric_limits<double>::infinity()) {
    if (!(s.repulsionRange > 0.0) || !(s.repulsionPressure >= 0.0) || !(s.vertexWeight >= 0.0))
        throw InputError("tube: repulsion range must be > 0, pressure and vertex weight >= 0");
}

Vertices TubeEnvironment::background(const Vertices& X) const {
    return poiseuilleVelocity(X, setup_.radius, setup_.centreLineSpeed);
}

double TubeEnvironment::repulsionEnergy(const Vertices& X) const {
    const double R = setup_.radius, dl = setup_.repulsionRange, p0 = setup_.repulsionPressure;
    double e = 0.0;
    for (Index i = 0; i < X.cols(); ++i) {
        const double d = std::max(R - std::hypot(X(1, i), X(2, i)), 1e-3 * dl);
        if (d < dl) e += setup_.vertexWeight * p0 * (dl * dl * (1.0 / d - 1.0 / dl) - 2.0 * dl * std::log(dl / d) + dl - d);
    }
    return e;
}

void TubeEnvironment::addExternalGradient(const Vertices& X, Vertices& g) const {
    const double R = setup_.radius, dl = setup_.repulsionRange, p0 = setup_.repulsionPressure;
    for (Index i = 0; i < X.cols(); ++i) {
        const double r = std::hypot(X(1, i), X(2, i));
        const double d = R - r;
        if (d >= dl || r == 0.0) continue;
        // dE/dx_i = w psi'(d) dd/dx_i, psi'(d) = -p0 (delta/d - 1)^2, dd/dx = -(0, y, z) / r.
        const double dc = std::max(d, 1e-3 * dl);
        const double s = setup_.vertexWeight * p0 * (dl / dc - 1.0) * (dl / dc - 1.0) / r;
        g(1, i) += s * X(1, i);
        g(2, i) += s * X(2, i);
    }
}

FlowEnvironment::DensityMap TubeEnvironment::wallOperator(const Vertices& Xs,
                                                          const BoundaryIntegralOperators& cellOperators) const {
    // The tube re-centred on the cell's centroid along the axis (translation invariance).
    const auto coupling = wall_.couple(cellOperators, centroid(Xs).x());
    return [coupling](const Vertices& f) { return coupling->apply(f); };
}

std::string TubeEnvironment::inadmissible(const Vertices& X) const {
    const double clearance = wallClearance(X, setup_.radius);
    const Vector3d c = centroid(X);
    minClearance_ = std::min(minClearance_, clearance);
    maxOffAxis_ = std::max(maxOffAxis_, std::hypot(c.y(), c.z()));
    if (clearance <= wall_.sagitta())
        return fmt::format("the cell touched the tube wall (vertex clearance {:.4g} R_A, the polygonal wall lies {:.4g} "
                           "R_A inside the circle)",
                           clearance, wall_.sagitta());
    const double reach = (X.row(0).array() - c.x()).abs().maxCoeff();
    if (reach > setup_.halfLength - setup_.endMargin * setup_.radius)
        return fmt::format("the cell (half-length {:.4g} R_A) no longer fits the discretised wall (half-length {:.4g} R_A "
                           "minus a margin of {:.3g} R): use a longer tube",
                           reach, setup_.halfLength, setup_.endMargin);
    return {};
}

// ---- Initial shape ------------------------------------------------------------------------------

Vertices fitIntoTube(const Vertices& X, const Faces& F, double radius, double clearance, double A0, double V0) {
    const Vector3d c = centroid(X);
    const Vertices Y = X.colwise() - c;
    const double room = radius - clearance;
    if (!(room > 0.0)) throw InputError(fmt::format("tube: clearance {} >= radius {}", clearance, radius));
    if (wallClearance(Y, radius) >= clearance) return Y;
    // Squeeze the widest transverse direction s by b, adjust the other (o) by c and x by a.
    const int s = Y.row(1).cwiseAbs().maxCoeff() >= Y.row(2).cwiseAbs().maxCoeff() ? 1 : 2, o = 3 - s;
    const auto mapped = [&](double a, double b, double cc) {
        Vertices Z = Y;
        Z.row(0) *= a;
        Z.row(s) *= b;
        Z.row(o) *= cc;
        return Z;
    };
    const auto residual = [&](double a, double b, double cc) {
        const Vertices Z = mapped(a, b, cc);
        return Eigen::Vector2d(totalArea(Z, F) / A0 - 1.0, enclosedVolume(Z, F) / V0 - 1.0);
    };
    double b = room / Y.row(s).cwiseAbs().maxCoeff();
    for (int attempt = 0; attempt < 60; ++attempt, b *= 0.97) {
        double a = 1.0 / b, cc = 1.0;
        Eigen::Vector2d r = residual(a, b, cc);
        for (int it = 0; it < 60 && r.norm() > 1e-13; ++it) {
            Eigen::Matrix2d J;
            const double h = 1e-7;
            J.col(0) = (residual(a + h, b, cc) - residual(a - h, b, cc)) / (2.0 * h);
            J.col(1) = (residual(a, b, cc + h) - residual(a, b, cc - h)) / (2.0 * h);
            const Eigen::Vector2d step = J.fullPivLu().solve(-r);
            double lam = 1.0;
            while (lam > 1e-4) {
                const double an = a + lam * step[0], cn = cc + lam * step[1];
                if (an > 0.0 && cn > 0.0) {
                    const Eigen::Vector2d rn = residual(an, b, cn);
                    if (rn.norm() < r.norm()) {
                        a = an;
                        cc = cn;
                        r = rn;
                        break;
                    }
                }
                lam *= 0.5;
            }
            if (lam <= 1e-4) break;
        }
        if (r.norm() > 1e-10) continue;
        const Vertices Z = mapped(a, b, cc);
        if (wallClearance(Z, radius) >= clearance) return Z;
    }
    throw NumericalError(fmt::format("tube: no affine deformation of the cell with its area and volume fits a tube of "
                                     "radius {:.4g} with clearance {:.3g} (um)",
                                     radius, clearance));
}

// ---- Observables --------------------------------------------------------------------------------

void TubeEnvironment::restoreRecords(const std::vector<double>& r) const {
    if (r.size() != 2) throw InputError(fmt::format("tube records: {} values, 2 expected", r.size()));
    minClearance_ = r[0];
    maxOffAxis_ = r[1];
}

void TubeEnvironment::resetRecords() const {
    minClearance_ = std::numeric_limits<double>::infinity();
    maxOffAxis_ = 0.0;
}

bool tubeShapeSettled(const std::vector<double>& t, const std::vector<Vertices>& frames, double span,
                      double tolerance) {
    if (t.size() != frames.size() || t.empty() || t.back() - t.front() < span) return false;
    for (const int axis : {0, 1, 2}) {
        double lo = std::numeric_limits<double>::infinity(), hi = -lo, sum = 0.0;
        std::size_t n = 0;
        for (std::size_t k = t.size(); k-- > 0 && t[k] >= t.back() - span * (1.0 + 1e-12);) {
            const double e = frames[k].row(axis).maxCoeff() - frames[k].row(axis).minCoeff();
            lo = std::min(lo, e);
            hi = std::max(hi, e);
            sum += e;
            ++n;
        }
        if (n < 2 || !(hi - lo < tolerance * sum / static_cast<double>(n))) return false;
    }
    return true;
}

TubeObservables analyzeTubeFrames(const std::vector<double>& t, const std::vector<Vertices>& frames) {
    const std::size_t n = frames.size();
    if (t.size() != n) throw InputError(fmt::format("tube frames: {} times for {} frames", t.size(), n));
    if (n < 16) throw InputError(fmt::format("tube frames: {} frames, at least 16 needed", n));
    TubeObservables o;
    std::vector<double> len(n), cx(n);
    std::vector<Vector3d> c(n);
    for (std::size_t k = 0; k < n; ++k) {
        const Vertices& X = frames[k];
        len[k] = X.row(0).maxCoeff() - X.row(0).minCoeff();
        c[k] = centroid(X);
        cx[k] = c[k].x();
        o.maxOffAxis = std::max(o.maxOffAxis, std::hypot(c[k].y(), c[k].z()));
    }
    const auto mean = [](const std::vector<double>& v, std::size_t a, std::size_t b) {
        double s = 0.0;
        for (std::size_t k = a; k < b; ++k) s += v[k];
        return s / static_cast<double>(b - a);
    };
    const std::size_t half = n / 2, q3 = (3 * n) / 4, e8 = n - n / 8, e7 = n - 2 * (n / 8);
    for (std::size_t k = half; k < n; ++k) {
        const Vertices& X = frames[k];
        o.widthY += X.row(1).maxCoeff() - X.row(1).minCoeff();
        o.widthZ += X.row(2).maxCoeff() - X.row(2).minCoeff();
    }
    o.widthY /= static_cast<double>(n - half);
    o.widthZ /= static_cast<double>(n - half);
    o.length = mean(len, half, n);
    o.framesUsed = n - half;
    o.velocity = slope(t, cx, e8, n);
    const double l3 = mean(len, half, q3), l4 = mean(len, q3, n);
    o.lengthChange = std::abs(l4 - l3) / l4;
    const double v7 = slope(t, cx, e7, e8);
    o.velocityChange = std::abs(o.velocity - v7) / std::max(std::abs(o.velocity), 1e-300);
    o.travel = (c[n - 1] - c[half]).norm();
    for (std::size_t k = half + 1; k < n; ++k)
        o.cellFrameMotion +=
            ((frames[k].colwise() - c[k]) - (frames[k - 1].colwise() - c[k - 1])).colwise().norm().maxCoeff();
    return o;
}

}  // namespace trbc
