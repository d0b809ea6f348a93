// AVX2 + FMA forward kernels of the networks (surrogate/mlp_avx2.hpp). No Eigen here: this file is
// compiled under `#pragma GCC target("avx2,fma")` and must not emit a weak copy of any inline
// function that baseline code could end up calling; its own functions have internal linkage or are
// the two entry points. The register tiling and the tanh are those of surrogate/mlp.cpp.
#include "surrogate/mlp_avx2.hpp"

#include <immintrin.h>

#include <algorithm>

#if defined(TRBC_MLP_AVX2_DISPATCH)
#pragma GCC push_options
#pragma GCC target("avx2,fma")

namespace trbc::mlp_avx2 {
namespace {

constexpr int kLanes = 4;
constexpr int kTileRows = 4;
constexpr int kTilePackets = 3;
static_assert(kTileSamples == std::int64_t(kTilePackets) * kLanes, "a tile is kTilePackets packets");

/// 2^k for integer-valued k in [-1022, 1023] (the exponent field of 1.5 2^52 + k + 1023).
inline __m256d exp2Integer(__m256d k) {
    constexpr double kShift = 0x1.8p52 + 1023.0;
    return _mm256_castsi256_pd(_mm256_slli_epi64(_mm256_castpd_si256(_mm256_add_pd(k, _mm256_set1_pd(kShift))), 52));
}

/// tanh of four doubles: surrogate/mlp.cpp, tanhPacket.
inline __m256d tanh4(__m256d x) {
    const __m256d signMask = _mm256_set1_pd(-0.0);
    const __m256d a = _mm256_andnot_pd(signMask, x);
    // min(20, a) returns a when a is NaN: NaN propagates.
    const __m256d u = _mm256_mul_pd(_mm256_set1_pd(2.0), _mm256_min_pd(_mm256_set1_pd(20.0), a));
    const __m256d k = _mm256_round_pd(_mm256_mul_pd(u, _mm256_set1_pd(1.4426950408889634)), _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    const __m256d minusK = _mm256_xor_pd(k, signMask);
    __m256d r = _mm256_fmadd_pd(minusK, _mm256_set1_pd(0x1.62e42fee00000p-1), u);
    r = _mm256_fmadd_pd(minusK, _mm256_set1_pd(0x1.a39ef35793c76p-33), r);
    __m256d e = _mm256_set1_pd(1.0 / 6227020800.0);
    for (const double c : {1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0, 1.0 / 40320.0,
                           1.0 / 5040.0, 1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5})
        e = _mm256_fmadd_pd(e, r, _mm256_set1_pd(c));
    const __m256d p = _mm256_fmadd_pd(_mm256_mul_pd(r, r), e, r);
    const __m256d twoK = exp2Integer(k);
    const __m256d m = _mm256_fmadd_pd(twoK, p, _mm256_sub_pd(twoK, _mm256_set1_pd(1.0)));
    return _mm256_or_pd(_mm256_div_pd(m, _mm256_add_pd(m, _mm256_set1_pd(2.0))), _mm256_and_pd(x, signMask));
}

template <int R>
void affineRows(const double* W, const double* b, std::int64_t nOut, std::int64_t nIn, const double* A, double* Z,
                std::int64_t i0, std::int64_t block) {
    for (std::int64_t j = 0; j < block; j += kTileSamples) {
        __m256d acc[R][kTilePackets];
        for (int r = 0; r < R; ++r)
            for (int c = 0; c < kTilePackets; ++c) acc[r][c] = _mm256_set1_pd(b[i0 + r]);
        for (std::int64_t k = 0; k < nIn; ++k) {
            const double* a = A + k * block + j;
            __m256d in[kTilePackets];
            for (int c = 0; c < kTilePackets; ++c) in[c] = _mm256_loadu_pd(a + c * kLanes);
            const double* w = W + k * nOut + i0;
            for (int r = 0; r < R; ++r) {
                const __m256d wr = _mm256_set1_pd(w[r]);
                for (int c = 0; c < kTilePackets; ++c) acc[r][c] = _mm256_fmadd_pd(wr, in[c], acc[r][c]);
            }
        }
        for (int r = 0; r < R; ++r)
            for (int c = 0; c < kTilePackets; ++c) _mm256_storeu_pd(Z + (i0 + r) * block + j + c * kLanes, acc[r][c]);
    }
}

}  // namespace

void tanhInPlace(double* x, std::int64_t n) {
    std::int64_t i = 0;
    for (; i + kLanes <= n; i += kLanes) _mm256_storeu_pd(x + i, tanh4(_mm256_loadu_pd(x + i)));
    if (i < n) {  // padded: every element goes through the same packet code
        alignas(32) double tail[kLanes] = {};
        std::copy(x + i, x + n, tail);
        _mm256_store_pd(tail, tanh4(_mm256_load_pd(tail)));
        std::copy(tail, tail + (n - i), x + i);
    }
}

void affineBlock(const double* W, const double* b, std::int64_t nOut, std::int64_t nIn, const double* A, double* Z,
                 bool hidden, std::int64_t block) {
    std::int64_t i = 0;
    for (; i + kTileRows <= nOut; i += kTileRows) affineRows<kTileRows>(W, b, nOut, nIn, A, Z, i, block);
    switch (nOut - i) {
        case 3: affineRows<3>(W, b, nOut, nIn, A, Z, i, block); break;
        case 2: affineRows<2>(W, b, nOut, nIn, A, Z, i, block); break;
        case 1: affineRows<1>(W, b, nOut, nIn, A, Z, i, block); break;
        default: break;
    }
    if (hidden) tanhInPlace(Z, nOut * block);
}

}  // namespace trbc::mlp_avx2

#pragma GCC pop_options
#endif
