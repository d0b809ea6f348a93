#pragma once
// Forward propagation of a posterior (docs/BAYESIAN_INFERENCE.md, prediction; `trbc predict`): every posterior
// sample is pushed through the surrogate (equilibrium, stretching) or Hochmuth's law (relaxation)
// and combined with its own error model, giving a predictive mixture of normals per observable
// and abscissa. Quantiles of the mixture are found by bisection on its CDF (the "better numerics"
// ), the mean curve is the mean of the noise-free outputs, and every experimental data
// point is checked against the central 90 % band (coverage).
//
// Posterior samples are read from the samples.csv files that `trbc infer` writes
// (rbc_pipeline.hpp), physical units, one row per sample:
//   equilibrium   v, FvK, sigma_rel
//   stretching    v, mu_uN_per_m, kb_J, b2, sigma0_um, sigma1_um
//   relaxation    etam_over_mu_s, sigma_tc_rel, tc_s, z0, zinf, sigma_z
// (plus log_likelihood, log_prior, which are not used).
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "inference/rbc_problem.hpp"

namespace trbc {

struct ExperimentOptions;

// ------------------------------------------------------------------------------------------------
// Mixtures of normals p(y) = (1/N) sum_k N(y; m_k, s_k^2); s_k <= 0 is a point mass at m_k.

double normalMixtureCdf(const Eigen::VectorXd& means, const Eigen::VectorXd& sds, double y);
double normalMixtureDensity(const Eigen::VectorXd& means, const Eigen::VectorXd& sds, double y);
/// Quantile by bisection on the CDF (bracket min(m - 12 s) .. max(m + 12 s)), accelerated by Newton
/// steps that stay inside the bracket, to an absolute tolerance `tol` (in the units of y; 0 picks
/// 1e-9 of the bracket width). Throws InputError for q outside (0, 1) or an empty mixture.
double normalMixtureQuantile(const Eigen::VectorXd& means, const Eigen::VectorXd& sds, double q, double tol = 0.0);

/// Predictive levels (50/75/90/99 % central bands and the median), ascending.
const std::vector<double>& predictiveLevels();  ///< 0.005 0.05 0.125 0.25 0.5 0.75 0.875 0.95 0.995
/// Column suffix of a level: q005, q05, q125, q25, q50, q75, q875, q95, q995.
std::string levelSuffix(double q);

/// Quantiles (predictiveLevels order) and noise-free mean of one predictive mixture.
struct PredictiveSummary {
    Eigen::VectorXd quantiles;
    double mean = 0.0;
    double q05() const;
    double q95() const;
};
PredictiveSummary summarizeMixture(const Eigen::VectorXd& means, const Eigen::VectorXd& sds);

// ------------------------------------------------------------------------------------------------
// Posterior samples

struct PosteriorSamples {
    std::filesystem::path file;        ///< the samples.csv read
    std::string name;                  ///< directory name (data set name, theta_new, ...)
    std::string label;                 ///< name used in output file names (single_/hierarchical_ prefix by phase)
    RbcExperiment experiment = RbcExperiment::Equilibrium;
    std::vector<std::string> columns;  ///< phase1OutputNames(experiment)
    Eigen::MatrixXd values;            ///< columns.size() x N, physical units (one sample per column)
};

/// Reads DIR/samples.csv (or the file itself). The experiment is recognised from the columns;
/// InputError naming the file when it is missing, unreadable, has no rows, or lacks a column of
/// its experiment (or matches none).
PosteriorSamples readPosteriorSamples(const std::filesystem::path& dirOrFile);

/// The posteriors of a `trbc infer` output directory: DIR/phase3/<data set> (the hierarchical ones)
/// and, with `withPhase1`, DIR/phase1/<data set> before them; each phase sorted by name, theta_new
/// left out. InputError naming `option` and DIR when DIR, a phase or its samples are missing.
std::vector<std::filesystem::path> inferencePosteriorDirectories(const std::filesystem::path& inferenceDirectory, bool withPhase1,
                                                                 const std::string& option = "--inference");

/// `n` distinct sample indices out of `total` (all, in order, when n <= 0 or n >= total), seeded.
std::vector<Eigen::Index> subsampleIndices(Eigen::Index total, Eigen::Index n, std::uint64_t seed);

// ------------------------------------------------------------------------------------------------
// Predictions

/// Forward models used by the prediction (the surrogate normally; tests inject analytic ones).
/// Only equilibrium and stretching are needed; relaxationTime is optional (tc_sim report).
using PredictionModel = RbcModel;

/// Predictive band of one observable along an abscissa (forces, times), or at the three
/// equilibrium observables (x = 0, 1, 2).
struct ObservableBand {
    std::string observable;                  ///< D0_um, D1_um, z, D_um, hmin_um, hmax_um
    std::vector<double> x;
    std::vector<PredictiveSummary> summary;  ///< one per x
};

/// One data point checked against the 90 % band (coverage table).
struct CoveragePoint {
    std::string observable;
    double x = 0.0;  ///< force (pN), time (s), or 0 for equilibrium
    double y = 0.0;  ///< measured value
    double q05 = 0.0, q50 = 0.0, q95 = 0.0;
    bool inside() const { return y >= q05 && y <= q95; }
};

struct PosteriorPrediction {
    std::string label, name;
    RbcExperiment experiment = RbcExperiment::Equilibrium;
    std::filesystem::path samplesFile;
    Eigen::Index samplesUsed = 0;
    std::string xName;                     ///< Fext_pN, t_s, or empty (equilibrium)
    std::vector<ObservableBand> bands;     ///< on the prediction grid (stretching: 100 forces, relaxation: 100 times)
    /// Equilibrium only: predictive densities on 200 points over mean(f) +- 3 [sd(f) + mean(sigma f)].
    std::vector<std::vector<double>> densityX, density;
    bool haveData = false;
    std::vector<CoveragePoint> coverage;   ///< bands evaluated at the data's own abscissae
    /// Relaxation: the surrogate's tc_sim(r) = r g(0.95, 4, 250, 1.6, 4 r) per sample (if the model has
    /// relaxationTime) next to the latent tc.
    Eigen::VectorXd tcSim, tcLatent;
};

struct PredictionOptions {
    int gridPoints = 100;          ///< forces on [0, 200] pN / times on [0, 0.5] s
    double forceMax = 200.0, timeMax = 0.5;
    int densityPoints = 200;
};

/// Propagates one posterior. `data` (optional) is the data set of the same experiment for coverage.
/// `indices` selects the samples used (empty: all).
PosteriorPrediction predictPosterior(const PosteriorSamples& posterior, const PredictionModel& model, const RbcDataSet* data,
                                     const PredictionOptions& options = {});

/// Writes DIR/predict_<label>_<experiment>.csv (and, for equilibrium, ..._density.csv). Returns the files.
std::vector<std::filesystem::path> writePredictionCsv(const std::filesystem::path& dir, const PosteriorPrediction& p);
/// Coverage of all predictions: one CSV row per data point (coverage.csv).
void writeCoverageCsv(const std::filesystem::path& file, const std::vector<PosteriorPrediction>& predictions);
/// Markdown coverage section: per posterior the number of points inside the 90 % band and the list
/// of those outside.
std::string coverageMarkdown(const std::vector<PosteriorPrediction>& predictions);

// ------------------------------------------------------------------------------------------------
// Surrogate versus direct forward model on a subsample

/// Observable values of the surrogate and of the direct model at the same inputs.
struct DirectComparison {
    std::string label, observable;
    std::vector<double> surrogate, direct;
    int failures = 0;  ///< direct runs that threw NumericalError (left out)
    double rmse() const;
    double maxAbs() const;
};
std::string directComparisonMarkdown(const std::vector<DirectComparison>& rows, int level);

/// Runs the direct forward model (experiments.hpp, runSample / runStretching, at options.level) on
/// the given posterior samples and the surrogate at the same inputs:
///   equilibrium  D, hmin, hmax at (v, FvK), mu = 4, b2 = 2 (ignored by the network, 3.1);
///   stretching   D0, D1 at the data forces (or 0, 50, ..., 200 pN without data);
///   relaxation   tc at (0.95, 4, 250, 1.6, 4 r).
/// Samples whose direct run fails (NumericalError) are counted in `failures` and left out.
std::vector<DirectComparison> compareWithDirectModel(const PosteriorSamples& posterior, const PredictionModel& model,
                                                     const RbcDataSet* data, const std::vector<Eigen::Index>& indices,
                                                     const ExperimentOptions& options,
                                                     const std::function<void(const std::string&)>& progress = {});

/// The posterior restricted to the given sample indices.
PosteriorSamples selectSamples(const PosteriorSamples& posterior, const std::vector<Eigen::Index>& indices);

}  // namespace trbc
