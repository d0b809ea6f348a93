#pragma once
// The flow networks (docs/FLOW_NETWORKS.md, networks): trained on a shear campaign
// (sampling/shear_campaign_table.hpp) with the MLPs, schedule and restarts of the cell surrogate.
//
//  * regime: the flow's groups of (v, mu, FvK, b2, eta_m, eta_out, rate) -> the probability that the
//    cell tank-treads.
//    Trained on the labels 1 (tank-treading) and 0 (tumbling or intermittent) with the squared
//    error, i.e. the Brier score: its minimiser is P(tank-treading | inputs), here over the
//    campaign's random starts (the ensemble protocol), so the network is a probability without a
//    second loss function. Evaluated values are clipped to [0, 1].
//  * tank-treading: the same inputs -> (inclination_deg, swing_deg, ttf = 4 pi f / rate), trained
//    on the tank-treading cases; TTF on a log scale.
// The networks see the flow's dimensionless groups (flowNetworkInput), not the seven physical inputs:
// every membrane modulus is proportional to mu at fixed FvK and b2 (Kalpha = mu, kb = mu R_A^2 /
// FvK), so the cell at (s mu, s rate) runs the same flow at the same strains, and the observables
// depend on six numbers. Removing that direction lowers the cross-validated angle error by 5-8 %
// at the same cases (docs/FLOW_NETWORKS.md). The identity is exact for the deterministic in-plane
// start; a random start's thermal kick, of amplitude sqrt(kT / kb), is a seventh number that the
// regime network does not see. FvK, Ca, the viscosity ratio and Bq enter as logarithms.
//
// The campaign holds the cytosol at one viscosity (10 mPa s). A cell at another eta_in is the same
// flow as the campaign's cell with every viscosity (eta_in, eta_out, eta_m) scaled by s = 10 / eta_in
// and the rate by 1 / s: Stokes flow and the membrane forces then give the same shapes at the same
// strains, so the angle, the swing, the TTF in units of the rate and the regime are unchanged.
#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "sampling/shear_campaign_table.hpp"
#include "surrogate/training.hpp"

namespace trbc {

/// v, mu_uN_per_m, FvK, b2, etam_Pa_s_um, eta_out_mPa_s, shear_rate_per_s
const std::vector<std::string>& flowSurrogateInputNames();

/// The networks' inputs, the dimensionless groups of the flow: v, FvK, b2, the capillary number
/// Ca = eta_out rate R_A / mu, the viscosity ratio eta_in / eta_out and the Boussinesq number
/// Bq = eta_m / (eta_out R_A).
const std::vector<std::string>& flowNetworkInputNames();
/// The network input (flowNetworkInputNames, from flowGroups) of one column of physical inputs
/// (flowSurrogateInputNames) at the cytosol viscosity etaInMPaS.
Eigen::Matrix<double, 6, 1> flowNetworkInput(const Eigen::Ref<const Eigen::Matrix<double, 7, 1>>& x, double etaInMPaS);

/// The name of the last input of multi-level networks.
inline constexpr const char* kFlowLevelInput = "mesh_level";

/// Per column of the inputs.
struct FlowPrediction {
    Eigen::VectorXd pTankTreading;
    Eigen::VectorXd inclinationDeg, swingDeg, ttf;  ///< of the tank-treading state (extrapolated where it does not exist)
    std::vector<bool> outsideBox;                   ///< the input lies outside the campaign's box (kShearCampaignAxes)
};

/// Campaigns at several mesh levels train one pair of networks with the level as a last input
/// (multi-fidelity: the cheap level's many cases carry the shape of the functions, the paired
/// cases of the finer level their offset); the networks answer at the finest level.
struct FlowSurrogate {
    TrainedNetwork regime;        ///< 6 groups (and the level) -> 1, flow_regime.json
    TrainedNetwork tankTreading;  ///< 6 groups (and the level) -> 3, flow_tank_treading.json
    double etaIn = 10.0;          ///< the campaign's cytosol viscosity, mPa s (flow_surrogate.json)
    std::vector<int> levels;      ///< the mesh levels of the training campaigns (empty: one, unrecorded)
    int level = 0;                ///< the level the predictions are for: the finest of `levels`
    /// The regime network's campaign start, "random" or "in-plane" (flow_surrogate.json); empty when
    /// not recorded. It is the threshold protocol the regime network answers for: random starts are
    /// the ensemble.
    std::string start;
    /// The tank-treading network's campaign start. Campaigns of both starts train the regime on the
    /// random ones and the angle, swing and TTF on the in-plane ones, the start of `validate`'s
    /// angle and TTF runs; with one start both networks share it. Empty when not recorded.
    std::string tankTreadingStart;

