#pragma once
// The double-precision forward kernels of the networks (surrogate/mlp.cpp) compiled for AVX2 + FMA
// whatever the build's baseline, chosen at run time when the CPU offers them (core/simd.hpp). The
// same arithmetic as the portable kernels, four samples per packet.
#include <cstdint>

namespace trbc::mlp_avx2 {

#if defined(__x86_64__) && defined(__GNUC__)
#define TRBC_MLP_AVX2_DISPATCH 1
/// Samples per register tile of affineBlock (3 packets of 4): a block's width is a multiple of it.
inline constexpr std::int64_t kTileSamples = 12;
/// tanh of x[0..n) in place (the branch-free formula of surrogate/mlp.cpp).
void tanhInPlace(double* x, std::int64_t n);
/// Z = W A + b on one feature-major block of `block` samples (a multiple of kTileSamples), then tanh in place
/// if `hidden`: W column-major nOut x nIn, A nIn x block, Z nOut x block.
void affineBlock(const double* W, const double* b, std::int64_t nOut, std::int64_t nIn, const double* A, double* Z,
                 bool hidden, std::int64_t block);
#endif

}  // namespace trbc::mlp_avx2
