#include "core/random.hpp"

#include <cmath>
#include <numbers>

namespace trbc {
namespace {

constexpr std::uint64_t kGolden = 0x9e3779b97f4a7c15ULL;

std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

}  // namespace

std::uint64_t splitmix64(std::uint64_t x) {
    // Output of the splitmix64 generator at state x: z = x + golden, then two xor-shift-multiply rounds.
    std::uint64_t z = x + kGolden;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

Rng::Rng(std::uint64_t seed, std::uint64_t a, std::uint64_t b, std::uint64_t c) {
    // Hash the stream tuple into one 64-bit key (each component mixed before xor-ing, so that
    // (seed, a, b, c) permutations differ), then expand the key with splitmix64 into the state.
    std::uint64_t h = splitmix64(seed);
    h = splitmix64(h ^ splitmix64(a ^ 0x243f6a8885a308d3ULL));
    h = splitmix64(h ^ splitmix64(b ^ 0x13198a2e03707344ULL));
    h = splitmix64(h ^ splitmix64(c ^ 0xa4093822299f31d0ULL));
    for (int i = 0; i < 4; ++i) {
        s_[i] = splitmix64(h);
        h += kGolden;
    }
}

Rng::result_type Rng::operator()() {
    // xoshiro256**: output rotl(s1 * 5, 7) * 9, then the linear state update.
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
}

double Rng::uniform() { return static_cast<double>((*this)() >> 11) * 0x1.0p-53; }

double Rng::uniformOpen() { return (static_cast<double>((*this)() >> 11) + 0.5) * 0x1.0p-53; }

double Rng::normal() {
    // Box-Muller: sqrt(-2 log u1) cos(2 pi u2).
    const double u1 = uniformOpen();
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

}  // namespace trbc
