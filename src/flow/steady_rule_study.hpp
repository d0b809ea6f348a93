#pragma once
// What a steady-state stop rule (SteadyStopRule) costs and changes, measured on full-length runs:
// a campaign run with `trbc flow campaign --full-length` records, per case, the observables of the
// frames up to every whole rigid-sphere turn (by_turn/case<id>.json). A rule stops a case at the
// first turn k >= minRotations whose observables agree with turn k - 1 (steadyBetween), so every
// candidate rule is evaluated on the same runs without running them again. The cost of a stop is
// the share of the full run's GMRES iterations (the boundary-integral products that dominate a
// step) spent up to that turn.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "flow/cell_flow.hpp"
#include "flow/shear_observables.hpp"

namespace trbc {

/// The observables up to one whole turn and the work done to reach it.
struct TurnRecord {
    int turn = 0;
    long steps = 0, gmresIterations = 0;  ///< accepted steps and their GMRES iterations up to the turn
    ShearObservables observables;         ///< regime, inclination, swing and TTF (the other fields unset when read)
};

/// The by-turn records of a finished run (times of `flow` in units of 1/rate).
std::vector<TurnRecord> turnRecords(const CellFlowResult& flow);
/// by_turn/case<id>.json: {"case": id, "turns": [{turn, steps, gmres_iterations, regime, inclination_deg,
/// swing_deg, ttf_4pi_f_over_rate (null when undefined)}]}.
nlohmann::json turnRecordsJson(long caseId, const std::vector<TurnRecord>& turns);

struct FullLengthCase {
    long caseId = 0;
    std::vector<TurnRecord> turns;
};
/// Every by_turn/case<id>.json of a campaign directory, by case id; InputError naming the file for a
/// damaged one, or the directory when it holds none.
std::vector<FullLengthCase> readFullLengthCases(const std::filesystem::path& campaignDir);

/// The effect of one rule on the full-length cases.
struct SteadyRuleEffect {
    SteadyStopRule rule;
    int cases = 0;        ///< cases with at least minRotations turns
    int stopped = 0;      ///< cases the rule stops before their last turn
    double meanTurns = 0.0;      ///< turns run, stopped or not
    double costFraction = 0.0;   ///< summed GMRES iterations up to the stops / those of the full runs
    int regimeChanged = 0;       ///< cases whose regime at the stop differs from the full run's
    int tankTreading = 0;        ///< cases tank-treading at both
    double angleRmsDeg = 0.0, angleMaxDeg = 0.0;  ///< inclination at the stop minus the full run's
    double swingRmsDeg = 0.0, swingMaxDeg = 0.0;
    double ttfRelRms = 0.0, ttfRelMax = 0.0;      ///< TTF at the stop / the full run's - 1
};
SteadyRuleEffect steadyRuleEffect(const std::vector<FullLengthCase>& cases, const SteadyStopRule& rule);

/// Markdown table of the effects, one row per rule.
std::string steadyRuleTable(const std::vector<SteadyRuleEffect>& effects);

}  // namespace trbc
