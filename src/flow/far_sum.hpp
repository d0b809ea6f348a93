#pragma once
// The fused far-field kernels of the boundary-integral operators (flow/boundary_integral.hpp):
// elementwise 1 / sqrt for the kernels' 1 / r, and the single- and double-layer sums of the far
// rule at one target (farSum) or at two targets at once (farSumTwoTargets, AVX2 + FMA). Header
// templates because the operators instantiate them for double and float and for either layer or
// both; shared by the operators' files only. Every function here has internal linkage (static):
// far_sum_avx2.cpp compiles this header for AVX2 + FMA, the other files for the build's baseline,
// and the linker must never merge the two (core/simd.hpp).
#include <immintrin.h>

#include <Eigen/Core>
#include <cmath>
#include <limits>

#include "flow/far_points.hpp"
#include "flow/stokes_kernels.hpp"

// The AVX2 + FMA code: where the baseline has it, or in far_sum_avx2.cpp, which compiles this
// header under `#pragma GCC target("avx2,fma")` (the pragma does not set __AVX2__ in C++).
#if (defined(__AVX2__) && defined(__FMA__)) || defined(TRBC_FAR_SUM_AVX2_TU)
#define TRBC_FAR_SUM_HAS_AVX2 1
#endif

namespace trbc::bie {

using Eigen::Index;
using stokes::Vec3;

// Points per block of the far loops: 1 / r of a block is computed in one pass (inverseSqrt), the
// kernels in a second; both stay in L1.
constexpr int kBlock = 256;

/// r <- 1 / sqrt(r) elementwise, 0 where r = 0 (a point at the target, left out of the far sums).
/// With AVX2 + FMA: the single-precision estimate (relative error < 1.5 2^-12) and three Newton
/// steps y <- y (3 - r y^2) / 2 in double precision (the error squares at each: 4e-4, 2e-7,
/// 6e-14, then rounding), a few ulp from the correctly rounded value; a fused far pass costs 0.88x
/// of one with packet square root and division (bench_stokes, level 3). Lanes outside the float
/// range take the exact formula.
static inline void inverseSqrt(double* r, Index n) {
    Index k = 0;
#if defined(TRBC_FAR_SUM_HAS_AVX2)
    const __m256d half = _mm256_set1_pd(0.5), three = _mm256_set1_pd(3.0);
    const __m256d lo = _mm256_set1_pd(static_cast<double>(std::numeric_limits<float>::min()));
    const __m256d hi = _mm256_set1_pd(static_cast<double>(std::numeric_limits<float>::max()));
    for (; k + 4 <= n; k += 4) {
        const __m256d x = _mm256_loadu_pd(r + k);
        const __m256d inRange = _mm256_and_pd(_mm256_cmp_pd(x, lo, _CMP_GE_OQ), _mm256_cmp_pd(x, hi, _CMP_LE_OQ));
        if (_mm256_movemask_pd(inRange) != 0xF) {
            for (Index j = k; j < k + 4; ++j) r[j] = r[j] > 0.0 ? 1.0 / std::sqrt(r[j]) : 0.0;
            continue;
        }
        __m256d y = _mm256_cvtps_pd(_mm_rsqrt_ps(_mm256_cvtpd_ps(x)));
        for (int it = 0; it < 3; ++it) {
            const __m256d xy2 = _mm256_mul_pd(_mm256_mul_pd(x, y), y);
            y = _mm256_mul_pd(_mm256_mul_pd(half, y), _mm256_sub_pd(three, xy2));
        }
        _mm256_storeu_pd(r + k, y);
    }
#endif
    for (; k < n; ++k) r[k] = r[k] > 0.0 ? 1.0 / std::sqrt(r[k]) : 0.0;
}

#if defined(TRBC_FAR_SUM_HAS_AVX2)
/// 1 / sqrt(x) for eight floats: the estimate and one Newton step y (3 - x y^2) / 2 (relative
/// error ~2e-7, the float rounding); lanes outside the normal float range take the exact formula,
/// 0 where x = 0.
static inline __m256 inverseSqrt8(__m256 x) {
    const __m256 lo = _mm256_set1_ps(std::numeric_limits<float>::min());
    const __m256 hi = _mm256_set1_ps(std::numeric_limits<float>::max());
    const __m256 inRange = _mm256_and_ps(_mm256_cmp_ps(x, lo, _CMP_GE_OQ), _mm256_cmp_ps(x, hi, _CMP_LE_OQ));
    if (_mm256_movemask_ps(inRange) != 0xFF) {
        alignas(32) float r[8];
        _mm256_store_ps(r, x);
        for (float& v : r) v = v > 0.0f ? 1.0f / std::sqrt(v) : 0.0f;
        return _mm256_load_ps(r);
    }
    const __m256 y = _mm256_rsqrt_ps(x);
    const __m256 xy2 = _mm256_mul_ps(_mm256_mul_ps(x, y), y);
    return _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(0.5f), y), _mm256_sub_ps(_mm256_set1_ps(3.0f), xy2));
}
#endif

