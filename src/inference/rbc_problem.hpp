#pragma once
// The red-cell inference problem of docs/BAYESIAN_INFERENCE.md (phase 1): the seven data sets, the forward
// models they need (batched callbacks, normally the surrogate networks), the phase-1 parameters and
// priors and the seven likelihoods. The sampler (tmcmc.hpp) knows nothing of this; this file knows
// nothing of the sampler beyond the TmcmcProblem it hands over (problem / likelihood / solver are
// kept apart, Korali style). The hierarchical phases 2-3 are in hierarchical.hpp.
//
// Units inside the inference: um, pN, s; mu in uN/m; kb in 1e-18 J (= pN um); etam in Pa s um;
// r = etam / mu in s. Outputs convert kb to J (rbcOutputScale).
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "experiments/parameters.hpp"
#include "inference/flow_likelihood.hpp"
#include "inference/priors.hpp"
#include "inference/tmcmc.hpp"

namespace trbc {

struct Surrogate;

// ------------------------------------------------------------------------------------------------
// Constants (docs/BAYESIAN_INFERENCE.md)

inline constexpr double kRbcAreaRadius2 = 10.742958658;  ///< R_A^2 = 135 / (4 pi) um^2
inline constexpr double kKbLow = 0.1074295866;            ///< kappa_lo, 1e-18 J (kb / R_A^2 = 0.01 uN/m)
inline constexpr double kKbHigh = 1.074295866;            ///< kappa_hi, 1e-18 J (kb / R_A^2 = 0.1 uN/m)
inline constexpr double kJoulePerKbUnit = 1e-18;          ///< kb in J = kb (inference unit) * 1e-18

/// FvK = mu R_A^2 / kb (mu in uN/m, kb in 1e-18 J).
inline double fvkFromModuli(double mu, double kb) { return mu * kRbcAreaRadius2 / kb; }

// ------------------------------------------------------------------------------------------------
// Data (docs/BAYESIAN_INFERENCE.md, data)

/// Flow: a shear-flow data set (inference/flow_likelihood.hpp) seen through the flow networks; its
/// cell is the whole (v, mu, kb, b2, r). Taken by the joint method only.
enum class RbcExperiment { Equilibrium, Stretching, Relaxation, Flow };
const char* experimentName(RbcExperiment e);  ///< "equilibrium", "stretching", "relaxation", "flow"

/// Phase-1 prior box of the physical parameters (docs/BAYESIAN_INFERENCE.md), in inference units (kb in
/// 1e-18 J). The default is the spec's box, which is also the surrogates' training box
/// (docs/CAMPAIGN_AND_SURROGATE.md, input box); a user may narrow it (`trbc infer --prior`, `[inference.prior]` of a calibrate
/// config) but never widen it, because the networks are not valid outside their training box.
/// The equilibrium FvK prior stays ratio-uniform with X = mu in [muLo, muHi], Y = kb / R_A^2, and
/// the relaxation ratio r = etam / mu ratio-uniform with X = etam, Y = mu.
struct RbcPriorBox {
    double vLo = kPriorV.lo, vHi = kPriorV.hi;
    double muLo = kPriorMu.lo, muHi = kPriorMu.hi;
    double kbLo = kKbLow, kbHi = kKbHigh;
    double b2Lo = kPriorB2.lo, b2Hi = kPriorB2.hi;
    double etamLo = kPriorEtam.lo, etamHi = kPriorEtam.hi;

