#pragma once
// The shear-flow campaign (docs/FLOW_CAMPAIGN.md): a design over the cell and the flow, one shear
// case per point (flow/shear_case.hpp: the ensemble protocol's random start by default, stopped at
// the steady state), one CSV row per case with the regime, the inclination, the swing and the TTF
// and their time-series uncertainties; checkpointed per case, resumable, cases shared round robin
// between ranks.
//
// Files in the output directory:
//   campaign.json      provenance: command, version, settings (a resume must match them), final counts
//   parts/rank<r>.csv  the checkpoint of rank r (sampling/part_file.hpp), one row per finished case
//   cases.csv          every case sorted by case id, written once all cases are done
//   by_turn/case<id>.json  with fullLength only: the observables up to every whole turn
// A run killed at any moment and restarted with resume loses no finished case and repeats none: a
// case counts as done when its whole row, with the design's inputs, is in a part file.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "flow/shear_observables.hpp"
#include "sampling/campaign.hpp"
#include "sampling/shear_campaign_table.hpp"

namespace trbc {

struct ShearCampaignOptions {
    DesignKind design = DesignKind::Sobol;
    long cases = 100;
    std::uint64_t seed = 1;
    int level = 3;
    double maxRotations = 10.0;  ///< the longest a case runs; it stops earlier once steady (unless fullLength)
    SteadyStopRule steadyRule;   ///< when a case is steady (flow/shear_observables.hpp); unused with fullLength
    /// Every case runs maxRotations (whole) turns and records turn by turn what a run stopped there
    /// would see and report, in by_turn/case<id>.json (flow/steady_rule_study.hpp), to measure stop
    /// rules against full runs
    bool fullLength = false;
    bool randomStart = true;     ///< the ensemble protocol's start; false: the disc in the shear plane
    double etaIn = 10.0;         ///< mPa s
    int threads = 1;             ///< cases run concurrently, one thread each
    int ranks = 1;               ///< provenance only
    std::filesystem::path outDir, cacheDir;
    bool resume = false;
    std::set<long> injectFailures;  ///< case ids that fail on purpose (tests)
    std::string command;
    std::function<void(const CampaignProgress&)> progress;  ///< after every case (serialised); "cells" are cases
};

/// One case (never throws for a numerical failure: status "failed" with the reason).
ShearCampaignRow runShearCampaignCase(const ShearCampaignPoint& point, const ShearCampaignOptions& o, bool injectFailure = false);

/// Creates the output directory and the provenance, or checks that a resume has the same settings
/// (a Sobol' or uniform design grows: a larger case count extends it). Once, before any rank runs.
void prepareShearCampaign(const ShearCampaignOptions& o);
/// Runs the unfinished cases of `rank` (case id modulo ranks), appending to parts/rank<rank>.csv.
CampaignSummary runShearCampaignShare(const ShearCampaignOptions& o, int rank = 0, int ranks = 1);
/// Writes cases.csv when every case is done, and the final counts. Once, after all ranks.
CampaignSummary finalizeShearCampaign(const ShearCampaignOptions& o, double wallSeconds);
/// prepare + share + finalize in one process.
CampaignSummary runShearCampaign(const ShearCampaignOptions& o);

}  // namespace trbc
