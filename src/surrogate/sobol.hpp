#pragma once
// Variance-based global sensitivity analysis (Sobol' indices), docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices:
// Saltelli's design with second-order cross matrices, the estimators of 4.2 (first order Saltelli
// et al. 2010, total Jansen 1999, second order Saltelli 2002) for many outputs at once, and
// bootstrap confidence intervals over the base rows.
//
// Inputs are independent and uniform on a box [lo_i, hi_i]. The model is a batched callback: it
// receives points as rows (columns = inputs) and returns one row per point (columns = outputs),
// so a surrogate can evaluate the whole design in large batches.
#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace trbc {

/// Batched model: X (points x inputs) -> Y (points x outputs). Must return X.rows() rows and the
/// same number of columns on every call.
using SobolModel = std::function<Eigen::MatrixXd(const Eigen::MatrixXd& X)>;

/// Base sample of the design: Sobol' low-discrepancy points (used by the reference) or
/// seeded pseudo-random uniforms (for tests).
enum class SobolBase { Sobol, PseudoRandom };

struct SobolOptions {
    /// N, number of base rows (>= 2). With the Sobol' base a power of two keeps its balance.
    Eigen::Index nBase = 1024;
    SobolBase base = SobolBase::Sobol;
    /// Sobol' base only: points of the 2D-dimensional sequence dropped before the N used
    /// (>= 0), or -1 (default): the smallest power of two >= N, so that the N points used are
    /// the aligned block [2^m, 2^m + N) (a net when N = 2^m) and the origin is never used.
    std::int64_t sobolSkip = -1;
    /// Seeds the pseudo-random base sample (std::mt19937_64(seed)) and the bootstrap (replicate r
    /// uses its own stream derived from (seed, r), so results do not depend on the thread count).
    std::uint64_t seed = 12345;
    /// R, bootstrap resamples (0: no intervals, the *_ci fields are 0; otherwise >= 2).
    int resamples = 100;
    /// Confidence-interval half-width = z * SD of the bootstrap replicates (95 %: z_0.975).
    double z = 1.959964;
    /// Build the B_A^(i) matrices and estimate S_ij (N(2D+2) evaluations, else N(D+2)).
    bool secondOrder = true;
    /// Rows per model call (>= 1), or 0: the whole design in one call.
    Eigen::Index batchSize = 0;
};

/// Saltelli design in physical units. The stacked points() are blocks of N rows:
/// block 0 = A, block 1+i = A_B^(i) (A with column i from B), block 1+D+i = B_A^(i) (B with
/// column i from A; second order only), last block = B.
struct SaltelliDesign {
    Eigen::Index n = 0;  ///< N, base rows
    Eigen::Index d = 0;  ///< D, inputs
    bool secondOrder = true;
    Eigen::MatrixXd A, B;  ///< N x D, scaled to the box

    Eigen::Index blocks() const { return secondOrder ? 2 * d + 2 : d + 2; }
    Eigen::Index rows() const { return n * blocks(); }
    Eigen::Index blockAB(Eigen::Index i) const { return 1 + i; }
    Eigen::Index blockBA(Eigen::Index i) const { return 1 + d + i; }
    Eigen::Index blockB() const { return blocks() - 1; }
    /// All rows() points, stacked as described above.
    Eigen::MatrixXd points() const;
};

/// A and B from a 2D-dimensional base sample u in [0,1)^(2D) (first D columns -> A, last D -> B),
/// x = lo + u (hi - lo). Throws InputError for bad options or boxes (sizes differ, D < 1,
/// lo >= hi, non-finite bounds; Sobol' base: 2D <= SobolSequence::kMaxDimensions).
SaltelliDesign saltelliDesign(const Eigen::VectorXd& lo, const Eigen::VectorXd& hi, const SobolOptions& opt);

/// Indices per output (rows) and input (columns). With R = 0 the *_ci are 0.
struct SobolResult {
    std::vector<std::string> inputs, outputs;
    Eigen::Index nBase = 0, evaluations = 0;
    int resamples = 0;
    Eigen::MatrixXd S1, S1_ci, ST, ST_ci;  ///< outputs x inputs
    /// Per output a symmetric D x D matrix of S_ij (diagonal unused, 0); empty without second order.
    std::vector<Eigen::MatrixXd> S2, S2_ci;
};

/// Estimators of 4.2 from model values Y (design.rows() x outputs, rows aligned with
/// design.points()). Each output is first standardised, (y - mean)/SD over all its rows; an output
/// with zero variance gets NaN indices. Bootstrap: R times draw N base rows with replacement,
/// re-estimate with the same rows of every block; CI half-width = z * SD (divisor R-1).
/// Empty name lists default to x1.., y1... Throws InputError on size mismatches and
/// NumericalError on a non-finite Y.
SobolResult sobolIndices(const SaltelliDesign& design, const Eigen::MatrixXd& Y, const SobolOptions& opt,
                         std::vector<std::string> inputNames = {}, std::vector<std::string> outputNames = {});

/// Whole analysis: design on [lo, hi], model evaluated in batches of opt.batchSize rows, indices.
SobolResult sobolAnalysis(const SobolModel& model, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi,
                          const SobolOptions& opt, std::vector<std::string> inputNames = {},
                          std::vector<std::string> outputNames = {});

/// Evaluate the model on all rows of X in batches of `batchSize` rows (0: one call), checking the
/// shape of every returned block.
Eigen::MatrixXd evaluateInBatches(const SobolModel& model, const Eigen::MatrixXd& X, Eigen::Index batchSize);

}  // namespace trbc
