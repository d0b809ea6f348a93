#pragma once
// Sobol' low-discrepancy sequence in base 2 (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices: base sample of the Saltelli
// design). Direction numbers: S. Joe and F. Y. Kuo, "Constructing Sobol sequences with better
// two-dimensional projections", SIAM J. Sci. Comput. 30 (2008) 2635-2654, table
// new-joe-kuo-6.21201 (the first 21 dimensions are built in). Points are generated in Gray-code
// order (Antonov & Saleev 1979) with 32-bit integer direction numbers, so every coordinate is an
// exact multiple of 2^-32 and at most 2^32 points exist.
//
// Point n (n = 0, 1, 2, ...) of dimension j is x_{n,j} = 2^-32 * XOR_{k : bit k of g(n) set} V_{j,k+1},
// g(n) = n XOR (n >> 1). Point 0 is the origin; the default skip drops it, so the first point
// returned is (0.5, 0.5, ...). An aligned block of points n in [q 2^k, (q+1) 2^k) puts exactly one
// value of every coordinate in each interval [i 2^-k, (i+1) 2^-k); for q = 0 (skip = 0) the values
// are exactly i 2^-k.
#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <vector>

namespace trbc {

class SobolSequence {
public:
    /// Number of dimensions with built-in direction numbers.
    static constexpr int kMaxDimensions = 21;
    /// Bits of the integer direction numbers; the sequence has 2^kBits points.
    static constexpr int kBits = 32;

    /// `dimensions` in [1, kMaxDimensions]; the first `skip` points (point 0 is the origin) are
    /// dropped, skip < 2^32. Throws InputError naming the option and its valid range.
    explicit SobolSequence(int dimensions, std::uint64_t skip = 1);

    int dimensions() const { return dims_; }
    /// Index n of the point the next call returns.
    std::uint64_t index() const { return index_; }

    /// Jump to point n (direct formula above, O(dimensions * 32)); n < 2^32.
    void seek(std::uint64_t n);

    /// The next point (length dimensions()). Throws InputError past point 2^32 - 1.
    Eigen::VectorXd next();
    /// The next `n` points as rows of an n x dimensions() matrix.
    Eigen::MatrixXd next(Eigen::Index n);

private:
    void advance();  // index_ -> index_ + 1, Gray-code update of x_

    int dims_;
    std::uint64_t index_ = 0;
    std::vector<std::array<std::uint32_t, kBits>> v_;  // v_[j][k] = V_{j,k+1} = m_{j,k+1} 2^(31-k)
    std::vector<std::uint32_t> x_;                     // integer coordinates of point index_
};

}  // namespace trbc
