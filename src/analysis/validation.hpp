#pragma once
// The flow-validation set of docs/VALIDATE.md: its configuration
// (configs/validation.toml), the cases it expands to, the tumbling/tank-treading bracket and its
// refinement, and the comparison of each prediction with the experimental scatter.
// The cases themselves are `trbc flow shear|tube` runs driven by `trbc validate` (cli/cmd_validate.cpp).
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "analysis/validation_data.hpp"
#include "experiments/parameters.hpp"

namespace trbc {

/// One shear-rate sweep at fixed outer viscosity: `count` rates log-spaced in [rateMin, rateMax].
struct ShearSweep {
    std::string kind;        ///< angle | ttf | threshold
    double etaOut = 0.0;     ///< mPa s
    double rateMin = 0.0, rateMax = 0.0;  ///< 1/s
    int count = 0;
};

struct ValidationConfig {
    std::filesystem::path file;       ///< the TOML file (absolute)
    std::vector<std::filesystem::path> bases;  ///< the configurations it overrides (`base`), nearest first
    std::filesystem::path dataDir;    ///< experimental validation data (shear_flow/, microtube/)
    int level = 2, jobs = 1, threads = 1;
    double stepTol = 1e-3;            ///< local error per step of the shear runs, R_A
    double checkpointInterval = 60.0; ///< wall seconds between a case's snapshots (flow --checkpoint-interval)
    /// Cell: "table1" (the paper's Table 1 means), "posterior" (means of a theta_new posterior) or
    /// "explicit" (the five parameters below).
    std::string cellSource = "table1";
    std::filesystem::path posterior;
    double v = table1::v, mu = table1::mu, kbJ = table1::kbJ, b2 = table1::b2, etam = table1::etam;
    double etaIn = 10.0, rotations = 10.0;  ///< shear flow: cytosol (mPa s), duration in rigid-sphere turns
    double tiltDeg = 0.0;                   ///< shear start turned about the flow axis (`flow shear --tilt-deg`)
    std::vector<ShearSweep> sweeps;         ///< the defaults of docs/VALIDATE.md unless the file gives any [[shear.*]]
    int thresholdRefinements = 2;           ///< bisections of each tumbling/tank-treading bracket
    /// The threshold's protocol (docs/FLOW_THERMAL.md). "in-plane" runs each rate once from the
    /// configured start (in-plane or tilted); "ensemble" runs thresholdMembers members from random
    /// starts (`flow shear --start random --seed k`); "fluctuating" runs thresholdMembers thermally
    /// fluctuating cells from the configured start (`--temperature temperatureK --seed k`). With
    /// members, a rate tank-treads when more than half of its finished members do
    /// (ensembleRegimePoints). The fluctuating cell is the default: a cell at room temperature is
    /// never exactly in the shear plane, and at 100 mPa s it brings the threshold down to the
    /// reference implementation's, whose cell fluctuates too (docs/FLOW_THERMAL.md).
    std::string thresholdProtocol = "fluctuating";
    int thresholdMembers = 3;
    double temperatureK = 293.15;
    bool stopWhenSteady = false;  ///< shear cases stop when steady (`flow shear --stop-when-steady`)
    bool tubeEnabled = true;
    double tubeRadius = 3.3, tubeEtaOut = 1.003, tubeDuration = 30.0;  ///< um, mPa s, R/V (main run)
    double tubeSettle = 60.0;       ///< settling stage: longest R/V (`flow tube --settle`)
    double tubeSettleRelax = 1.5;   ///< its eta_m / mu in R/V (`flow tube --settle-relax`)
    double tubeSettleEtam = 0.0;    ///< > 0: its eta_m in Pa s um instead (`flow tube --settle-etam`)
    double tubeSettleTol = 2e-3;                       ///< `flow tube --settle-tol`
    double tubeStepTol = 0.0;       ///< `flow tube --step-tol`; 0: the command's default ([run] step_tol is the shear's)
    int tubeLevel = 0;                      ///< 0: the run level
    std::vector<double> pressureGradients;  ///< mmHg/mm
};

/// Members per threshold rate: 0 for the in-plane protocol (one run of the configured start).
int thresholdMemberCount(const ValidationConfig& c);

/// Reads and checks a validation config; every error names file:line:key and the valid range.
/// `experiments` resolves the "@experiments/" alias (the shipped data/experiments by default).
ValidationConfig readValidationConfig(const std::filesystem::path& file, const std::filesystem::path& experiments);

/// `count` values log-spaced in [lo, hi] (count 1: lo).
std::vector<double> logSpaced(double lo, double hi, int count);

/// One case of the set: a flow shear or flow tube run.
struct ValidationCase {
    std::string id;      ///< e.g. angle_eta23.9_rate55.4, tube_pg30
    std::string kind;    ///< angle | ttf | threshold | tube
    double etaOut = 0.0, rate = 0.0, pressureGradient = 0.0;
    long sample = -1;    ///< the posterior draw's sample (validation_draws.hpp); -1: the configured cell
    int member = 0;      ///< threshold ensemble member k >= 1 (random start, seed k); 0: the configured start
};

/// The id of member k of an ensemble case: "<id>_m<k>".
std::string memberCaseId(const std::string& caseId, int member);
/// The id without the member's suffix (the id itself for a case of the configured start).
std::string baseCaseId(const ValidationCase& c);

/// The outer viscosities of the threshold sweeps, each once, in the config's order.
std::vector<double> thresholdViscosities(const ValidationConfig& c);

/// The cases of the sweeps and the tube before any refinement, in a fixed order.
std::vector<ValidationCase> initialValidationCases(const ValidationConfig& c);
/// "<kind>_eta<eta>_rate<rate>", the rate to `digits` significant digits (17: exact).
std::string shearCaseId(const std::string& kind, double etaOut, double rate, int digits = 4);
/// The id with the fewest digits (4, 6, 9, 12, exact) that no case of another kind, viscosity or
/// rate in `cases` has: distinct inputs never share an id, and ids stay short where they can.
std::string uniqueShearCaseId(const std::string& kind, double etaOut, double rate, const std::vector<ValidationCase>& cases);
std::string tubeCaseId(double pressureGradient);

/// Part `part` of `parts` (1 <= part <= parts) of the initial cases, for running one set on several
/// machines: the cases are dealt round-robin in units, one unit per angle, TTF or tube case and one
/// per threshold viscosity (its sweep and the refinements that follow from it stay together).
std::vector<ValidationCase> validationShard(const std::vector<ValidationCase>& cases, int part, int parts);
/// "K/N" -> (K, N); an error naming `option` unless 1 <= K <= N.
std::pair<int, int> parseShard(const std::string& text, const std::string& option);

/// Result of a shear case as far as the threshold needs it.
struct RegimePoint {
    double rate = 0.0;
    std::string regime;  ///< tank-treading | tumbling | intermittent | "" (failed)
};

/// The regime of each rate from the regimes of its ensemble members (the points of one rate given
/// once per member): tank-treading when more than half of the members that finished tank-tread,
/// tumbling when fewer than half do, intermittent at exactly half; "" (failed) when none finished.
/// Sorted by rate.
std::vector<RegimePoint> ensembleRegimePoints(const std::vector<RegimePoint>& members);

/// The first line of a failure reason, at most `limit` characters, cut at a word boundary with
/// " ..." when longer, so that a quoted reason never ends in the middle of a word.
std::string shortenedReason(const std::string& reason, std::size_t limit);

/// Threshold bracket (docs/VALIDATE.md): gammaLo = highest rate with tumbling, gammaHi = lowest rate with tank-treading.
struct ThresholdBracket {
    std::optional<double> gammaLo, gammaHi;
    bool monotone = true;                 ///< gammaLo < gammaHi (false: tumbling above tank-treading)
    std::vector<double> intermittentRates;
};
ThresholdBracket thresholdBracket(std::vector<RegimePoint> points);

/// The next rate to run for a bracket: inside [gammaLo, gammaHi] the geometric mean of the widest
/// gap between neighbouring rates already run (intermittent or failed ones included) when it
/// exceeds `minRatio`; 2 max(rates) when nothing tank-treaded yet, min(rates) / 2 when something
/// tank-treaded and nothing tumbled; none otherwise (also when tumbling occurs above
/// tank-treading: reported, not bisected).
std::optional<double> refinementRate(const std::vector<RegimePoint>& points, double minRatio = 1.05);

/// A prediction against the experimental scatter around it.
struct ScatterComparison {
    /// inside | outside | no data | not bracketed (threshold with a one-sided bound) | not monotone
    /// (tumbling above tank-treading) | no prediction (set by the caller: tank-treading without a TTF)
    std::string verdict;
    double lo = 0.0, hi = 0.0;  ///< the scatter interval (valid unless "no data")
    int points = 0;         ///< experimental values in the window
    std::string window;     ///< how the scatter was selected
};

/// Scatter of all y values of the rows with x in [x / factor, x * factor].
ScatterComparison compareWithScatter(double x, double predicted, const ExperimentalPoints& data, double factor);
/// Interval comparison (threshold): the predicted interval [lo, hi] overlaps the data's [min, max]
/// of the rows with x within a relative `tolerance`; "not bracketed" when either bound is missing.
ScatterComparison compareInterval(double x, std::optional<double> lo, std::optional<double> hi, const ExperimentalPoints& data,
                                  double tolerance);
/// Band comparison (tube length): the band [y_low(x), y_high(x)] linearly interpolated in log x
/// between the data rows (y columns: value, high, low); "no data" outside their x range.
ScatterComparison compareWithBand(double x, double predicted, const ExperimentalPoints& data);

/// The critical shear stress interval [eta gamma_lo, eta gamma_hi] in Pa of a bracket at outer
/// viscosity eta in mPa s (a bound is missing where the bracket's is).
std::pair<std::optional<double>, std::optional<double>> criticalStressInterval(const ThresholdBracket& b, double etaOut);

/// The experimental scatter of the flow validations (the judged sets of validationDataSets;
/// docs/VALIDATE.md) and the comparison of each predicted observable with it. Every file is read
/// once, when it is made.
class ValidationEvidence {
public:
    explicit ValidationEvidence(const std::filesystem::path& dataDir);
    /// Inclination [deg] against Fischer 2015 at the same outer viscosity, rates within a factor
    /// 1.5; none where there are no data for that viscosity. A tank-treading cell without an
    /// angle is "no prediction".
    std::optional<ScatterComparison> inclination(double etaOut, double rate, double angleDeg, const std::string& regime) const;
    /// 4 pi f / rate against the donors' TTF, rates within a factor 1.25; a tank-treading cell
    /// without a TTF is "no prediction".
    ScatterComparison tankTreadingFrequency(double rate, double ttf, const std::string& regime) const;
    /// Velocity [cm/s] against Tomaiuolo 2009, pressure gradients within a factor 1.25.
    ScatterComparison tubeVelocity(double pressureGradient, double velocity) const;
    /// Length [um] against the Tomaiuolo band at the predicted velocity.
    ScatterComparison tubeLength(double velocity, double length) const;
    /// Critical stress interval [Pa] against Fischer 2013 and Abkarian 2007, outer viscosities within 10 %.
    ScatterComparison criticalStress(double etaOut, std::optional<double> tauLo, std::optional<double> tauHi) const;
    /// Every set with its points, as experimental_data.json records them (validationDataJson).
    const std::vector<ValidationData>& data() const { return data_; }

private:
    /// The points of the judged set of `observable` (measured at etaOut, when given), blanks
    /// dropped; nullptr when the data have none.
    const ExperimentalPoints* judged(const std::string& observable, std::optional<double> etaOut = std::nullopt) const;
    /// judged(observable), or an InputError naming the data folder.
    const ExperimentalPoints& required(const std::string& observable) const;

    std::filesystem::path dataDir_;
    std::vector<ValidationData> data_;
    std::vector<ExperimentalPoints> judged_;  ///< per set of data_, blanks dropped (empty when not judged)
    ExperimentalPoints critical_;
};

}  // namespace trbc