/// The same in single precision (inverseSqrt8 with AVX2 + FMA).
static inline void inverseSqrt(float* r, Index n) {
    Index k = 0;
#if defined(TRBC_FAR_SUM_HAS_AVX2)
    for (; k + 8 <= n; k += 8) _mm256_storeu_ps(r + k, inverseSqrt8(_mm256_loadu_ps(r + k)));
#endif
    for (; k < n; ++k) r[k] = r[k] > 0.0f ? 1.0f / std::sqrt(r[k]) : 0.0f;
}

/// Far parts at the target x0, in one pass over the points:
///   single layer  s = sum_q w_q G(y_q - x0) g_q,
///   double layer  v = sum_q w_q K(y_q - x0, n_q) (u_q - u0)   (singularity subtracted),
/// either or both (template flags). A point at x0 contributes nothing (1/r set to 0). Each block
/// of kBlock points is summed in T, the block sums in double.
template <class T, bool kSingle, bool kDouble>
static void farSum(const T (&x0)[3], const FarPoints<T>& p, const PointDensity<T>& g, const PointDensity<T>& u,
            const T (&u0)[3], Vec3& s, Vec3& v) {
    alignas(64) T dx[kBlock], dy[kBlock], dz[kBlock], rinv[kBlock];
    const T* __restrict px = p.x;
    const T* __restrict py = p.y;
    const T* __restrict pz = p.z;
    const T* __restrict pw = p.w;
    const T* __restrict nx = p.wnx;
    const T* __restrict ny = p.wny;
    const T* __restrict nz = p.wnz;
    const T* __restrict gx = g.x;
    const T* __restrict gy = g.y;
    const T* __restrict gz = g.z;
    const T* __restrict ux = u.x;
    const T* __restrict uy = u.y;
    const T* __restrict uz = u.z;
    const T x00 = x0[0], x01 = x0[1], x02 = x0[2], u00 = u0[0], u01 = u0[1], u02 = u0[2];
    s.setZero();
    v.setZero();
    for (Index b0 = 0; b0 < p.n; b0 += kBlock) {
        const int m = static_cast<int>(std::min<Index>(kBlock, p.n - b0));
#pragma omp simd
        for (int k = 0; k < m; ++k) {
            dx[k] = px[b0 + k] - x00;
            dy[k] = py[b0 + k] - x01;
            dz[k] = pz[b0 + k] - x02;
            rinv[k] = dx[k] * dx[k] + dy[k] * dy[k] + dz[k] * dz[k];
        }
        inverseSqrt(rinv, m);
        T sx = 0, sy = 0, sz = 0, vx = 0, vy = 0, vz = 0;
#pragma omp simd reduction(+ : sx, sy, sz, vx, vy, vz)
        for (int k = 0; k < m; ++k) {
            const Index q = b0 + k;
            if constexpr (kSingle)
                stokes::addStokeslet(dx[k], dy[k], dz[k], rinv[k], pw[q], gx[q], gy[q], gz[q], sx, sy, sz);
            if constexpr (kDouble) {
                const T c = stokes::doubleLayerCoefficient(dx[k], dy[k], dz[k], rinv[k], nx[q], ny[q], nz[q]);
                // K (u_q - u0) = c d (d . (u_q - u0))
                const T du = c * (dx[k] * (ux[q] - u00) + dy[k] * (uy[q] - u01) + dz[k] * (uz[q] - u02));
                vx += du * dx[k];
                vy += du * dy[k];
                vz += du * dz[k];
            }
        }
        s += Vec3(double(sx), double(sy), double(sz));
        v += Vec3(double(vx), double(vy), double(vz));
    }
}

