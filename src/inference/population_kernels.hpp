#pragma once
// Internal building blocks of the population sums (docs/BAYESIAN_INFERENCE.md): the scaled normal tail,
// the closed form of q(FvK | psi) as a branch-free inline function, and the fused log-sum-exp
// loops. Everything here vectorises under `#pragma omp simd` (no library calls; exp and log from
// vector_math.hpp). Only population.cpp and hierarchical.cpp include this.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "inference/vector_math.hpp"

namespace trbc::detail {
// Internal linkage: every including file (all compiled with no-trapping-math) gets its own copy, so
// the linker never picks a copy compiled without vectorisation.
namespace {

/// Chebyshev coefficients of h(t) = erfcx(z) / t, z = 2/t - 2, in u = 2t - 1 on [0, 1] (c_0 already
/// halved). Computed with mpmath (40 digits) from 80 Chebyshev nodes; the first 25 leave a
/// truncation error below 3e-16 (|c_24| = 2.3e-16 and the coefficients decay geometrically).
constexpr int kErfcxTerms = 25;
constexpr double kErfcxCheb[kErfcxTerms] = {
    0.57703373861646968862,     0.355436921270498487306,    0.0650951588287865245502,   0.00367114239583663916592,
    -0.00111284474335263249691, -0.00016075829915378079758, 0.0000327803157417313706047, 0.00000544244164550501603325,
    -0.00000151546655531714816222, -1.42976081811698649168e-7, 8.23460882741949343302e-8, -1.2962846852306562536e-9,
    -4.15472163101519830419e-9, 6.34705827836281118136e-10, 1.43208227122562237069e-10, -6.16039010520458554175e-11,
    2.06121385547216963059e-12, 3.57149314884770444503e-12, -8.58642284325179647566e-13, -6.14560021379063055398e-14,
    7.41872574859661705732e-14, -1.28950427550323256153e-14, -2.35872638571063235675e-15, 1.57293493816859113966e-15,
    -2.27829662395464651728e-16};

/// Q(x) e^{x^2/2} for x >= 0 (Q = 1 - Phi): Q(x) = erfc(x/sqrt 2)/2 = (t/2) h(t) e^{-x^2/2},
/// t = 2 / (2 + x/sqrt 2); h by Clenshaw's recurrence (unrolled: no branches, no calls).
[[gnu::always_inline]] inline double scaledNormalTail(double x) {
    const double t = 2.0 / (2.0 + x * (1.0 / std::numbers::sqrt2));
    const double u2 = 2.0 * (2.0 * t - 1.0);
    double b1 = 0.0, b2 = 0.0;
#pragma GCC unroll 32
    for (int j = kErfcxTerms - 1; j >= 1; --j) {
        const double b0 = kErfcxCheb[j] + u2 * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    return 0.5 * t * (kErfcxCheb[0] + 0.5 * u2 * b1 - b2);
}

constexpr double kInvSqrt2Pi = 0.3989422804014326779399;  // 1 / sqrt(2 pi)
constexpr double kHalfLog2Pi = 0.91893853320467274178;     // log(2 pi) / 2
/// Exponents below this are clamped before exp: e^-300 = 5e-131 is negligible next to every other
/// term it is combined with (relative 1e-100 and less), and no subnormal number appears.
constexpr double kExpFloor = -300.0;

/// Parameters of q in the form the loops need: X ~ N(muX, vx), Y ~ TN(muY, vy, [0.01, 0.1]),
/// ivx = 1/vx, ivy = 1/vy, logC = log(sqrt(2 pi) sdX sdY Zy).
struct FvkCoefficients {
    double muX, vx, ivx, muY, vy, ivy, logC;
};
constexpr double kFvkYLow = 0.01, kFvkYHigh = 0.1;  // [a_y, b_y] = kb / R_A^2 range

/// log q(z) by the closed form of 4.3,
///   q = exp(-(muX - z muY)^2 / (2 (vx + z^2 vy))) s B / (sqrt(2 pi) sdX sdY Zy),
///   P = z^2/vx + 1/vy, s = P^-1/2, m = (z muX/vx + muY/vy)/P, alpha = (a-m)/s, beta = (b-m)/s,
///   B = m (Phi(beta) - Phi(alpha)) + s (phi(alpha) - phi(beta)),
/// with B in one of three forms chosen so that nothing underflows (g = Q(|x|) e^{x^2/2},
/// la = -alpha^2/2, lb = -beta^2/2):
///   alpha >= 0:  B = e^{la} [m (g_a - g_b r) + s (1 - r)/sqrt(2 pi)],  r = e^{lb - la};
///   beta <= 0:   B = e^{lb} [m (g_b - g_a r) - s (1 - r)/sqrt(2 pi)],  r = e^{la - lb};
///   otherwise:   B = m (1 - g_a e^{la} - g_b e^{lb}) + s (e^{la} - e^{lb})/sqrt(2 pi).
/// Branch-free (all cases computed, one selected). z > 0.
[[gnu::always_inline]] inline double logFvkDensityCore(double z, const FvkCoefficients& c) {
    const double P = z * z * c.ivx + c.ivy;
    const double s = fastRsqrt(P), root = P * s;
    const double m = (z * c.muX * c.ivx + c.muY * c.ivy) * (s * s);
    const double alpha = (kFvkYLow - m) * root, beta = (kFvkYHigh - m) * root;
    const double la = -0.5 * alpha * alpha, lb = -0.5 * beta * beta;
    const double hiL = la > lb ? la : lb, loL = la > lb ? lb : la;
    const double r = fastExp(std::max(loL - hiL, kExpFloor));
    const double emax = fastExp(std::max(hiL, kExpFloor));
    const double ga = scaledNormalTail(std::abs(alpha)), gb = scaledNormalTail(std::abs(beta));
    const double innerA = m * (ga - gb * r) + s * (1.0 - r) * kInvSqrt2Pi;
    const double innerB = m * (gb - ga * r) - s * (1.0 - r) * kInvSqrt2Pi;
    const double ea = la >= lb ? emax : emax * r, eb = la >= lb ? emax * r : emax;
    const double innerM = m * (1.0 - ga * ea - gb * eb) + s * (ea - eb) * kInvSqrt2Pi;
    const bool caseA = alpha >= 0.0, caseB = beta <= 0.0;
    const double inner = caseA ? innerA : caseB ? innerB : innerM;
    const double L0 = caseA ? la : caseB ? lb : 0.0;
    const double e = c.muX - z * c.muY;
    const double E = e * e / (2.0 * (c.vx + z * z * c.vy));
    return L0 + fastLog(std::max(s * inner, 1e-300)) - E - c.logC;
}

/// The same in mixed precision (docs/BAYESIAN_INFERENCE.md cost): P, s, m, alpha, beta, the exponents and E in
/// double (they carry the cancellations), the normal tails (13 Chebyshev terms, truncation 6e-10),
/// the two exponentials, the bracket and its log in float. |difference| to logFvkDensityCore below
/// 1e-5 wherever log q is within 40 of its maximum (tests); about twice as fast.
[[gnu::always_inline]] inline float scaledNormalTailF(float x) {
    const float t = 2.0f / (2.0f + x * 0.707106781f);
    const float u2 = 2.0f * (2.0f * t - 1.0f);
    float b1 = 0.0f, b2 = 0.0f;
#pragma GCC unroll 16
    for (int j = 13; j >= 1; --j) {
        const float b0 = static_cast<float>(kErfcxCheb[j]) + u2 * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    return 0.5f * t * (static_cast<float>(kErfcxCheb[0]) + 0.5f * u2 * b1 - b2);
}

[[gnu::always_inline]] inline double logFvkDensityCoreMixed(double z, const FvkCoefficients& c) {
    const double P = z * z * c.ivx + c.ivy;
    const double s = fastRsqrt(P), root = P * s;
    const double m = (z * c.muX * c.ivx + c.muY * c.ivy) * (s * s);
    const double alpha = (kFvkYLow - m) * root, beta = (kFvkYHigh - m) * root;
    const double la = -0.5 * alpha * alpha, lb = -0.5 * beta * beta;
    const double hiL = la > lb ? la : lb, loL = la > lb ? lb : la;
    // e^-80 = 2e-35: still a normal float, negligible next to every term it is combined with
    const float r = fastExpF(static_cast<float>(std::max(loL - hiL, -80.0)));
    const float emax = fastExpF(static_cast<float>(std::max(hiL, -80.0)));
    const float ga = scaledNormalTailF(static_cast<float>(std::abs(alpha))), gb = scaledNormalTailF(static_cast<float>(std::abs(beta)));
    const float mf = static_cast<float>(m), sf = static_cast<float>(s), c0 = static_cast<float>(kInvSqrt2Pi);
    const float innerA = mf * (ga - gb * r) + sf * (1.0f - r) * c0;
    const float innerB = mf * (gb - ga * r) - sf * (1.0f - r) * c0;
    const float ea = la >= lb ? emax : emax * r, eb = la >= lb ? emax * r : emax;
    const float innerM = mf * (1.0f - ga * ea - gb * eb) + sf * (ea - eb) * c0;
    const bool caseA = alpha >= 0.0, caseB = beta <= 0.0;
    const float inner = caseA ? innerA : caseB ? innerB : innerM;
    const double L0 = caseA ? la : caseB ? lb : 0.0;
    const double e = c.muX - z * c.muY;
    const double E = e * e / (2.0 * (c.vx + z * z * c.vy));
    return L0 + static_cast<double>(fastLogF(std::max(sf * inner, 1e-37f))) - E - c.logC;
}

/// The coefficients from (muX, sdX, muY, sdY, logZy).
inline FvkCoefficients fvkCoefficients(double muX, double sdX, double muY, double sdY, double logZy) {
    const double vx = sdX * sdX, vy = sdY * sdY;
    return {muX, vx, 1.0 / vx, muY, vy, 1.0 / vy, kHalfLog2Pi + std::log(sdX) + std::log(sdY) + logZy};
}

/// log sum_k exp(L_k) of a buffer by max shift; -inf when every term is zero or a value is
/// not finite. Two vectorised passes in a fixed order (the result does not depend on threads).
inline double logSumExp(const double* L, Eigen::Index n) {
    double mx = -std::numeric_limits<double>::infinity();
#pragma omp simd reduction(max : mx)
    for (Eigen::Index k = 0; k < n; ++k) mx = std::max(mx, L[k]);
    if (!(mx > -std::numeric_limits<double>::infinity()) || !std::isfinite(mx)) return -std::numeric_limits<double>::infinity();
    double sum = 0.0;
#pragma omp simd reduction(+ : sum)
    for (Eigen::Index k = 0; k < n; ++k) sum += fastExp(L[k] - mx);
    const double r = mx + std::log(sum);
    return std::isfinite(r) ? r : -std::numeric_limits<double>::infinity();
}

}  // namespace
}  // namespace trbc::detail
