#pragma once
// Branch-free exp and log in double precision for loops that the compiler vectorises
// (`#pragma omp simd`): glibc's exp/log are opaque calls that keep such loops scalar. Used by the
// population sums of the hierarchical inference (docs/BAYESIAN_INFERENCE.md), which evaluate ~1e11 terms.
//
// fastExp: x = n ln2 + r, |r| <= ln2/2 (Cody-Waite with a two-part ln2), e^r by its degree-12
// Taylor polynomial (truncation 2e-16), times 2^n built in the exponent bits. Arguments are clamped
// below at -708: e^-708 = 3e-308 stays a normal number (subnormals are slow on x86), so terms
// below that are not exactly zero but ~1e-308 — irrelevant next to any term that matters. Valid for
// x <= 709 (callers pass x <= 0).
// fastLog (x > 0, finite, normal): x = 2^e f with f in [sqrt(1/2), sqrt 2), log f = 2 atanh(s),
// s = (f - 1)/(f + 1), |s| < 0.172, by its odd series to s^23.
// fastRsqrt: see below. All agree with glibc to a few ulp (tests/inference/test_rbc_pipeline.cpp).
#include <bit>
#include <cstdint>

namespace trbc::detail {
namespace {  // internal linkage (see population_kernels.hpp)

[[gnu::always_inline]] inline double fastExp(double x) {
    constexpr double kLog2e = 1.4426950408889634074;
    constexpr double kLn2Hi = 6.93147180369123816490e-01, kLn2Lo = 1.90821492927058770002e-10;
    constexpr double kShift = 6755399441055744.0;  // 1.5 * 2^52: adding it rounds to an integer
    x = x < -708.0 ? -708.0 : x;  // (one select per value: chains of selects keep GCC from vectorising)
    const double t = x * kLog2e + kShift;
    const double n = t - kShift;  // round(x / ln2)
    const double r = (x - n * kLn2Hi) - n * kLn2Lo;
    double p = 1.0 / 479001600.0;  // 1/12!
    p = p * r + 1.0 / 39916800.0;
    p = p * r + 1.0 / 3628800.0;
    p = p * r + 1.0 / 362880.0;
    p = p * r + 1.0 / 40320.0;
    p = p * r + 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    const std::int64_t k = std::bit_cast<std::int64_t>(t) - std::bit_cast<std::int64_t>(kShift);  // n as integer
    return p * std::bit_cast<double>((k + 1023) << 52);
}

[[gnu::always_inline]] inline double fastLog(double x) {
    constexpr double kLn2Hi = 6.93147180369123816490e-01, kLn2Lo = 1.90821492927058770002e-10;
    constexpr double kSqrt2 = 1.41421356237309504880;
    const std::uint64_t bits = std::bit_cast<std::uint64_t>(x);
    // exponent as a double without an int -> double conversion: (2^52 + e_biased) - 2^52
    const double eBiased = std::bit_cast<double>((bits >> 52) | 0x4330000000000000ULL) - 4503599627370496.0;
    double f = std::bit_cast<double>((bits & 0x000FFFFFFFFFFFFFULL) | 0x3FF0000000000000ULL);  // [1, 2)
    const double big = f > kSqrt2 ? 1.0 : 0.0;  // f in [sqrt 2, 2): halve it, exponent + 1
    f *= 1.0 - 0.5 * big;
    const double e = eBiased - 1023.0 + big;
    const double s = (f - 1.0) / (f + 1.0), s2 = s * s;
    double p = 1.0 / 23.0;
    p = p * s2 + 1.0 / 21.0;
    p = p * s2 + 1.0 / 19.0;
    p = p * s2 + 1.0 / 17.0;
    p = p * s2 + 1.0 / 15.0;
    p = p * s2 + 1.0 / 13.0;
    p = p * s2 + 1.0 / 11.0;
    p = p * s2 + 1.0 / 9.0;
    p = p * s2 + 1.0 / 7.0;
    p = p * s2 + 1.0 / 5.0;
    p = p * s2 + 1.0 / 3.0;
    const double logF = 2.0 * s + 2.0 * s * s2 * p;
    return e * kLn2Hi + (logF + e * kLn2Lo);
}

/// 1/sqrt(x) for x > 0 (finite, normal): bit-level first guess (relative error < 3.5 %) and four
/// Newton steps y <- y (3/2 - x y^2 / 2) (error 3.5e-2 -> 1.8e-3 -> 4.7e-6 -> 3.3e-11 -> round-off).
/// std::sqrt cannot be used in vectorised loops: it sets errno for negative arguments.
[[gnu::always_inline]] inline double fastRsqrt(double x) {
    double y = std::bit_cast<double>(0x5FE6EB50C7B537A9ULL - (std::bit_cast<std::uint64_t>(x) >> 1));
    const double h = 0.5 * x;
    y = y * (1.5 - h * y * y);
    y = y * (1.5 - h * y * y);
    y = y * (1.5 - h * y * y);
    y = y * (1.5 - h * y * y);
    return y;
}

/// Single-precision exp for x <= 88 (clamped below at -87; relative error ~1e-7): same scheme as
/// fastExp with a degree-7 polynomial.
[[gnu::always_inline]] inline float fastExpF(float x) {
    constexpr float kShift = 12582912.0f;  // 1.5 * 2^23
    x = x < -87.0f ? -87.0f : x;
    const float t = x * 1.44269504f + kShift;
    const float n = t - kShift;
    const float r = (x - n * 0.693359375f) - n * -2.12194440e-4f;  // ln 2 = 0.693359375 - 2.12194440e-4
    float p = 1.0f / 5040.0f;
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    const std::int32_t k = std::bit_cast<std::int32_t>(t) - std::bit_cast<std::int32_t>(kShift);
    return p * std::bit_cast<float>((k + 127) << 23);
}

/// Single-precision log for x > 0 (finite, normal; relative error ~1e-7), as fastLog.
[[gnu::always_inline]] inline float fastLogF(float x) {
    const std::uint32_t bits = std::bit_cast<std::uint32_t>(x);
    const float eBiased = std::bit_cast<float>((bits >> 23) | 0x4B000000u) - 8388608.0f;
    float f = std::bit_cast<float>((bits & 0x007FFFFFu) | 0x3F800000u);
    const float big = f > 1.41421356f ? 1.0f : 0.0f;
    f *= 1.0f - 0.5f * big;
    const float e = eBiased - 127.0f + big;
    const float s = (f - 1.0f) / (f + 1.0f), s2 = s * s;
    float p = 1.0f / 9.0f;
    p = p * s2 + 1.0f / 7.0f;
    p = p * s2 + 1.0f / 5.0f;
    p = p * s2 + 1.0f / 3.0f;
    return e * 0.693147181f + (2.0f * s + 2.0f * s * s2 * p);
}

}  // namespace
}  // namespace trbc::detail
