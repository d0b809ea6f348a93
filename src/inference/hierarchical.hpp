#pragma once
// Phases 2 and 3 of the hierarchical red-cell inference (docs/BAYESIAN_INFERENCE.md), built on the
// phase-1 samples without new evaluations of the phase-1 likelihoods (phase 2) and with the
// phase-2 samples (phase 3):
//
//   phase 2:  p(psi | d) ∝ p(psi) prod_i b_i(psi),  b_i(psi) = (1/N_i) sum_k p_i(theta_k | psi) / pi_i(theta_k);
//   phase 3a: p(theta_new | d) ≈ (1/M) sum_m p(theta_new | psi_m) on the box of 4.5;
//   phase 3b: p(theta_i, sigma | d_i, d) ∝ pi3_i p(d_i | theta_i, sigma) (1/M) sum_m p_i(theta_i | psi_m) / max(b_i(psi_m), 1e-6).
//
// All sums are log-sum-exp with a max shift, in vectorised loops (population_kernels.hpp),
// threaded over the candidates of a batch (each candidate's sum runs serially in a fixed order, so
// results do not depend on the thread count). What keeps the ~1e11 terms of a 50 000-sample run
// affordable:
//   * identical samples (BASIS repeats a sample whenever its move is rejected) are merged into one
//     term with their multiplicity (exact; only the summation order changes);
//   * one-dimensional sums (relaxation, phase 2) use a Hermite expansion per bin (exact to ~1e-15);
//   * one-dimensional mixtures (relaxation, phase 3b) are tabulated and interpolated (checked, 1e-9);
//   * q(FvK | psi) is evaluated in mixed precision by default (|d log q| < 1e-5; FvkDensityRule).
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <vector>

#include "inference/population.hpp"
#include "inference/rbc_problem.hpp"
#include "inference/tmcmc.hpp"

namespace trbc {

/// Distinct columns of x (exact equality), in order of first appearance: columns.col(index[k]) == x.col(k),
/// count[u] = number of columns equal to distinct column u.
struct DistinctColumns {
    Eigen::MatrixXd columns;
    std::vector<Eigen::Index> count, index;
};
DistinctColumns distinctColumns(const Eigen::MatrixXd& x);

/// Time spent in the population sums (phase 2 likelihoods, phase 3 mixtures and precomputations).
struct PopulationTimer {
    double seconds = 0.0;
    long long terms = 0;  ///< density terms evaluated
};

/// Pooled coordinates that a data set sees: equilibrium (v, FvK), stretching (v, mu, kb, b2),
/// relaxation (r). They are the first 2, 4 or 1 phase-1 variables.
int pooledCoordinateCount(RbcExperiment e);

/// The final phase-1 samples of one data set as the re-weighting needs them: distinct pooled
/// coordinates x_k (d x K) with log w_k = log(n_k / N) - log pi_i(x_k) (n_k = multiplicity, pi_i the
/// phase-1 prior density of those coordinates, uniform / ratio-uniform, exact).
struct ReweightingSamples {
    RbcExperiment experiment = RbcExperiment::Equilibrium;
    Eigen::MatrixXd x;          ///< sorted lexicographically
    Eigen::VectorXd logWeight;
    Eigen::Index total = 0;     ///< N (with repeats)
    /// One-dimensional sets (relaxation): the samples grouped into bins of width <= binWidth around
    /// centres c_b, with the weighted moments mu_bn = sum_{k in b} exp(lw_k - L_b) (x_k - c_b)^n,
    /// n < kHermiteTerms, L_b = max_{k in b} lw_k (see logReweightingFactors).
    struct Bin {
        Eigen::Index first = 0, last = 0;  ///< sample range [first, last)
        double centre = 0.0, logScale = 0.0;
    };
    static constexpr int kHermiteTerms = 24;
    static constexpr double kBinWidth = 1e-3;
    std::vector<Bin> bins;
    Eigen::MatrixXd moments;    ///< kHermiteTerms x bins
};
/// `phase1Samples` is dim x N (phase-1 variables of `data`, e.g. TmcmcResult::samples).
ReweightingSamples reweightingSamples(const RbcDataSet& data, const Eigen::MatrixXd& phase1Samples);

/// log b_i(psi) for every column of psi (kHyperDimension x B), threaded over columns.
/// -inf where b_i is zero or not finite. One-dimensional sets (relaxation, sum_k w_k N(r_k; mu_r, sd_r^2))
/// use, for sd_r >= 10 x the bin width, the Hermite expansion of the Gaussian around each bin centre
/// (the 1-D fast Gauss transform): with a = (c - mu)/sd and d_k = (r_k - c)/sd (|d_k| <= 0.05),
///   sum_{k in b} w_k e^{-(r_k - mu)^2 / (2 sd^2)} = e^{-a^2/2} sum_n He_n(a) (-1)^n / n! sum_{k in b} w_k d_k^n,
/// truncated after 24 terms (relative error < 1e-15 for |a| <= 30; bins with |a| > 30 are summed
/// directly). Exact to round-off, and independent of the number of samples per candidate.
Eigen::VectorXd logReweightingFactors(const ReweightingSamples& samples, const Eigen::MatrixXd& psi,
                                      FvkDensityRule rule = FvkDensityRule::ClosedForm, PopulationTimer* timer = nullptr);

/// Phase 2: hyper-prior and log-likelihood sum_i log b_i(psi).
TmcmcProblem phase2Problem(std::vector<ReweightingSamples> sets, FvkDensityRule rule = FvkDensityRule::ClosedForm,
                           std::shared_ptr<PopulationTimer> timer = nullptr);

// ------------------------------------------------------------------------------------------------
// Mixtures over the phase-2 samples (phase 3)

/// log (1/M) sum_m exp(c_m) p(x | psi_m) over the M phase-2 samples psi_m, for query points x of the
/// pooled coordinates of one layout:
///   NewCell: x = (v, mu, kb, b2, r), the full density of 4.2 (phase 3a);
///   Equilibrium / Stretching / Relaxation: the marginals of 4.3 (phase 3b).
class PopulationMixture {
public:
    enum class Layout { NewCell, Equilibrium, Stretching, Relaxation };
    /// psi: kHyperDimension x M; logOffset: c_m (size M, or empty = 0). fvkFrom >= 0 (equilibrium
    /// only): evaluate q(FvK | psi) at that single column for every m (the reference's defect, 4.6).
    /// Identical (psi_m, c_m) are merged into one component with weight n (BASIS repeats samples).
    PopulationMixture(Layout layout, const Eigen::MatrixXd& psi, const Eigen::VectorXd& logOffset = Eigen::VectorXd(),
                      FvkDensityRule rule = FvkDensityRule::ClosedForm, Eigen::Index fvkFrom = -1);
    int dimension() const { return static_cast<int>(pooled_.size()) + (fvk_ ? 1 : 0); }
    Eigen::Index components() const { return M_; }              ///< M (with repeats)
    Eigen::Index distinctComponents() const { return c_.size(); }
    /// One query (the first dimension() entries of x are used).
    double logMeanAt(const Eigen::Ref<const Eigen::VectorXd>& x) const;
    /// Every column of x (threaded over columns).
    Eigen::VectorXd logMean(const Eigen::MatrixXd& x, PopulationTimer* timer = nullptr) const;

