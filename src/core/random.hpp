#pragma once
// Seeded random numbers of every stochastic part of trbc: `Rng` is xoshiro256** (Blackman & Vigna
// 2018, 32 bytes of state) seeded through splitmix64 from a (seed, stream...) tuple, so that each
// stream is derived deterministically from a user's seed. Normal and uniform variates are generated
// here (not by std:: distributions) so that results do not depend on the standard library either.
#include <cstdint>
#include <limits>

namespace trbc {

/// splitmix64 finaliser: a bijective 64-bit mix, x -> z (used to hash seeds and stream ids).
std::uint64_t splitmix64(std::uint64_t x);

/// xoshiro256** generator; satisfies UniformRandomBitGenerator.
class Rng {
public:
    using result_type = std::uint64_t;
    /// Stream `(seed, a, b, c)`: distinct tuples give statistically independent streams.
    explicit Rng(std::uint64_t seed, std::uint64_t a = 0, std::uint64_t b = 0, std::uint64_t c = 0);
    static constexpr result_type min() { return 0; }
    static constexpr result_type max() { return std::numeric_limits<result_type>::max(); }
    result_type operator()();

    double uniform();      ///< U[0, 1), 53 random bits
    double uniformOpen();  ///< U(0, 1), never 0 or 1 (safe for log)
    double normal();       ///< N(0, 1) by Box-Muller (two uniforms per call, no cached state)

private:
    std::uint64_t s_[4];
};

}  // namespace trbc
