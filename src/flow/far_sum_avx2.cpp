// The two-target far sum for AVX2 + FMA in a build whose baseline lacks them (core/simd.hpp): the
// headers above the pragma keep the baseline, so no inline function of Eigen or the standard library
// is emitted here for AVX2 and merged by the linker into baseline code; far_sum.hpp below it has
// internal linkage throughout.
#include <immintrin.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>

#include "flow/far_points.hpp"
#include "flow/stokes_kernels.hpp"

#if defined(TRBC_FAR_SUM_AVX2_DISPATCH)
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#define TRBC_FAR_SUM_AVX2_TU 1
#include "flow/far_sum.hpp"

namespace trbc::bie {

template <bool kSingle, bool kDouble>
void farSumTwoTargetsAvx2(const float (&x0)[2][3], const FarPoints<float>& p, const PointDensity<float>& wg,
                          const PointDensity<float>& u, const float (&u0)[2][3], stokes::Vec3 (&s)[2], stokes::Vec3 (&v)[2]) {
    farSumTwoTargets<kSingle, kDouble>(x0, p, wg, u, u0, s, v);
}

template void farSumTwoTargetsAvx2<true, false>(const float (&)[2][3], const FarPoints<float>&, const PointDensity<float>&,
                                                const PointDensity<float>&, const float (&)[2][3], stokes::Vec3 (&)[2],
                                                stokes::Vec3 (&)[2]);
template void farSumTwoTargetsAvx2<false, true>(const float (&)[2][3], const FarPoints<float>&, const PointDensity<float>&,
                                                const PointDensity<float>&, const float (&)[2][3], stokes::Vec3 (&)[2],
                                                stokes::Vec3 (&)[2]);
template void farSumTwoTargetsAvx2<true, true>(const float (&)[2][3], const FarPoints<float>&, const PointDensity<float>&,
                                               const PointDensity<float>&, const float (&)[2][3], stokes::Vec3 (&)[2],
                                               stokes::Vec3 (&)[2]);

}  // namespace trbc::bie

#pragma GCC pop_options
#endif
