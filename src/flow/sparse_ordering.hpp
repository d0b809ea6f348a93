#pragma once
// The fill-reducing ordering of the flow preconditioner's sparse factors.
#include <Eigen/Sparse>
#include <iostream>  // Eigen/MetisSupport uses std::cerr without including it
#include <Eigen/MetisSupport>
#include <mutex>

namespace trbc {

/// Serialises the process's METIS calls. METIS seeds the C library's rand() with its fixed seed and
/// draws its ordering from it: two orderings at once (flow cases run side by side in threads)
/// interleave one random sequence, and each gets an ordering that depends on the timing (without the
/// lock, all 80 orderings of CellFlow.TheFactorsOrderingIsTheLoneCallsWhateverRunsBesideIt differ
/// from the lone call's). The factor is the same up to round-off whatever the ordering, but that
/// round-off then differs in the last digits of a run's results.
inline std::mutex& metisMutex() {
    static std::mutex m;
    return m;
}

/// Eigen's METIS nested-dissection ordering (an ordering functor of Eigen's sparse Cholesky factors),
/// one call at a time: every call returns the ordering of a lone call, whatever runs beside it.
template <class StorageIndex>
class SerialMetisOrdering {
public:
    using PermutationType = typename Eigen::MetisOrdering<StorageIndex>::PermutationType;

    template <class MatrixType>
    void operator()(const MatrixType& A, PermutationType& perm) {
        const std::lock_guard lock(metisMutex());
        Eigen::MetisOrdering<StorageIndex>()(A, perm);
    }
};

}  // namespace trbc