    bool multiLevel() const { return levels.size() > 1; }
    /// flowNetworkInputNames, with kFlowLevelInput when multiLevel.
    std::vector<std::string> inputNames() const;
    /// The networks' inputs: the groups (flowNetworkInput at etaIn) of the 7 physical rows, with the row
    /// of `level` appended when multiLevel.
    Eigen::MatrixXd networkInputs(const Eigen::Ref<const Eigen::MatrixXd>& x7) const;

    /// Reads the files of `dir`; InputError naming the file when one is missing or bad.
    static FlowSurrogate load(const std::filesystem::path& dir);
    /// The networks of `dir` as a likelihood sees them: fingerprintOf the two networks, their
    /// cytosol and inputs (flow_surrogate.json) and the errors of training.json.
    static std::string fingerprint(const std::filesystem::path& dir);
    void save(const std::filesystem::path& dir) const;

    /// x: 7 x n physical inputs (flowSurrogateInputNames), etaIn: the cytosol viscosity of each
    /// column (mPa s), mapped to the campaign's by the exact rescaling above.
    FlowPrediction predict(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::Ref<const Eigen::VectorXd>& etaIn) const;
    /// The campaign's eta_in for every column.
    FlowPrediction predict(const Eigen::Ref<const Eigen::MatrixXd>& x) const;