    /// Canonical names of the bounded parameters: v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um.
    static const std::vector<std::string>& parameterNames();
    /// Bounds of a parameter by canonical name, in physical units (kb in J); InputError for an unknown name.
    std::pair<double, double> bounds(const std::string& name) const;
    /// Sets the bounds of a parameter (physical units). InputError naming the parameter and the valid
    /// range unless default.lo <= lo < hi <= default.hi.
    void set(const std::string& name, double lo, double hi);
};

/// One of the seven data sets. Only the fields of its experiment are filled.
struct RbcDataSet {
    std::string name;               ///< evans_fung_1972, mills_2004, suresh_2005, hochmuth_1979_cell1..4
    RbcExperiment experiment = RbcExperiment::Equilibrium;
    std::filesystem::path file;
    std::string contentHash;        ///< FNV-1a of the file bytes (provenance)
    Eigen::Vector3d shape = Eigen::Vector3d::Zero();  ///< equilibrium: mean D, hmin, hmax (um)
    /// equilibrium: the population SD of D, hmin, hmax (um) where the file gives one (sd_um), NaN
    /// elsewhere; drawn by the figures, not used by the likelihood (its error model is inferred).
    Eigen::Vector3d shapeSd = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    Eigen::VectorXd force, d0, d1;  ///< stretching: bead force F_j (pN), transverse D0_j, axial D1_j (um)
    Eigen::VectorXd time, aspect;   ///< relaxation: t_k (s), z_k = L/W
    RbcPriorBox prior;              ///< phase-1 prior box of the physical parameters
    std::shared_ptr<const FlowDataSet> flow;  ///< flow: the observations and their error model
};

/// A flow data set as a data set of the model.
RbcDataSet flowRbcDataSet(FlowDataSet flow);

/// Readers; every problem is an InputError naming the file, the line and the column.
/// Equilibrium: columns quantity (D, hmin, hmax), mean_um (> 0), optional sd_um (>= 0 or blank).
RbcDataSet readEquilibriumData(const std::filesystem::path& file, std::string name = "evans_fung_1972");
/// Stretching: columns Fext (pN, >= 0), D0, D1 (um, > 0), at least one row.
RbcDataSet readStretchingData(const std::filesystem::path& file, std::string name);
/// Relaxation: columns t (s, >= 0), L_W (> 0), at least two rows.
RbcDataSet readRelaxationData(const std::filesystem::path& file, std::string name);

/// Manifest file name of a user-assembled data directory (see loadRbcDataSets).
inline constexpr const char* kRbcDataManifest = "datasets.json";
/// The data sets of a directory: when it holds datasets.json (an array of {"name", "experiment":
/// equilibrium|stretching|relaxation, "file" relative to the directory}) those, in its order (any
/// number per experiment, names unique); otherwise the seven data sets of docs/BAYESIAN_INFERENCE.md, in its
/// order, from an `experiments` directory
/// (equilibrium/evans_fung_1972.csv, stretching/{mills_2004,suresh_2005}/..., relaxation/hochmuth_1979/1-4.csv).
std::vector<RbcDataSet> loadRbcDataSets(const std::filesystem::path& experimentsDirectory);

// ------------------------------------------------------------------------------------------------
// Forward models (batched, one sample per column)

/// The three experiments as batch callbacks, normally the surrogate networks (surrogate.hpp);
/// tests inject analytic models. Each is called from one thread and may thread internally.
struct RbcModel {
    /// (v, FvK) 2 x n -> (D, hmin, hmax) um, 3 x n.
    std::function<Eigen::MatrixXd(const Eigen::MatrixXd&)> equilibrium;
    /// (v, mu, FvK, b2, Fext) 5 x n -> (D0, D1) um, 2 x n.
    std::function<Eigen::MatrixXd(const Eigen::MatrixXd&)> stretching;
    /// (v, mu, FvK, b2, etam) 5 x n -> relaxation time tc in s, n.
    std::function<Eigen::VectorXd(const Eigen::MatrixXd&)> relaxationTime;
    /// The flow networks, for flow data sets (empty without them).
    FlowModel flow;
};

/// Time and evaluations spent in the forward model (accumulated by timedModel).
struct ModelTimer {
    double seconds = 0.0;
    long long evaluations = 0;  ///< cells evaluated (columns); a critical stress, a bisection over the networks, counts once
};

/// The surrogate as an RbcModel (the surrogate object is shared, not copied).
RbcModel surrogateRbcModel(std::shared_ptr<const Surrogate> surrogate);
/// The same model with every call timed into `timer` (which must outlive the model).
RbcModel timedModel(RbcModel model, std::shared_ptr<ModelTimer> timer);

// ------------------------------------------------------------------------------------------------
// Phase-1 parameters and priors (3.1-3.3)

/// Sampled variables of each experiment, in inference units:
///   equilibrium (v, FvK, sigma); stretching (v, mu, kb, b2, sigma0, sigma1);
///   relaxation (r, sigma_tc, tc, z0, zinf, sigma_z); flow (v, mu, kb, b2, r, sigma).
const std::vector<std::string>& phase1ParameterNames(RbcExperiment e);
/// The same as written to files, physical units (kb in J): e.g. v, mu_uN_per_m, kb_J, b2, sigma0_um, ...
const std::vector<std::string>& phase1OutputNames(RbcExperiment e);
/// The columns of a data set's samples: phase1OutputNames(d.experiment), with a flow set's noise
/// named by its unit: sigma_deg for an inclination set, sigma_rel for a TTF or critical-stress set.
std::vector<std::string> phase1OutputNames(const RbcDataSet& d);
/// Factor from inference to output units per parameter (1, or 1e-18 for kb).
Eigen::VectorXd phase1OutputScale(RbcExperiment e);

/// Phase-1 prior pi_i (3.1-3.3): uniform boxes, ratio-uniform FvK in [10, 1000] (X = mu in [1, 10],
/// Y = kb / R_A^2 in [0.01, 0.1]) and ratio-uniform r in [0.01, 1] s (X = etam in [0.1, 1],
/// Y = mu in [1, 10]); relaxation z0 ~ U[y_1 - 0.2, y_1 + 0.2] with y_1 the first L/W of the cell.
/// The bounds of v, mu, kb, b2, etam are those of data.prior (the spec's box by default).
/// Flow: v, mu, kb, b2 uniform on the box, r uniform on [etamLo / muHi, etamHi / muLo], sigma
/// uniform on [0, 5] deg (inclination) or [0, 2] (relative, TTF and critical stress).
std::shared_ptr<const ProductPrior> phase1Prior(const RbcDataSet& data);

// ------------------------------------------------------------------------------------------------
// Likelihoods (3.1-3.3), batched: theta is dim x n (phase-1 variables), returns n log-likelihoods.
// A non-positive standard deviation gives -inf.

/// log N(y; m, s^2) = -((y - m)/s)^2 / 2 - log s - log(2 pi)/2; -inf for s <= 0.
double normalLogPdf(double y, double m, double s);

/// 3.1: sum_k log N(y_k; f_k, (sigma f_k)^2), f = equilibrium(v, FvK), y = (D, hmin, hmax).
Eigen::VectorXd equilibriumLogLikelihood(const RbcModel& model, const RbcDataSet& data, const Eigen::MatrixXd& theta);
/// 3.2: sum_j log N(D0_j; D0(v, mu, FvK, b2, F_j), sigma0^2) + log N(D1_j; D1(.), sigma1^2),
/// FvK = mu R_A^2 / kb; one batch of n x (number of forces) network evaluations.
Eigen::VectorXd stretchingLogLikelihood(const RbcModel& model, const RbcDataSet& data, const Eigen::MatrixXd& theta);
/// 3.3: sum_k log N(y_k; z(t_k), sigma_z^2) + log N(tc; tc_sim(r), (sigma_tc tc)^2) with
/// Hochmuth's law z(t) and tc_sim(r) = relaxationTime(v = 0.95, mu = 4, FvK = 250, b2 = 1.6, etam = 4 r)
/// (= r g with g = tc mu / etam of the network).
Eigen::VectorXd relaxationLogLikelihood(const RbcModel& model, const RbcDataSet& data, const Eigen::MatrixXd& theta);
/// Dispatch on data.experiment.
Eigen::VectorXd rbcLogLikelihood(const RbcModel& model, const RbcDataSet& data, const Eigen::MatrixXd& theta);

/// Hochmuth's law: z(t) = zinf (L + e^{-t/tc}) / (L - e^{-t/tc}), L = (z0 + zinf) / (z0 - zinf);
/// z(t) = zinf when z0 = zinf.
double hochmuthAspect(double t, double tc, double z0, double zinf);

/// Inert parameters of the relaxation likelihood (3.3, used): v, mu, FvK, b2; etam = 4 r.
inline constexpr double kRelaxationV = 0.95, kRelaxationMu = 4.0, kRelaxationFvK = 250.0, kRelaxationB2 = 1.6;
/// Range of r in which the network input etam = 4 r lies in its training range [0.1, 1].
inline constexpr double kRelaxationRLow = 0.025, kRelaxationRHigh = 0.25;

// ------------------------------------------------------------------------------------------------
// Phase-1 problems and sampler settings

/// The phase-1 TMCMC problem of one data set: phase1Prior and the batched likelihood.
TmcmcProblem phase1Problem(const RbcModel& model, const RbcDataSet& data);

/// The runs of the pipeline (table of docs/BAYESIAN_INFERENCE.md).
enum class RbcRun { Phase1, Phase2, Phase3a, Phase3b };
/// Target CoV and beta^2 of a run; the experiment matters for phases 1 and 3b.
struct RbcSamplerSettings {
    double targetCoV = 0.4;
    double covarianceScaling = 0.06;
    /// Largest population of the run (0: the run's --samples). A flow data set's phase-1 run only
    /// starts the joint MCMC (its starting points and first proposal covariance), and each of its
    /// samples costs tens of network rows, so it is capped.
    int populationCap = 0;
};
RbcSamplerSettings rbcSamplerSettings(RbcRun run, RbcExperiment experiment = RbcExperiment::Equilibrium);

}  // namespace trbc
