#pragma once
// The far rule's points and densities as the fused far sums (flow/far_sum.hpp) read them, and the
// two-target far sum compiled for AVX2 + FMA (far_sum_avx2.cpp), which the operators call when the
// CPU offers it (core/simd.hpp). Kept apart from far_sum.hpp because far_sum_avx2.cpp includes
// this header for the build's baseline and far_sum.hpp for AVX2.
#include <Eigen/Core>

#include "flow/stokes_kernels.hpp"

namespace trbc::bie {

/// The far-rule points and a density on them (structure of arrays), in T = double or float.
template <class T>
struct FarPoints {
    const T *x, *y, *z, *w, *wnx, *wny, *wnz;  ///< position, weight, weighted normal
    Eigen::Index n;
};
template <class T>
struct PointDensity {
    const T *x, *y, *z;
};

#if defined(__x86_64__) && defined(__GNUC__)
#define TRBC_FAR_SUM_AVX2_DISPATCH 1
/// farSumTwoTargets (flow/far_sum.hpp) compiled for AVX2 + FMA, whatever the build's baseline:
/// call only when simd::active() is simd::Path::avx2. Instantiated for (single, double) layers
/// (true, false), (false, true) and (true, true).
template <bool kSingle, bool kDouble>
void farSumTwoTargetsAvx2(const float (&x0)[2][3], const FarPoints<float>& p, const PointDensity<float>& wg,
                          const PointDensity<float>& u, const float (&u0)[2][3], stokes::Vec3 (&s)[2], stokes::Vec3 (&v)[2]);
#endif

}  // namespace trbc::bie
