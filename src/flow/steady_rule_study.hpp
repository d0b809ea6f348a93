#pragma once
// What a steady-state stop rule (SteadyStopRule) costs and changes, measured on full-length runs:
// a campaign run with `trbc flow campaign --full-length` records, per case and whole rigid-sphere
// turn k, what a run stopped at turn k would have seen and reported (by_turn/case<id>.json). A rule
// stops a case at the first turn k >= minRotations whose rule observables agree with those of turn
// k - 1 (steadyBetween), so every candidate rule is evaluated on the same runs without running them
// again, with the observables the stopped run reports. The cost of a stop is the share of the full
// run's GMRES iterations (the boundary-integral products that dominate a step) of the accepted
// steps up to it; rejected steps are not counted.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "flow/cell_flow.hpp"
#include "flow/shear_observables.hpp"

namespace trbc {

/// Turn k of a full run as a run stopped there sees it. shearSteadyStateReached looks at turn k after
/// the step that records the first frame at or after turn k; a run stopped there ends with that
/// step and analyses every frame it recorded, which can be one more than the rule compared.
struct TurnRecord {
    int turn = 0;
    long steps = 0, gmresIterations = 0;  ///< accepted steps up to the end of the stopping step, their GMRES iterations
    ShearObservables rule;                ///< the frames up to the turn: what the rule compares
    ShearObservables stop;                ///< the frames up to the end of the stopping step: what the run reports
    // Read back from JSON, both hold the regime, inclination, swing and TTF only.
};

/// The by-turn records of a finished run (times of `flow` in units of 1/rate); the last whole turn's
/// `stop` is the analysis of the whole run.
std::vector<TurnRecord> turnRecords(const CellFlowResult& flow);
/// by_turn/case<id>.json: {"case": id, "turns": [{turn, steps, gmres_iterations, "rule": {regime,
/// inclination_deg, swing_deg, ttf_4pi_f_over_rate}, "stop": {...}}]}, a NaN or undefined value as null.
nlohmann::json turnRecordsJson(long caseId, const std::vector<TurnRecord>& turns);

struct FullLengthCase {
    long caseId = 0;
    std::vector<TurnRecord> turns;
};
/// Every by_turn/case<id>.json of a campaign directory, by case id; InputError naming the file for a
/// damaged one (also: a case id other than its name's, no turns, turns not increasing), or the
/// directory when it holds none.
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

/// InputError naming `option` unless the first turn is in [2, lastTurn], the angle tolerance in
/// (0, 10] deg and the TTF tolerance in (0, 0.5].
void validateSteadyRule(const SteadyStopRule& rule, double lastTurn, const std::string& option);

/// Markdown table of the effects, one row per rule ("–" where no case enters a column).
std::string steadyRuleTable(const std::vector<SteadyRuleEffect>& effects);

/// The line above the table: "N full-length cases (level L, design D, seed S, T turns)" from the
/// campaign's campaign.json, or "N full-length cases of FOLDER" when it has none (not the
/// campaign's path, which is a machine's).
std::string steadyRuleStudyTitle(const std::filesystem::path& campaignDir, std::size_t cases);

}  // namespace trbc
