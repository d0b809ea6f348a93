#pragma once
// The flow validations over draws of a theta_new posterior (docs/VALIDATE.md and docs/VALIDATION_BANDS.md,
// "Posterior draws"): the seeded choice of the draws, the cases of each draw, the median and the
// 5-95 % band of an observable over the draws, and the band verdict against the experimental
// scatter.
#include <array>
#include <filesystem>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "analysis/validation.hpp"
#include "core/csv.hpp"

namespace trbc {

/// One draw of theta_new: its sample (0-based data row of samples.csv) and its cell.
struct PosteriorDraw {
    long sample = 0;
    double v = 0.0, mu = 0.0, kbJ = 0.0, b2 = 0.0, etam = 0.0;  ///< mu in uN/m, kb in J, etam in Pa s um
};

/// The parameters of theta_new: the columns of its samples.csv and the parameter names of its rows
/// of posterior_stats.csv.
inline constexpr std::array<const char*, 5> kThetaNewColumns = {"v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"};

/// Samples of a theta_new posterior (DIR/samples.csv of `trbc infer`, or the file itself), columns
/// kThetaNewColumns; InputError naming the file and the missing column.
NumericTable readThetaNewSamples(const std::filesystem::path& posterior, const char* option = "--posterior");

/// `n` distinct samples of a theta_new table (columns kThetaNewColumns),
/// chosen by subsampleIndices(rows, n, seed) and listed in sample order. The choice is a partial
/// Fisher-Yates shuffle, so the samples of n draws are among those of any larger n with the same
/// seed. InputError naming `option` and the valid range [1, rows] unless 1 <= n <= rows.
std::vector<PosteriorDraw> selectPosteriorDraws(const NumericTable& samples, int n, std::uint64_t seed,
                                                const std::string& option = "--draws");

/// The row of a threshold viscosity in the band tables: the id threshold_eta<eta>, kind
/// "threshold", no rate.
ValidationCase thresholdBandCase(double etaOut);

/// The id of a case run for one draw: "<case>_sample<row>".
std::string drawCaseId(const std::string& caseId, long sample);

/// Every case followed by its copy for each draw (ValidationCase::sample set, drawCaseId).
std::vector<ValidationCase> casesWithDraws(const std::vector<ValidationCase>& cases, const std::vector<PosteriorDraw>& draws);

/// What one draw gave for one observable.
struct DrawOutcome {
    bool finished = false;  ///< the run gave a result; false: it failed (`reason`)
    double value = std::numeric_limits<double>::quiet_NaN();  ///< NaN: no value (`reason`, e.g. tumbling: no angle)
    std::string reason;
};

/// An observable over the draws.
struct DrawBand {
    int draws = 0, finished = 0, failed = 0, withValue = 0;
    /// Type-7 quantiles 0.5, 0.05, 0.95 (inference/statistics.hpp, quantileSorted) of the finished
    /// draws' values; NaN without any.
    double median = std::numeric_limits<double>::quiet_NaN(), lo = median, hi = median;
    /// Their Monte Carlo standard errors (quantileMcseSorted; the draws are independent, so the
    /// effective sample size is their number); NaN without a value.
    double medianMcse = median, loMcse = median, hiMcse = median;
    /// quantileMcseIsLowerBound at 0.05 or 0.95 (fewer than 19 draws with a value): loMcse and
    /// hiMcse are lower bounds (0.2-0.75x the true spread for 2-10 draws).
    bool endsMcseIsLowerBound = false;
    std::map<std::string, int> reasons;  ///< why draws failed or gave no value, with their counts
};
DrawBand drawBand(const std::vector<DrawOutcome>& outcomes);

/// "N x reason; ..." in the order of the reasons' text ("" when none).
std::string drawReasonsText(const DrawBand& band);

/// The band verdict: "overlap" when [lo, hi] meets the scatter [scatter.lo, scatter.hi]; "no data"
/// without scatter (scatter.points = 0); "no prediction" when no draw finished; when the finished
/// draws gave no value, "no overlap" if `noValueDisagrees` (a tumbling cell where the donors
/// tank-tread, as in the mean-cell verdict), else "no prediction" (no threshold bracketed);
/// "no overlap" otherwise.
std::string bandVerdict(const DrawBand& band, const ScatterComparison& scatter, bool noValueDisagrees = true);

/// Whether the band verdict could flip within the Monte Carlo error of the band's ends: the end
/// that decides it (for an overlap the one nearer to leaving the scatter, else the one facing it)
/// lies within its MCSE of the scatter's edge, or the ends' MCSEs are only lower bounds
/// (endsMcseIsLowerBound). False without a band or without scatter.
bool bandVerdictWithinMcse(const DrawBand& band, const ScatterComparison& scatter);

/// A draw's critical shear stress [Pa] from its threshold cases at outer viscosity etaOut (mPa s):
/// sqrt(tau_lo tau_hi) of criticalStressInterval, the bracket's centre on the log scale on which
/// the refinement bisects it. No value when not bracketed or not monotone (the reason says which);
/// not finished when every case failed.
DrawOutcome criticalStressOutcome(const std::vector<RegimePoint>& points, double etaOut);

}  // namespace trbc