#if defined(TRBC_FAR_SUM_HAS_AVX2)
/// farSum<float> for two targets at once (AVX2 + FMA), with the weighted single-layer density
/// wg_q = w_q g_q: one pass per 8 points, each point's position, normal and densities loaded once
/// for both targets, 1 / r kept in registers (inverseSqrt8), twelve independent accumulators, the
/// double layer's factor -6 applied to the block sums. The multiplies set the pace (about 31 per
/// pair for both layers), so the gain over two farSum calls is modest (docs/PERFORMANCE_FLOW.md,
/// "Flow solver").
template <bool kSingle, bool kDouble>
static void farSumTwoTargets(const float (&x0)[2][3], const FarPoints<float>& p, const PointDensity<float>& wg,
                      const PointDensity<float>& u, const float (&u0)[2][3], Vec3 (&s)[2], Vec3 (&v)[2]) {
    alignas(32) static constexpr int kLanes[16] = {-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0};
    __m256 X[2][3], U[2][3];
    for (int t = 0; t < 2; ++t)
        for (int c = 0; c < 3; ++c) X[t][c] = _mm256_set1_ps(x0[t][c]), U[t][c] = _mm256_set1_ps(u0[t][c]);
    for (int t = 0; t < 2; ++t) s[t].setZero(), v[t].setZero();
    const auto hsum = [](__m256 a) {
        const __m128 q = _mm_add_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1));
        const __m128 d = _mm_add_ps(q, _mm_movehl_ps(q, q));
        return double(_mm_cvtss_f32(_mm_add_ss(d, _mm_movehdup_ps(d))));
    };
    for (Index b0 = 0; b0 < p.n; b0 += kBlock) {
        const Index bend = std::min<Index>(p.n, b0 + kBlock);
        __m256 acc[2][6];
        for (auto& a : acc)
            for (auto& c : a) c = _mm256_setzero_ps();
        for (Index k = b0; k < bend; k += 8) {
            // A partial last chunk reads zeros beyond the end, and its 1 / r is zeroed there (a
            // zero point near the target would overflow r^-5): those lanes add exactly nothing.
            const bool full = bend - k >= 8;
            const __m256i mask = _mm256_loadu_si256(
                reinterpret_cast<const __m256i*>(kLanes + 8 - static_cast<int>(std::min<Index>(8, bend - k))));
            const auto load = [&](const float* a) {
                return full ? _mm256_loadu_ps(a + k) : _mm256_maskload_ps(a + k, mask);
            };
            const __m256 px = load(p.x), py = load(p.y), pz = load(p.z);
            __m256 gx{}, gy{}, gz{}, nx{}, ny{}, nz{}, ux{}, uy{}, uz{};
            if constexpr (kSingle) gx = load(wg.x), gy = load(wg.y), gz = load(wg.z);
            if constexpr (kDouble)
                nx = load(p.wnx), ny = load(p.wny), nz = load(p.wnz), ux = load(u.x), uy = load(u.y), uz = load(u.z);
            for (int t = 0; t < 2; ++t) {
                const __m256 dx = _mm256_sub_ps(px, X[t][0]), dy = _mm256_sub_ps(py, X[t][1]),
                             dz = _mm256_sub_ps(pz, X[t][2]);
                const __m256 r2 = _mm256_fmadd_ps(dz, dz, _mm256_fmadd_ps(dy, dy, _mm256_mul_ps(dx, dx)));
                __m256 rinv = inverseSqrt8(r2);  // 0 for a point at the target
                if (!full) rinv = _mm256_and_ps(rinv, _mm256_castsi256_ps(mask));
                const __m256 r2inv = _mm256_mul_ps(rinv, rinv), r3inv = _mm256_mul_ps(r2inv, rinv);
                if constexpr (kSingle) {  // w G g = (w g) / r + (d . w g) d / r^3
                    const __m256 dg = _mm256_fmadd_ps(dz, gz, _mm256_fmadd_ps(dy, gy, _mm256_mul_ps(dx, gx)));
                    const __m256 b = _mm256_mul_ps(r3inv, dg);
                    acc[t][0] = _mm256_add_ps(acc[t][0], _mm256_fmadd_ps(rinv, gx, _mm256_mul_ps(b, dx)));
                    acc[t][1] = _mm256_add_ps(acc[t][1], _mm256_fmadd_ps(rinv, gy, _mm256_mul_ps(b, dy)));
                    acc[t][2] = _mm256_add_ps(acc[t][2], _mm256_fmadd_ps(rinv, gz, _mm256_mul_ps(b, dz)));
                }
                if constexpr (kDouble) {  // c / -6 = (d . w n) / r^5
                    const __m256 dn = _mm256_fmadd_ps(dz, nz, _mm256_fmadd_ps(dy, ny, _mm256_mul_ps(dx, nx)));
                    const __m256 c = _mm256_mul_ps(dn, _mm256_mul_ps(r3inv, r2inv));
                    const __m256 ddu = _mm256_fmadd_ps(
                        dz, _mm256_sub_ps(uz, U[t][2]),
                        _mm256_fmadd_ps(dy, _mm256_sub_ps(uy, U[t][1]), _mm256_mul_ps(dx, _mm256_sub_ps(ux, U[t][0]))));
                    const __m256 du = _mm256_mul_ps(c, ddu);
                    acc[t][3] = _mm256_fmadd_ps(du, dx, acc[t][3]);
                    acc[t][4] = _mm256_fmadd_ps(du, dy, acc[t][4]);
                    acc[t][5] = _mm256_fmadd_ps(du, dz, acc[t][5]);
                }
            }
        }
        for (int t = 0; t < 2; ++t) {
            if constexpr (kSingle) s[t] += Vec3(hsum(acc[t][0]), hsum(acc[t][1]), hsum(acc[t][2]));
            if constexpr (kDouble) v[t] += -6.0 * Vec3(hsum(acc[t][3]), hsum(acc[t][4]), hsum(acc[t][5]));
        }
    }
}
#endif

}  // namespace trbc::bie
