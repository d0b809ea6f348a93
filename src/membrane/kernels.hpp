#pragma once
// Force kernels: small pure functions of one triangle or one edge stencil (Mirheo style).
// The loops that gather positions, call them and scatter gradients live in model.cpp.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

#include "membrane/parameters.hpp"

namespace trbc::kernels {

using Vec3 = Eigen::Vector3d;

/// Face geometry: twice-area vector n2A = (x_j - x_i) x (x_k - x_i), area A_t = |n2A|/2,
/// outward unit normal n.
struct FaceGeometry {
    Vec3 normal;
    double area;
};

inline FaceGeometry faceGeometry(const Vec3& xi, const Vec3& xj, const Vec3& xk) {
    const Vec3 c = (xj - xi).cross(xk - xi);
    const double twiceArea = c.norm();
    return {c / twiceArea, 0.5 * twiceArea};
}

/// dA_t/dx for the three corners: dA/dx_i = 1/2 n x (x_k - x_j), cyclic (MODEL.md C).
struct Corner3 {
    Vec3 i, j, k;
};

inline Corner3 areaGradient(const Vec3& n, const Vec3& xi, const Vec3& xj, const Vec3& xk) {
    return {0.5 * n.cross(xk - xj), 0.5 * n.cross(xi - xk), 0.5 * n.cross(xj - xi)};
}

/// dV_t/dx with V_t = 1/6 (x_i - c).((x_j - c) x (x_k - c)), c a fixed origin.
inline Corner3 volumeGradient(const Vec3& yi, const Vec3& yj, const Vec3& yk) {
    return {yj.cross(yk) / 6.0, yk.cross(yi) / 6.0, yi.cross(yj) / 6.0};
}

/// atan2(y, x) without branches, so that loops over many edges vectorise (libm's atan2 does not,
/// and costs ~17 ns a call). Octant reduction to |t| <= tan(pi/8), then
/// atan(t) = t + t^3 P(t^2) with a degree-10 least-squares fit of (atan(t)/t - 1)/t^2
/// (max error 7e-17 against long-double atan on the reduced range; a test checks <= 2 ulp-ish
/// agreement with std::atan2 over the circle).
inline double fastAtan2(double y, double x) {
    constexpr double kPi = 3.14159265358979323846, kTanPi8 = 0.41421356237309504880;
    const double ay = std::abs(y), ax = std::abs(x);
    const double lo = std::min(ay, ax), hi = std::max(ay, ax);
    const bool shift = lo > kTanPi8 * hi;  // t in (tan pi/8, 1]: atan t = pi/4 + atan((t-1)/(t+1))
    const double t = (shift ? lo - hi : lo) / (shift ? lo + hi : hi);
    const double z = t * t;
    double p = 0.02116433177473143;
    p = p * z - 0.043505175038486062;
    p = p * z + 0.056892411262755863;
    p = p * z - 0.06640412549964593;
    p = p * z + 0.076899751088093729;
    p = p * z - 0.090907746926810001;
    p = p * z + 0.11111106254106223;
    p = p * z - 0.14285714182892653;
    p = p * z + 0.199999999988794;
    p = p * z - 0.33333333333328524;
    double r = t + t * z * p + (shift ? 0.25 * kPi : 0.0);
    r = ay > ax ? 0.5 * kPi - r : r;
    r = x < 0 ? kPi - r : r;
    return y < 0 ? -r : r;
}

/// Signed dihedral angle of edge (a, b) between the outward normals of faces (a,b,c) and
/// (b,a,d), positive when convex: theta = atan2((n1 x n2).e, n1.n2) (MODEL.md C.1).
inline double dihedralAngle(const Vec3& n1, const Vec3& n2, const Vec3& eHat) {
    return fastAtan2(n1.cross(n2).dot(eHat), n1.dot(n2));
}

/// Gradient of l_e theta_e over the edge stencil (a, b, c, d), scaled by `coef`:
/// coef [theta dl/dx + l dtheta/dx] with dtheta/dx_c = -n1/h_c, dtheta/dx_d = -n2/h_d,
/// dtheta/dx_a = (1 - s_c) n1/h_c + (1 - s_d) n2/h_d, dtheta/dx_b = s_c n1/h_c + s_d n2/h_d,
/// h = 2 A / l the heights over the edge and s_c = (x_c - x_a).(x_b - x_a)/l^2 (MODEL.md C.1).
struct Corner4 {
    Vec3 a, b, c, d;
};

inline Corner4 lengthThetaGradient(double coef, const Vec3& xa, const Vec3& xb, const Vec3& xc,
                                   const Vec3& xd, const Vec3& n1, const Vec3& n2, double area1,
                                   double area2, double theta) {
    const Vec3 e = xb - xa;
    const double l2 = e.squaredNorm(), l = std::sqrt(l2);
    const Vec3 eHat = e / l;
    const double sc = (xc - xa).dot(e) / l2, sd = (xd - xa).dot(e) / l2;
    // l * n/h = l^2 n / (2 A)
    const Vec3 g1 = (coef * l2 / (2.0 * area1)) * n1;
    const Vec3 g2 = (coef * l2 / (2.0 * area2)) * n2;
    const Vec3 gl = (coef * theta) * eHat;
    return {-gl + (1.0 - sc) * g1 + (1.0 - sd) * g2, gl + sc * g1 + sd * g2, -g1, -g2};
}

/// Stress-free data of one face for the Lim energy: |a0|^2, |b0|^2, a0.b0 and A0_t, with
/// a0 = X_j - X_i, b0 = X_k - X_i.
struct LimReference {
    double a0a0, b0b0, a0b0, area0;
};

inline LimReference limReference(const Vec3& Xi, const Vec3& Xj, const Vec3& Xk) {
    const Vec3 a0 = Xj - Xi, b0 = Xk - Xi;
    return {a0.squaredNorm(), b0.squaredNorm(), a0.dot(b0), 0.5 * a0.cross(b0).norm()};
}

/// Lim energy of one face and its gradient written as
/// dU_t/dx = cArea dA_t/dx + cN dN/dx (MODEL.md C.2) with
/// N = |b0|^2 |a|^2 + |a0|^2 |b|^2 - 2 (a0.b0)(a.b), alpha = A/A0 - 1, beta = N/(8 A0 A) - 1.
struct LimFace {
    double energy, alpha, beta, cArea, cN;
};

inline LimFace limFace(const LimParameters& p, const LimReference& r, const Vec3& a, const Vec3& b,
                       double area) {
    const double N = r.b0b0 * a.squaredNorm() + r.a0a0 * b.squaredNorm() - 2.0 * r.a0b0 * a.dot(b);
    const double alpha = area / r.area0 - 1.0;
    const double beta = N / (8.0 * r.area0 * area) - 1.0;
    const double a2 = alpha * alpha;
    const double energy =
        r.area0 * (0.5 * p.Kalpha * a2 * (1.0 + p.a3 * alpha + p.a4 * a2) +
                   p.mu * beta * (1.0 + p.b1 * alpha + p.b2 * beta));
    const double dUdAlpha = r.area0 * (p.Kalpha * alpha * (1.0 + 1.5 * p.a3 * alpha + 2.0 * p.a4 * a2) +
                                       p.mu * p.b1 * beta);
    const double dUdBeta = r.area0 * p.mu * (1.0 + p.b1 * alpha + 2.0 * p.b2 * beta);
    // dalpha/dx = dA/dx / A0; dbeta/dx = dN/dx / (8 A0 A) - (beta + 1)/A dA/dx
    return {energy, alpha, beta, dUdAlpha / r.area0 - dUdBeta * (beta + 1.0) / area,
            dUdBeta / (8.0 * r.area0 * area)};
}

/// dN/dx for the three corners (MODEL.md C.2), scaled by c.
inline Corner3 limShearGradient(double c, const LimReference& r, const Vec3& a, const Vec3& b) {
    const Vec3 gj = (2.0 * c) * (r.b0b0 * a - r.a0b0 * b);
    const Vec3 gk = (2.0 * c) * (r.a0a0 * b - r.a0b0 * a);
    return {-gj - gk, gj, gk};
}

/// Pairwise membrane-viscosity force on vertex a of edge (a, b) (MODEL.md C.4):
/// -gamma [(v_a - v_b).e] e with e = (x_a - x_b)/|x_a - x_b|; vertex b gets the opposite.
inline Vec3 edgeViscousForce(double gamma, const Vec3& xa, const Vec3& xb, const Vec3& va,
                             const Vec3& vb) {
    const Vec3 e = (xa - xb).normalized();
    return -gamma * (va - vb).dot(e) * e;
}

}  // namespace trbc::kernels
