#pragma once
// The flow networks against direct runs of the same posterior draws (docs/FLOW_NETWORKS.md,
// "Cross-check against direct runs"): a finished `trbc validate --draws N` run is read back
// (ValidationRunner::loadOnly), and each of its angle, TTF and threshold cases is compared with
// the networks
//  * at the same draws, pair by pair: how often both give a value (a tank-treading cell, a
//    bracketed threshold) or both none, and the mean and RMS of network - direct over the draws
//    where both give one;
//  * over the many draws of the surrogate bands: the share of draws with a value, the median and
//    the 5-95 % band against the direct ones, each within kCrossCheckSigmas of the two Monte Carlo
//    errors combined. The quantiles are compared from kCrossCheckMinValues values in each band on,
//    the ends only where neither band's end errors are lower bounds (fewer than 19 values: 16
//    direct draws compare the share and the median).
#include <string>
#include <vector>

#include "analysis/validation_draws.hpp"
#include "analysis/validation_runner.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {

inline constexpr double kCrossCheckSigmas = 2.0;
inline constexpr int kCrossCheckMinValues = 3;

struct FlowCrossCheckRow {
    ValidationCase c;        ///< an angle or TTF case, or a threshold viscosity (thresholdBandCase)
    std::string observable;  ///< "inclination [deg]", "4 pi f / rate", "critical stress [Pa]"
    DrawBand direct;         ///< the direct runs of the draws
    DrawBand networkPaired;  ///< the networks at the draws the direct run finished
    DrawBand network;        ///< the networks over the surrogate bands' draws
    int pairs = 0, pairsAlike = 0;  ///< draws both finished; of them, both with a value or both without
    int paired = 0;                 ///< draws with a value from both
    double meanDifference = NAN, rmsDifference = NAN;  ///< network - direct over them
    bool agrees = false;            ///< the share with a value, the median and both ends agree (see above)
    std::string note;               ///< what differs, and by how many combined MC errors
};

/// The comparison of one observable: `direct` and `networkPaired` are the outcomes of the same
/// draws in the same order, `network` the band of the networks over many draws. The share with a
/// value agrees when it differs by at most kCrossCheckSigmas binomial standard errors of the two
/// shares combined (the pooled share); a quantile when |network - direct| is at most
/// kCrossCheckSigmas sqrt(mcse_network^2 + mcse_direct^2). The note names what was not compared.
FlowCrossCheckRow compareWithDirect(const ValidationCase& c, std::string observable, const std::vector<DrawOutcome>& direct,
                                    const std::vector<DrawOutcome>& networkPaired, const DrawBand& network);

/// Every angle and TTF case and every threshold viscosity of the direct run's configuration that
/// holds at least one complete draw (its record; for a threshold every rate and member), against
/// `model` at those draws and over `manyDraws`, the cytosol of that configuration.
std::vector<FlowCrossCheckRow> flowCrossCheck(const ValidationRunner& direct, const FlowSurrogate& model,
                                              const std::vector<PosteriorDraw>& manyDraws);

/// The rows as CSV (one per case and observable) and as Markdown with the agreeing count per kind.
std::string flowCrossCheckCsv(const std::vector<FlowCrossCheckRow>& rows);
std::string flowCrossCheckMarkdown(const std::vector<FlowCrossCheckRow>& rows);

}  // namespace trbc
