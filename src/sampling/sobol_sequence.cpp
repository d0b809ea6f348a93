#include "sampling/sobol_sequence.hpp"

#include <bit>
#include <string>

#include "core/error.hpp"

namespace trbc {

namespace {

// Primitive polynomial x^s + a_1 x^(s-1) + ... + a_(s-1) x + 1 over GF(2) with a = (a_1 ... a_(s-1))
// in binary, and the initial direction integers m_1..m_s (odd, m_k < 2^k).
struct DirectionEntry {
    int s;
    unsigned a;
    std::array<std::uint32_t, 7> m;
};

// Published data: S. Joe and F. Y. Kuo, direction numbers file "new-joe-kuo-6.21201"
// (https://web.maths.unsw.edu.au/~fkuo/sobol/), rows d = 2..21 (columns s, a, m_i). Dimension 1
// is not in the file: it is the van der Corput sequence (all m_k = 1).
constexpr DirectionEntry kJoeKuo[SobolSequence::kMaxDimensions - 1] = {
    {1, 0, {1}},                        // d = 2
    {2, 1, {1, 3}},                     // d = 3
    {3, 1, {1, 3, 1}},                  // d = 4
    {3, 2, {1, 1, 1}},                  // d = 5
    {4, 1, {1, 1, 3, 3}},               // d = 6
    {4, 4, {1, 3, 5, 13}},              // d = 7
    {5, 2, {1, 1, 5, 5, 17}},           // d = 8
    {5, 4, {1, 1, 5, 5, 5}},            // d = 9
    {5, 7, {1, 1, 7, 11, 19}},          // d = 10
    {5, 11, {1, 1, 5, 1, 1}},           // d = 11
    {5, 13, {1, 1, 1, 3, 11}},          // d = 12
    {5, 14, {1, 3, 5, 5, 31}},          // d = 13
    {6, 1, {1, 3, 3, 9, 7, 49}},        // d = 14
    {6, 13, {1, 1, 1, 15, 21, 21}},     // d = 15
    {6, 16, {1, 3, 1, 13, 27, 49}},     // d = 16
    {6, 19, {1, 1, 1, 15, 7, 5}},       // d = 17
    {6, 22, {1, 3, 1, 15, 13, 25}},     // d = 18
    {6, 25, {1, 1, 5, 5, 19, 61}},      // d = 19
    {7, 1, {1, 3, 7, 11, 23, 15, 103}}, // d = 20
    {7, 4, {1, 3, 7, 13, 13, 15, 69}},  // d = 21
};

constexpr int kBits = SobolSequence::kBits;
constexpr std::uint64_t kPoints = std::uint64_t{1} << kBits;
constexpr double kScale = 1.0 / static_cast<double>(kPoints);  // 2^-32

using Directions = std::array<std::uint32_t, kBits>;

// V_k = m_k 2^(32-k) for k <= s; for k > s the recurrence of the primitive polynomial (Bratley &
// Fox 1988, eq. 2 in Joe & Kuo 2008):
//   V_k = a_1 V_(k-1) ^ a_2 V_(k-2) ^ ... ^ a_(s-1) V_(k-s+1) ^ V_(k-s) ^ (V_(k-s) >> s).
Directions directionNumbers(int dimension) {
    Directions v{};
    if (dimension == 1) {
        for (int k = 0; k < kBits; ++k) v[k] = std::uint32_t{1} << (kBits - 1 - k);
        return v;
    }
    const DirectionEntry& e = kJoeKuo[dimension - 2];
    for (int k = 0; k < kBits; ++k) {  // k is 0-based: v[k] = V_(k+1)
        if (k < e.s) {
            v[k] = e.m[k] << (kBits - 1 - k);
            continue;
        }
        std::uint32_t vk = v[k - e.s] ^ (v[k - e.s] >> e.s);
        for (int i = 1; i < e.s; ++i)
            if ((e.a >> (e.s - 1 - i)) & 1u) vk ^= v[k - i];
        v[k] = vk;
    }
    return v;
}

}  // namespace

SobolSequence::SobolSequence(int dimensions, std::uint64_t skip) : dims_(dimensions) {
    if (dimensions < 1 || dimensions > kMaxDimensions)
        throw InputError("SobolSequence: dimensions = " + std::to_string(dimensions) +
                         " is out of range; valid: 1 to " + std::to_string(kMaxDimensions) +
                         " (Joe-Kuo direction numbers built in)");
    v_.reserve(static_cast<std::size_t>(dims_));
    for (int j = 1; j <= dims_; ++j) v_.push_back(directionNumbers(j));
    x_.assign(static_cast<std::size_t>(dims_), 0u);
    seek(skip);
}

void SobolSequence::seek(std::uint64_t n) {
    if (n >= kPoints)
        throw InputError("SobolSequence: skip/seek index = " + std::to_string(n) +
                         " is out of range; valid: 0 to 2^32 - 1");
    const std::uint64_t gray = n ^ (n >> 1);
    for (int j = 0; j < dims_; ++j) {
        std::uint32_t x = 0;
        for (int k = 0; k < kBits; ++k)
            if ((gray >> k) & 1u) x ^= v_[j][k];
        x_[j] = x;
    }
    index_ = n;
}

// Gray code: g(n+1) = g(n) ^ 2^c with c = number of trailing one bits of n (the position of its
// lowest zero bit), so x_(n+1) = x_n ^ V_(c+1).
void SobolSequence::advance() {
    const int c = std::countr_one(index_);
    ++index_;
    if (index_ >= kPoints) return;  // next() refuses to return this point
    for (int j = 0; j < dims_; ++j) x_[j] ^= v_[j][c];
}

Eigen::VectorXd SobolSequence::next() {
    if (index_ >= kPoints)
        throw InputError("SobolSequence: all 2^32 points have been used; valid: at most 2^32 points");
    Eigen::VectorXd p(dims_);
    for (int j = 0; j < dims_; ++j) p[j] = kScale * static_cast<double>(x_[j]);
    advance();
    return p;
}

Eigen::MatrixXd SobolSequence::next(Eigen::Index n) {
    if (n < 0) throw InputError("SobolSequence: number of points = " + std::to_string(n) + " is out of range; valid: >= 0");
    if (static_cast<std::uint64_t>(n) > kPoints - index_)
        throw InputError("SobolSequence: " + std::to_string(n) + " points from index " + std::to_string(index_) +
                         " exceed the 2^32 points of the sequence");
    Eigen::MatrixXd P(n, dims_);
    for (Eigen::Index i = 0; i < n; ++i) {
        for (int j = 0; j < dims_; ++j) P(i, j) = kScale * static_cast<double>(x_[j]);
        advance();
    }
    return P;
}

}  // namespace trbc