    /// The shear stress eta_out * rate (Pa) at which the probability of tank-treading crosses 1/2,
    /// at the cell and eta_out of each column of x (the rate row is ignored), by bisection in log
    /// stress over the campaign's stress range; NaN where it does not cross inside that range, or
    /// with `clampToRange` the range's end on the side where the crossing lies (the low end when
    /// the cell tank-treads over the whole range, the high end when it never does). `etaIn`: the
    /// cytosol viscosity of each column (mPa s), mapped to the campaign's by the exact rescaling
    /// above, which leaves the critical stress unchanged (every viscosity times s: tau = eta_out rate).
    Eigen::VectorXd criticalStressPa(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::Ref<const Eigen::VectorXd>& etaIn,
                                     double probability = 0.5, bool clampToRange = false) const;
    /// The campaign's eta_in for every column.
    Eigen::VectorXd criticalStressPa(const Eigen::Ref<const Eigen::MatrixXd>& x, double probability = 0.5,
                                     bool clampToRange = false) const;
};

/// The threshold protocol whose regime the networks give: "ensemble" (random starts), "in-plane",
/// or "not recorded".
std::string flowSurrogateProtocol(const FlowSurrogate& s);

/// One column of inputs, in flowSurrogateInputNames order.
Eigen::Matrix<double, 7, 1> flowInput(const CellParameters& cell, double etaOutMPaS, double shearRatePerS);
/// Inputs (7 x n) of campaign rows.
Eigen::MatrixXd flowInputs(const std::vector<const ShearCampaignRow*>& rows);


/// The cell surrogates' training options with one hidden layer of 32: on the shipped campaigns
/// (287 random, 537 in-plane cases, the six groups, 16 restarts), 5-fold CV of 8, 16, 32, 16-16 and
/// 32-32-32 gives 32 the lowest angle and TTF errors; the deeper networks overfit, and the
/// misclassification is the same for all within its noise (docs/FLOW_NETWORKS.md).
inline TrainingOptions flowNetworkDefaults() {
    TrainingOptions o;
    o.hiddenLayers = {32};
    return o;
}

struct FlowSurrogateTrainingOptions {
    TrainingOptions network = flowNetworkDefaults();  ///< layers, seeds and schedule (scaled to the rows, scheduleForRows)
    /// Trainings per network from seeds seed, seed+1, ...; the best is kept. 16: on the shipped
    /// campaigns their mean has an 8 % lower CV angle error than 4, at 1 s of training.
    int restarts = 16;
    bool ensemble = true;     ///< the other restarts become ensemble members (mean prediction)
    double testFraction = 0.1;
    std::uint64_t testSeed = 20261129;
    /// k-fold cross-validation: the test cases are those at positions p of the seeded case
    /// permutation with p % folds == fold (testFraction is then not used).
    int folds = 0, fold = 0;
    /// A test case is near the regime boundary when its stress lies within this factor of the
    /// regressor's critical stress at its cell and eta_out (one bracket step of the threshold scans).
    double boundaryFactor = 1.5;
    std::string command;
};

/// The accuracy the flow networks are built for: the angle and the TTF within the campaign's
/// resolution of the validation data, and the regime right almost everywhere away from the boundary.
struct FlowAccuracyGoals {
    double inclinationRmseDeg = 0.3;
    double ttfRelativeRmse = 0.02;
    double farMisclassifiedFraction = 0.03;  ///< of the cases more than boundaryFactor from the boundary
};
inline constexpr FlowAccuracyGoals kFlowAccuracyGoals{};

/// Accuracy on held-out cases.
struct FlowAccuracy {
    long cases = 0;            ///< finished test cases
    long tankTreading = 0;     ///< of them tank-treading (the regressors' test set)
    double inclinationRmseDeg = NAN, swingRmseDeg = NAN;
    double ttfRelativeRmse = NAN;  ///< sqrt(mean (pred / truth - 1)^2)
    /// The same on the cases the steady-state rule stopped (their values move by less than the
    /// rule's tolerances between the last two turns), and the campaign's own uncertainty: the RMS
    /// of the rows' *_se over the tank-treading test cases, a floor no network can beat.
    long steady = 0;
    double inclinationRmseSteadyDeg = NAN, ttfRelativeRmseSteady = NAN;
    double inclinationNoiseDeg = NAN, ttfRelativeNoise = NAN;
    double brier = NAN;            ///< mean (p - label)^2
    long far = 0, farMisclassified = 0;    ///< more than boundaryFactor from the critical stress (or none)
    long near = 0, nearMisclassified = 0;  ///< within it
};

/// The accuracy of `model` on `rows` (finished ones only): the regime on the rows of the model's
/// start, the observables on those of its tank-treading start; a row or model without a recorded
/// start counts for both.
FlowAccuracy flowAccuracy(const FlowSurrogate& model, const std::vector<const ShearCampaignRow*>& rows, double boundaryFactor);

/// A held-out row predicted by the fold that held it out: the regime network's rows carry the
/// probability and the critical stress, the tank-treading network's the observables (NaN where a
/// network does not take the row). With one start a row is both networks'.
struct FlowHeldOutPrediction {
    ShearCampaignRow row;
    int fold = 0;
    bool regime = false, tankTreading = false;  ///< the row is held out of that network
    double pTankTreading = NAN, criticalStressPa = NAN;
    double inclinationDeg = NAN, swingDeg = NAN, ttf = NAN;
};

struct FlowSurrogateTrainingReport {
    FlowSurrogate model;
    std::string dataHash;
    long rows = 0, used = 0, testCases = 0;
    long regimeRows = 0, tankTreadingRows = 0;  ///< training rows of each network
    FlowAccuracy test;
    std::vector<FlowHeldOutPrediction> heldOut;  ///< the test rows' predictions (fold = opt.fold), from which `test` follows
    double wallSeconds = 0.0;
};

/// Trains both networks on the finished rows outside the test set. Rows of several mesh levels
/// (ShearCampaignRow::meshLevel) train multi-level networks; the test set and the accuracy are
/// then those of the finest level's cases, and every coarser case trains. Rows of both starts (the
/// same design run from random and from in-plane starts) train the regime on the random rows and
/// the tank-treading network on the in-plane ones; the test set is a set of case ids, so a held-out
/// case is out of both. InputError when a network has fewer than 20 finished cases at the finest
/// level, when training holds fewer than 10 tank-treading rows with values or lacks a tank-treading
/// or an other regime row, or when the two starts' rows span different mesh levels.
FlowSurrogateTrainingReport trainFlowSurrogate(const std::vector<ShearCampaignRow>& rows, const FlowSurrogateTrainingOptions& opt);

struct FlowCrossValidation {
    int folds = 0;
    long rows = 0;
    FlowAccuracy pooled;                 ///< every case predicted by the fold that held it out
    std::vector<FlowAccuracy> perFold;
    std::vector<FlowHeldOutPrediction> predictions;  ///< every held-out row, in fold order
};
FlowCrossValidation crossValidateFlowSurrogate(const std::vector<ShearCampaignRow>& rows, FlowSurrogateTrainingOptions opt, int folds);

/// One network in place of each ensemble, for callers that evaluate the networks millions of times
/// (the flow likelihood of `trbc infer`): one pass instead of one per member. The student learns
/// the ensemble's mean at points of the campaign's box (kShearCampaignAxes, where the ensemble was
/// trained and is defined), so its error against the data is the ensemble's plus its own, which
/// compareFlowSurrogates measures on points it never saw.
/// The defaults make the shipped data/surrogates/flow_distilled: against the ensemble, 32-32 is off
/// by 0.10 deg in the angle and 0.5 % in the TTF at 5x the speed; one layer of 64 by 0.12 deg and
/// 0.6 %, 64-64 by 0.06 deg at the ensemble's cost; 100,000 points learn as well as 400,000
/// (docs/CALIBRATION_WITH_FLOWS.md).
struct FlowDistillationOptions {
    long samples = 100000;                ///< training points: the first of a Sobol' design of seed `seed`
    std::uint64_t seed = 20261201;
    std::vector<int> hiddenLayers = {32, 32};
    long checkSamples = 20000;            ///< comparison points: a uniform design of seed `seed` + 1
    std::uint64_t trainingSeed = 1;       ///< initial weights and mini-batch order
    std::string command;                  ///< recorded in the student networks' files
};

/// Student against teacher at the same points.
struct FlowDistillationCheck {
    long points = 0;
    long tankTreading = 0;          ///< points where the teacher's probability of tank-treading is >= 1/2
    double probabilityRmse = NAN;   ///< of the probability of tank-treading, every point
    double regimeDisagreement = NAN;  ///< share of points on different sides of probability 1/2
    /// Where the teacher tank-treads: RMS of student - teacher, and of student / teacher - 1 for the TTF.
    double inclinationRmseDeg = NAN, swingRmseDeg = NAN, ttfRelativeRmse = NAN;
};

/// x7: 7 x n physical inputs (flowSurrogateInputNames) at the models' cytosol viscosity.
FlowDistillationCheck compareFlowSurrogates(const FlowSurrogate& student, const FlowSurrogate& teacher,
                                            const Eigen::Ref<const Eigen::MatrixXd>& x7);

/// n points of a design over kShearCampaignAxes as physical inputs (7 x n), the cytosol at etaIn.
Eigen::MatrixXd flowDesignInputs(DesignKind kind, long n, std::uint64_t seed, double etaIn);

struct FlowDistillation {
    FlowSurrogate model;
    FlowDistillationCheck check;
    double wallSeconds = 0.0;
};

/// Both networks of `teacher` distilled (the two trainings run concurrently). InputError for a
/// multi-level teacher (its level input would be a constant), a teacher without ensemble members or
/// distilled already, fewer than 1,000 samples or 100 check samples, or an empty hidden layer list.
FlowDistillation distillFlowSurrogate(const FlowSurrogate& teacher, const FlowDistillationOptions& opt);

/// training.json of a distilled model: the teacher's (its cross-validated accuracy, command and
/// build stay the ensemble's) with a `distillation` block: the options, the check, `command` and
/// this binary's build (withBuild).
nlohmann::json flowDistillationJson(const nlohmann::json& teacherTraining, const FlowDistillationOptions& opt,
                                    const FlowDistillation& d, const std::string& teacherDir, const std::string& command);

/// FNV-1a of the formatted rows.
std::string flowCampaignDataHash(const std::vector<ShearCampaignRow>& rows);

/// Campaigns trained together differ at most in level, size and start: every setting of their
/// campaign.json other than level, cases, start and inject_failures is the same (box, design, seed
/// so that their cases pair, cytosol, stopping rule). Each entry is a campaign directory or a file in
/// it (its cases.csv); an entry without a campaign.json is not compared, nor is a single entry.
/// InputError naming the campaign and the first setting that differs from the first campaign's.
void checkShearCampaignsMatch(const std::vector<std::filesystem::path>& campaigns);

/// The rows of a learning-curve point: the first n cases (by case id) of mesh level `level`, followed
/// by every row of the other levels, which all stay in training; with two starts, both rows of each
/// of the first n case ids. InputError when `level` has fewer than n distinct cases.
std::vector<ShearCampaignRow> flowLearningCurveRows(const std::vector<ShearCampaignRow>& rows, int level, long n);

/// The accuracy as training.json records it; a statistic without cases is null.
nlohmann::json flowAccuracyJson(const FlowAccuracy& a);
/// A row of the accuracy table of accuracy.md, the set named `label`.
std::string flowAccuracyRow(const std::string& label, const FlowAccuracy& a);

/// A campaign read for a training, as training.json and accuracy.md name it.
struct FlowTrainingSource {
    std::string campaign;   ///< as given
    long cases = 0;
    int level = 0;          ///< 0: not recorded
    bool complete = true;   ///< false: the finished cases of a campaign still running
};

/// Cross-validated accuracy on the first `cases` cases of the design (flowLearningCurveRows).
struct FlowLearningCurvePoint {
    long cases = 0;
    FlowAccuracy pooled;
};

/// A learning curve over `rows`: for each size n of `sizes`, in their order, the pooled accuracy of
/// `folds`-fold cross-validation on flowLearningCurveRows(rows, level, n), the cases of `level`
/// sorted once for all sizes. A size above the level's case count is not a point but is listed in
/// `skipped`; InputError for a negative size or from the cross-validation.
struct FlowLearningCurve {
    std::vector<FlowLearningCurvePoint> points;
    std::vector<long> skipped;  ///< sizes above `available`, in their order
    long available = 0;         ///< distinct cases of `level`
};
FlowLearningCurve flowLearningCurve(const std::vector<ShearCampaignRow>& rows, int level, const std::vector<long>& sizes,
                                    const FlowSurrogateTrainingOptions& opt, int folds);

/// Everything training.json and accuracy.md report.
struct FlowTrainingSummary {
    std::vector<FlowTrainingSource> sources;
    FlowSurrogateTrainingOptions options;  ///< command, restarts, ensemble, boundaryFactor, testFraction
    FlowSurrogateTrainingReport training;
    std::optional<FlowCrossValidation> crossValidation;
    /// Present when a curve was asked for, empty when every size exceeded the campaign.
    std::optional<std::vector<FlowLearningCurvePoint>> learningCurve;
    int learningCurveFolds = 5;
};

/// training.json (with withBuild's identity of this binary).
nlohmann::json flowTrainingJson(const FlowTrainingSummary& s);
/// accuracy.md: the held-out (and cross-validated) accuracy, then the learning curve.
std::string flowAccuracyMarkdown(const FlowTrainingSummary& s);
/// cv_predictions.csv: one line per held-out row with its inputs, start, regime, steady flag, the
/// campaign's values and the fold's predictions.
std::string flowCrossValidationCsv(const FlowCrossValidation& cv);
/// Writes dir/training.json and dir/accuracy.md (and dir/cv_predictions.csv with a cross-validation),
/// each atomically; returns accuracy.md's text.
std::string writeFlowTrainingReport(const std::filesystem::path& dir, const FlowTrainingSummary& s);

}  // namespace trbc
