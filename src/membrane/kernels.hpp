#pragma once
// Force kernels: small pure functions of one triangle or one edge stencil (Mirheo style).
// The loops that gather positions, call them and scatter gradients live in model.cpp.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#include "membrane/parameters.hpp"

namespace trbc::kernels {

using Vec3 = Eigen::Vector3d;

/// A 3-vector of plain doubles for the kernels that run inside the face and edge loops: the
/// compiler vectorises those loops across faces or edges, which Eigen's own SSE code for
/// fixed-size 3-vectors would prevent.
struct Real3 {
    double x, y, z;
};

inline Real3 operator+(Real3 a, Real3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Real3 operator-(Real3 a, Real3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Real3 operator-(Real3 a) { return {-a.x, -a.y, -a.z}; }
inline Real3 operator*(double s, Real3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline Real3& operator+=(Real3& a, Real3 b) { return a = a + b; }
inline double dot(Real3 a, Real3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Real3 cross(Real3 a, Real3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

/// Twice-area vector of face (i, j, k): c = (x_j - x_i) x (x_k - x_i), so that A_t = |c|/2 and
/// the outward unit normal is n = c/|c|.
inline Real3 twiceAreaVector(Real3 xi, Real3 xj, Real3 xk) { return cross(xj - xi, xk - xi); }

/// Signed volume of the tetrahedron (o, x_i, x_j, x_k), y = x - o: V_t = y_i.(y_j x y_k)/6.
inline double faceVolume(Real3 yi, Real3 yj, Real3 yk) { return dot(yi, cross(yj, yk)) / 6.0; }

/// A vector per corner (i, j, k) of a face.
struct Corner3 {
    Real3 i, j, k;
};

inline Corner3& operator+=(Corner3& a, const Corner3& b) {
    a.i += b.i;
    a.j += b.j;
    a.k += b.k;
    return a;
}

/// The edges opposite the corners, e_i = x_k - x_j, e_j = x_i - x_k, e_k = x_j - x_i
/// (cyclic, along the face orientation).
inline Corner3 oppositeEdges(Real3 xi, Real3 xj, Real3 xk) { return {xk - xj, xi - xk, xj - xi}; }

/// cArea dA_t/dx + cVolume dV_t/dx at the three corners (docs/MEMBRANE_MODEL.md), with y = x - o and
/// V_t = 1/6 y_i.(y_j x y_k): dA_t/dx_r = 1/2 n x e_r (r = i, j, k) and, as
/// y_j = y_i + e_k, y_k = y_i - e_j and e_j x e_k = 2 A_t n,
/// dV_t/dx_i = 1/6 y_j x y_k = 1/6 (y_i x e_i + 2 A_t n), dV_t/dx_j = 1/6 y_k x y_i = 1/6 y_i x e_j,
/// dV_t/dx_k = 1/6 y_i x y_j = 1/6 y_i x e_k. Together, with u = cArea/2 n + cVolume/6 y_i:
///   g_i = u x e_i + cVolume A_t/3 n,  g_j = u x e_j,  g_k = u x e_k.
inline Corner3 areaVolumeGradient(double cArea, double cVolume, Real3 n, double area, Real3 yi, Corner3 e) {
    const Real3 u = (0.5 * cArea) * n + (cVolume / 6.0) * yi;
    return {cross(u, e.i) + (cVolume * area / 3.0) * n, cross(u, e.j), cross(u, e.k)};
}

/// c ? a : b, branch-free with both a and b computed. A plain ?: lets GCC move the arithmetic of
/// a or b under a branch, which (as it might trap, -ftrapping-math) keeps the loop from
/// vectorising on targets without AVX-512 masks.
inline double select(bool c, double a, double b) {
    const std::uint64_t m = -static_cast<std::uint64_t>(c), ua = std::bit_cast<std::uint64_t>(a),
                        ub = std::bit_cast<std::uint64_t>(b);
    return std::bit_cast<double>((ua & m) | (ub & ~m));
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
    const double t = select(shift, lo - hi, lo) / select(shift, lo + hi, hi);
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
    double r = t + t * z * p + select(shift, 0.25 * kPi, 0.0);
    r = select(ay > ax, 0.5 * kPi - r, r);
    r = select(x < 0, kPi - r, r);
    return select(y < 0, -r, r);
}

/// Signed dihedral angle of edge (a, b) between the outward normals of faces (a,b,c) and
/// (b,a,d), positive when convex (docs/MEMBRANE_MODEL.md, bending): theta = atan2((n1 x n2).e_hat, n1.n2)
/// = atan2(y, l x) with e = x_b - x_a, l = |e|, y = (n1 x n2).e, x = n1.n2. In two steps, so
/// that the loops can take the square root l = sqrt(e.e) for a whole block of edges in between.
struct DihedralArgs {
    double y, x;
};

inline DihedralArgs dihedralArgs(Real3 n1, Real3 n2, Real3 e) { return {dot(cross(n1, n2), e), dot(n1, n2)}; }

inline double dihedralAngle(DihedralArgs a, double l) { return fastAtan2(a.y, l * a.x); }

/// Face t's share of sum_e coef_e d(l_e theta_e)/dx over its three edges (docs/MEMBRANE_MODEL.md, bending split by
/// face, theta dl/dx halved between the two faces of an edge). For the half-edge h = (p -> q) of
/// t with opposite corner r, e_h = x_q - x_p, s_h = (x_r - x_p).e_h / l_h^2 and h_r = 2 A_t / l_h:
///   d/dx_p = (1 - s_h) G_h n - B_h e_h,  d/dx_q = s_h G_h n + B_h e_h,  d/dx_r = -G_h n,
/// G_h = coef_h l_h / h_r = coef_h |e_h|^2 / (2 A_t), s_h G_h = coef_h (x_r - x_p).e_h / (2 A_t),
/// B_h = coef_h theta_h / (2 l_h). The other face of the edge has the half-edge q -> p.
/// Half-edges i, j, k are the ones opposite corners i, j, k: (j -> k), (k -> i), (i -> j), with
/// e = oppositeEdges(x_i, x_j, x_k).
struct HalfEdges {
    double i, j, k;
};

inline Corner3 lengthThetaGradient(Real3 n, Corner3 e, double invTwiceArea, HalfEdges coef,
                                   HalfEdges thetaOverLen) {
    const Real3 ei = e.i, ej = e.j, ek = e.k;
    const double wi = coef.i * invTwiceArea, wj = coef.j * invTwiceArea, wk = coef.k * invTwiceArea;
    const double Gi = wi * dot(ei, ei), Gj = wj * dot(ej, ej), Gk = wk * dot(ek, ek);
    const double Si = -wi * dot(ek, ei), Sj = -wj * dot(ei, ej), Sk = -wk * dot(ej, ek);  // s G
    const double Bi = 0.5 * coef.i * thetaOverLen.i, Bj = 0.5 * coef.j * thetaOverLen.j,
                 Bk = 0.5 * coef.k * thetaOverLen.k;
    return {(Gk - Sk + Sj - Gi) * n + Bj * ej - Bk * ek,
            (Gi - Si + Sk - Gj) * n + Bk * ek - Bi * ei,
            (Gj - Sj + Si - Gk) * n + Bi * ei - Bj * ej};
}

/// Stress-free data of one face for the Lim energy: |a0|^2, |b0|^2, a0.b0, A0_t and 1/A0_t,
/// with a0 = X_j - X_i, b0 = X_k - X_i.
struct LimReference {
    double a0a0, b0b0, a0b0, area0, invArea0;
};

inline LimReference limReference(const Vec3& Xi, const Vec3& Xj, const Vec3& Xk) {
    const Vec3 a0 = Xj - Xi, b0 = Xk - Xi;
    const double area0 = 0.5 * a0.cross(b0).norm();
    return {a0.squaredNorm(), b0.squaredNorm(), a0.dot(b0), area0, 1.0 / area0};
}

/// N = |b0|^2 |a|^2 + |a0|^2 |b|^2 - 2 (a0.b0)(a.b) with a = x_j - x_i, b = x_k - x_i
/// (docs/MEMBRANE_MODEL.md, Lim energy), so that beta = N/(8 A0 A) - 1; from aa = a.a, bb = b.b, ab = a.b.
inline double limN(const LimReference& r, double aa, double bb, double ab) {
    return r.b0b0 * aa + r.a0a0 * bb - 2.0 * r.a0b0 * ab;
}

/// Lim energy of one face and its gradient written as dU_t/dx = cArea dA_t/dx + cN dN/dx
/// (docs/MEMBRANE_MODEL.md, Lim energy), from N, A = A_t and 1/A: alpha = A/A0 - 1, beta = N/(8 A0 A) - 1,
/// cArea = dU/dalpha / A0 - dU/dbeta (beta + 1)/A, cN = dU/dbeta / (8 A0 A)
/// (dalpha/dx = dA/dx / A0, dbeta/dx = dN/dx / (8 A0 A) - (beta + 1)/A dA/dx).
struct LimFace {
    double energy, alpha, beta, cArea, cN;
};

inline LimFace limFace(const LimParameters& p, const LimReference& r, double N, double area, double invArea) {
    const double alpha = area * r.invArea0 - 1.0;
    const double beta = 0.125 * N * r.invArea0 * invArea - 1.0;
    const double a2 = alpha * alpha;
    const double energy = r.area0 * (0.5 * p.Kalpha * a2 * (1.0 + p.a3 * alpha + p.a4 * a2) +
                                     p.mu * beta * (1.0 + p.b1 * alpha + p.b2 * beta));
    // dU/dalpha / A0 and dU/dbeta / A0
    const double dAlpha =
        p.Kalpha * alpha * (1.0 + 1.5 * p.a3 * alpha + 2.0 * p.a4 * a2) + p.mu * p.b1 * beta;
    const double dBeta = p.mu * (1.0 + p.b1 * alpha + 2.0 * p.b2 * beta);
    return {energy, alpha, beta, dAlpha - dBeta * r.area0 * (beta + 1.0) * invArea, 0.125 * dBeta * invArea};
}

/// The same from the current edge vectors a = x_j - x_i, b = x_k - x_i and the area A_t.
inline LimFace limFace(const LimParameters& p, const LimReference& r, const Vec3& a, const Vec3& b,
                       double area) {
    return limFace(p, r, limN(r, a.squaredNorm(), b.squaredNorm(), a.dot(b)), area, 1.0 / area);
}

/// Capsule-law energy of one face and its gradient written as dU_t/dx = cArea dA_t/dx + cN dN/dx
/// (docs/MEMBRANE_MODEL.md, in-plane laws), from the same N and A = A_t as the Lim energy. With C the
/// right Cauchy-Green tensor of the face's affine map from its reference, tr C = N/(4 A0^2) and
/// det C = (A/A0)^2, so I1 = N/(4 A0^2) - 2 and I2 = J^2 - 1 (J = A/A0). U_t = A0 W(I1, I2), and
/// with W_k = dW/dI_k, dI1/dx = dN/dx / (4 A0^2), dI2/dx = 2 A/A0^2 dA/dx:
///   cN = W_1 / (4 A0),  cArea = 2 W_2 J.
/// Neo-Hookean, W = Gs/2 (I1 - 1 + 1/(I2 + 1)): W_1 = Gs/2, W_2 = -Gs/(2 J^4),
///   cN = Gs/(8 A0), cArea = -Gs / J^3.
/// Skalak, W = Gs/4 (I1^2 + 2 I1 - 2 I2 + C I2^2): W_1 = Gs/2 (I1 + 1), W_2 = Gs/2 (C I2 - 1),
///   cN = Gs (I1 + 1)/(8 A0), cArea = Gs (C I2 - 1) J.
struct CapsuleFace {
    double energy, I1, I2, cArea, cN;
};

template <InPlaneLaw law>
inline CapsuleFace capsuleFace(const CapsuleLawParameters& p, const LimReference& r, double N, double area,
                               double invArea) {
    static_assert(law == InPlaneLaw::NeoHookean || law == InPlaneLaw::Skalak);
    const double J = area * r.invArea0;
    const double I1 = 0.25 * N * r.invArea0 * r.invArea0 - 2.0, I2 = J * J - 1.0;
    const double cN1 = 0.125 * p.Gs * r.invArea0;  // Gs/(8 A0)
    if constexpr (law == InPlaneLaw::NeoHookean) {
        const double invJ = r.area0 * invArea, invJ2 = invJ * invJ;  // 1/(I2 + 1) = 1/J^2
        return {0.5 * p.Gs * r.area0 * (I1 - 1.0 + invJ2), I1, I2, -p.Gs * invJ2 * invJ, cN1};
    } else {
        return {0.25 * p.Gs * r.area0 * (I1 * (I1 + 2.0) - 2.0 * I2 + p.C * I2 * I2), I1, I2,
                p.Gs * (p.C * I2 - 1.0) * J, cN1 * (I1 + 1.0)};
    }
}

/// The same from the current edge vectors a = x_j - x_i, b = x_k - x_i and the area A_t.
template <InPlaneLaw law>
inline CapsuleFace capsuleFace(const CapsuleLawParameters& p, const LimReference& r, const Vec3& a, const Vec3& b,
                               double area) {
    return capsuleFace<law>(p, r, limN(r, a.squaredNorm(), b.squaredNorm(), a.dot(b)), area, 1.0 / area);
}

/// dN/dx for the three corners (docs/MEMBRANE_MODEL.md, Lim energy), scaled by c:
/// dN/dx_j = 2 (|b0|^2 a - (a0.b0) b), dN/dx_k = 2 (|a0|^2 b - (a0.b0) a), dN/dx_i = -dN/dx_j - dN/dx_k.
inline Corner3 limShearGradient(double c, const LimReference& r, Real3 a, Real3 b) {
    const double ca = 2.0 * c * r.a0a0, cb = 2.0 * c * r.b0b0, cab = 2.0 * c * r.a0b0;
    const Real3 gj = cb * a - cab * b, gk = ca * b - cab * a;
    return {-(gj + gk), gj, gk};
}

/// Pairwise membrane-viscosity force on vertex a of edge (a, b) along the unit edge vector e
/// (docs/MEMBRANE_MODEL.md, membrane viscosity): -gamma [(v_a - v_b).e] e; vertex b gets the opposite.
inline Vec3 edgeViscousForceAlong(double gamma, const Vec3& e, const Vec3& va, const Vec3& vb) {
    return -gamma * (va - vb).dot(e) * e;
}

}  // namespace trbc::kernels
