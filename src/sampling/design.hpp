#pragma once
// Experimental designs over the input box of docs/CAMPAIGN_AND_SURROGATE.md: i.i.d. uniform (the reference's
// design, 2.1), Latin hypercube and a randomly shifted Sobol' sequence, all seeded; points are rows of
// [0, 1]^d, then mapped to the box.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "experiments/parameters.hpp"

namespace trbc {

enum class DesignKind { Uniform, LatinHypercube, Sobol };
DesignKind parseDesignKind(const std::string& name);  ///< "uniform" | "lhs" | "sobol"; InputError otherwise
std::string designName(DesignKind kind);

/// n x d points in [0, 1)^d: i.i.d. uniform, a Latin hypercube (each column one point per
/// stratum [k/n, (k+1)/n), uniformly jittered, strata randomly permuted per column), or points
/// 1..n of the Sobol' sequence (sampling/sobol_sequence.hpp, d <= 21) shifted by one seeded uniform
/// vector modulo 1 (Cranley-Patterson rotation: every point stays uniform, the set keeps its low
/// discrepancy). Uniform and Sobol' designs are prefixes: n points are the first n of any larger design
/// with the same seed, so a campaign grows and every prefix is a valid smaller design (learning curves).
Eigen::MatrixXd unitDesign(DesignKind kind, long n, int d, std::uint64_t seed);

/// Whether a recorded input is the design's value. Builds for other instruction sets (FMA
/// contraction, libm's exp and log) map the same unit point to values that differ in the last
/// bits, so a campaign resumed or read by another build compares within 1e-12 relative; another
/// seed or design differs in the leading digits.
inline bool sameDesignValue(double recorded, double design) {
    return recorded == design || std::abs(recorded - design) <= 1e-12 * std::max(std::abs(recorded), std::abs(design));
}

/// The five cell inputs (v, mu, FvK, b2, etam) in design order, and the bead force.
inline constexpr PriorRange kCellBox[5] = {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam};
CellParameters cellFromUnit(const Eigen::Ref<const Eigen::RowVectorXd>& u);
double forceFromUnit(double u);

/// One row of a campaign: a cell (five parameters) at one bead force. Rows that share a cell
/// share its SFS, equilibrium, stretching continuation and relaxation (the physics of
/// docs/CAMPAIGN_AND_SURROGATE.md, input box: only the stretching depends on the force).
struct CampaignPoint {
    long sampleId = 0;
    long cellId = 0;
    CellParameters p;
    double fext = 0.0;  ///< pN
};

/// `nSamples` rows in cells of `forcesPerCell` rows (the last cell may be smaller). The cells
/// follow a 5-D design of kind `kind`; the forces a 1-D design of the same kind over all rows, so
/// every marginal is uniform on its range. forcesPerCell = 1 is the reference design.
std::vector<CampaignPoint> campaignDesign(DesignKind kind, long nSamples, int forcesPerCell, std::uint64_t seed);

}  // namespace trbc
