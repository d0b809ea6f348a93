#pragma once
// Thread-count-independent reductions: the index range is cut into a fixed number of blocks
// (independent of the number of OpenMP threads), each block is summed in order and the block sums
// are added in order. Results are therefore bit-identical on 1, 2 or 64 threads.
#include <algorithm>
#include <array>
#include <cstddef>

namespace trbc {

inline constexpr int kReductionBlocks = 64;

/// Sum of f(i) for i in [0, n), deterministic under OpenMP (see file comment).
template <class F>
double deterministicSum(std::ptrdiff_t n, F&& f) {
    std::array<double, kReductionBlocks> partial{};
    const std::ptrdiff_t block = (n + kReductionBlocks - 1) / kReductionBlocks;
#pragma omp parallel for schedule(static)
    for (int b = 0; b < kReductionBlocks; ++b) {
        double s = 0.0;
        const std::ptrdiff_t end = std::min(n, (b + 1) * block);
        for (std::ptrdiff_t i = b * block; i < end; ++i) s += f(i);
        partial[b] = s;
    }
    double total = 0.0;
    for (double p : partial) total += p;
    return total;
}

}  // namespace trbc
