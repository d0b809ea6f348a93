#pragma once
// Free-space Stokes kernels: small pure functions of one separation vector (Mirheo style). The
// loops over targets and quadrature points that call them live in boundary_integral.cpp.
//
// Conventions (Pozrikidis 1992, "Boundary Integral and Singularity Methods for Linearized
// Viscous Flow", ch. 2): separation d = x - x0 from the target (pole) x0 to the integration
// point x, r = |d|.
//   Stokeslet       G_ij(d)  = delta_ij / r + d_i d_j / r^3,
//                   u_j(x0) = 1/(8 pi mu) G_ij(x - x0) g_i for a point force g at x (symmetric).
//   Stress tensor   T_ijk(d) = -6 d_i d_j d_k / r^5.
//   Double-layer kernel contracted with the normal n(x):
//                   K_ij(d, n) = T_ijk(d) n_k = -6 d_i d_j (d . n) / r^5   (symmetric in i, j).
// Integral identities on a closed surface D with outward normal n (ch. 2, derived from the
// divergence theorem, checked in tests/flow/test_boundary_integral.cpp):
//   int_D K_ij(x - x0, n(x)) dS(x) = -8 pi delta_ij (x0 inside), -4 pi delta_ij (x0 on D, principal
//   value, smooth D), 0 (x0 outside);   int_D G_ij(x - x0) n_j(x) dS(x) = 0 for every x0.
#include <Eigen/Core>
#include <cmath>

namespace trbc::stokes {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

/// Stokeslet G(d) = I / r + d d^T / r^3.
inline Mat3 stokeslet(const Vec3& d) {
    const double r = d.norm();
    return Mat3::Identity() / r + d * d.transpose() / (r * r * r);
}

/// Stress tensor of the Stokeslet contracted with a vector n in its last index:
/// K(d, n)_ij = T_ijk(d) n_k = -6 d_i d_j (d . n) / r^5.
inline Mat3 stressletNormal(const Vec3& d, const Vec3& n) {
    const double r2 = d.squaredNorm();
    const double r5 = r2 * r2 * std::sqrt(r2);
    return (-6.0 * d.dot(n) / r5) * (d * d.transpose());
}

/// The full stress tensor component T_ijk(d) = -6 d_i d_j d_k / r^5.
inline double stresslet(const Vec3& d, int i, int j, int k) {
    const double r2 = d.squaredNorm();
    return -6.0 * d[i] * d[j] * d[k] / (r2 * r2 * std::sqrt(r2));
}

// ---- Scalar forms for the vectorised loops (plain T = double or float; rinv = 1/r supplied by
// the caller, who batches the square roots).

/// u += w G(d) g = w (g / r + d (d . g) / r^3).
template <class T>
inline void addStokeslet(T dx, T dy, T dz, T rinv, T w, T gx, T gy, T gz, T& ux, T& uy, T& uz) {
    const T a = w * rinv;
    const T b = a * rinv * rinv * (dx * gx + dy * gy + dz * gz);
    ux += a * gx + b * dx;
    uy += a * gy + b * dy;
    uz += a * gz + b * dz;
}

/// Coefficient c of the double-layer kernel w K(d, n) = c d d^T with the weighted normal
/// wn = w n: c = -6 (d . wn) / r^5.
template <class T>
inline T doubleLayerCoefficient(T dx, T dy, T dz, T rinv, T wnx, T wny, T wnz) {
    const T r2inv = rinv * rinv;
    return T(-6) * (dx * wnx + dy * wny + dz * wnz) * r2inv * r2inv * rinv;
}

}  // namespace trbc::stokes
