#pragma once
// The shear validations through the flow networks (docs/FLOW_NETWORKS.md, "Bands through the
// networks"): every angle, TTF and threshold case of a validation config predicted for many draws
// of a theta_new posterior by surrogate/flow_surrogate.hpp in seconds, with the band over the draws,
// its Monte Carlo error and its verdict against the experimental scatter, as the direct draws of
// `trbc validate --draws` have them.
//
// Per draw: the cell tank-treads when the network's probability exceeds 1/2 (the ensemble
// protocol's majority, as ensembleRegimePoints scores direct runs); then its angle and TTF are the
// regressors', otherwise the draw has no value ("tumbling"). Its critical stress is where the
// probability crosses 1/2 along the stress axis (FlowSurrogate::criticalStressPa); no value when it
// does not cross inside the campaign's stress range.
#include <string>
#include <vector>

#include "analysis/validation.hpp"
#include "analysis/validation_draws.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {

struct SurrogateBandRow {
    ValidationCase c;         ///< an angle or TTF case; a threshold viscosity has the id threshold_eta<eta> and no rate
    std::string observable;   ///< "inclination [deg]", "4 pi f / rate", "critical stress [Pa]"
    DrawBand band;
    ScatterComparison scatter;
    std::string verdict;      ///< bandVerdict
    bool withinMcse = false;  ///< bandVerdictWithinMcse
    long outsideBox = 0;      ///< draws whose inputs lie outside the campaign's box (the networks extrapolate)
    double meanPTankTreading = NAN;  ///< over the draws (angle and TTF cases)
};

/// What the networks give each draw for case c, the cytosol at etaIn (mPa s): for an angle or TTF
/// case the regressor's value where the probability of tank-treading exceeds 1/2, else no value;
/// for a threshold case (thresholdBandCase) the critical stress at c.etaOut, no value where the
/// probability does not cross 1/2 in the campaign's stress range. `prediction`, when given, receives
/// the networks' outputs of an angle or TTF case.
std::vector<DrawOutcome> networkDrawOutcomes(const FlowSurrogate& model, const std::vector<PosteriorDraw>& draws, const ValidationCase& c,
                                             double etaIn, FlowPrediction* prediction = nullptr);

/// The bands of every angle, TTF and threshold case of `cfg` (tube cases are not predicted).
std::vector<SurrogateBandRow> surrogateShearBands(const ValidationConfig& cfg, const FlowSurrogate& model,
                                                  const std::vector<PosteriorDraw>& draws, const ValidationEvidence& evidence);

/// The rows as CSV (one per case and observable) and as a Markdown table with the verdict counts.
std::string surrogateBandsCsv(const std::vector<SurrogateBandRow>& rows);
std::string surrogateBandsMarkdown(const std::vector<SurrogateBandRow>& rows);

}  // namespace trbc