    /// One-dimensional layouts (relaxation): tabulate log (1/M) sum_m ... on a uniform grid of
    /// [lo, hi] with spacing h and answer queries inside it by 4-point Lagrange interpolation. The
    /// table is checked against the exact sum at the mid-points of 1000 cells spread over the range;
    /// h is halved until the largest difference there is below `tolerance` where the log density is
    /// within 40 of its maximum. Returns that difference. The mixture's components have sd >= 0.01
    /// (hyper-prior), so h = 1e-4 typically suffices (interpolation error ~ (h/sd)^4 / 384).
    double tabulate(double lo, double hi, double h = 1e-4, double tolerance = 1e-9, PopulationTimer* timer = nullptr);
    bool tabulated() const { return table_.size() > 0; }

private:
    std::vector<int> pooled_;         // pooled index of each Gaussian coordinate
    std::vector<double> lo_, hi_;     // truncation bounds of each Gaussian coordinate
    Eigen::MatrixXd mean_, invSd_;    // M x (number of Gaussian coordinates)
    Eigen::ArrayXd c_;                // c_m - sum_j logNorm_jm
    bool fvk_ = false;                // equilibrium: second coordinate FvK with q(FvK | psi_m)
    FvkDensityRule rule_ = FvkDensityRule::ClosedForm;
    bool fvkSingle_ = false;          // q at one psi for every m
    RatioDensityParameters fvkSingleParameters_;
    std::vector<RatioDensityParameters> fvkParameters_;
    struct FvkArrays {  // q coefficients per component (closed form): muX, sdX^2, 1/sdX^2, muY, sdY^2, 1/sdY^2, log C
        Eigen::ArrayXd muX, vx, ivx, muY, vy, ivy, logC;
    } fvkArrays_;
    Eigen::Index M_ = 0;
    Eigen::VectorXd table_;           // tabulated log mean (1-D layouts)
    double tableLo_ = 0.0, tableH_ = 0.0;
    double exactLogMean(const double* q, double z, double* L) const;
};

/// Phase 3a: the box prior of newCellBoxPrior and the mixture log (1/M) sum_m p(theta | psi_m)
/// as log-likelihood.
TmcmcProblem phase3aProblem(const Eigen::MatrixXd& psi, std::shared_ptr<PopulationTimer> timer = nullptr);

/// Cross-check of phase 3a: n ancestral draws (m uniform, theta ~ p(theta | psi_m), rejected
/// outside the box), 5 x n, reproducible for a seed.
Eigen::MatrixXd sampleNewCellAncestral(const Eigen::MatrixXd& psi, Eigen::Index n, std::uint64_t seed);

/// Options of phase 3b.
struct Phase3bOptions {
    FvkDensityRule rule = FvkDensityRule::ClosedForm;
    /// Reference prior (used): the phase-1 prior multiplies the target (ratio-uniform factors on FvK
    /// and r) and the equilibrium sigma is U[1e-4, 0.5]. Default: the indicator of the phase-1 support.
    bool referencePrior = false;
    /// Reference defect (used): the equilibrium q(FvK | psi) at the last phase-2 sample for every m.
    bool referenceEquilibriumDefect = false;
    double bFloor = 1e-6;  ///< max(b_i(psi_m), bFloor) in the denominators
};

/// Prior of phase 3b for a data set: the indicator of the phase-1 support (a uniform box with the
/// phase-1 bounds), or with referencePrior the phase-1 prior (equilibrium sigma on [1e-4, 0.5]).
std::shared_ptr<const ProductPrior> phase3bPrior(const RbcDataSet& data, const Phase3bOptions& options);

/// Phase 3b for one data set: log p(d_i | theta, sigma) + log (1/M) sum_m p_i(theta | psi_m) / max(b_i(psi_m), floor)
/// with logB = log b_i(psi_m) (size M, from logReweightingFactors).
TmcmcProblem phase3bProblem(const RbcModel& model, const RbcDataSet& data, const Eigen::MatrixXd& psi,
                            const Eigen::VectorXd& logB, const Phase3bOptions& options,
                            std::shared_ptr<PopulationTimer> timer = nullptr);

}  // namespace trbc
