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
// A run killed at any moment and restarted with resume loses no finished case and repeats none: a
// case counts as done when its whole row, with the design's inputs, is in a part file.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "experiments/parameters.hpp"
#include "sampling/campaign.hpp"
#include "sampling/design.hpp"

namespace trbc {

/// One input of the design: uniform in [lo, hi], or log-uniform when logScale.
struct DesignAxis {
    const char* name;
    double lo, hi;
    bool logScale;
};

/// The design's inputs, in design order: the cell (v, mu, FvK, b2, eta_m) and the flow (outer
/// viscosity, shear stress eta_out * rate). The box holds the prior box of the cell and the 1-99 %
/// range of the theta_new population, and every shear validation set (eta_out 10.7-104 mPa s,
/// stresses 0.02-7.6 Pa); docs/FLOW_CAMPAIGN.md gives the reasons for each range.
inline constexpr DesignAxis kShearCampaignAxes[7] = {
    {"v", 0.65, 1.0, false},
    {"mu_uN_per_m", 1.0, 12.0, true},
    {"FvK", 10.0, 2000.0, true},
    {"b2", 0.0, 8.0, false},
    {"etam_Pa_s_um", 0.05, 2.5, true},
    {"eta_out_mPa_s", 8.0, 130.0, true},
    {"shear_stress_Pa", 0.01, 10.0, true},
};

struct ShearCampaignPoint {
    long caseId = 0;
    CellParameters cell;
    double etaOut = 0.0;      ///< mPa s
    double shearRate = 0.0;   ///< 1/s
    double etaIn = 10.0;      ///< mPa s
    std::uint64_t startSeed = 0;  ///< of the random start (ShearCaseOptions::seed)
};

/// `n` points of a design of `kind` over kShearCampaignAxes (ids 0..n-1); each case's start seed
/// is derived from (seed, case id).
std::vector<ShearCampaignPoint> shearCampaignDesign(DesignKind kind, long n, std::uint64_t seed, double etaIn = 10.0);

struct ShearCampaignRow {
    ShearCampaignPoint point;
    std::string regime;  ///< tank-treading, tumbling, intermittent; empty when the case failed
    /// Tank-treading only (NaN otherwise): the observables of flow/shear_observables.hpp and their
    /// uncertainty, the change of each when the last whole rigid-sphere turn is dropped from the
    /// analysed frames (NaN with fewer than three turns).
    double inclinationDeg = NAN, inclinationSeDeg = NAN;
    double swingDeg = NAN, swingSeDeg = NAN;
    double ttf = NAN, ttfSe = NAN;  ///< 4 pi f / rate
    double turns = NAN;             ///< rigid-sphere turns run (rate t_end / 4 pi)
    bool steady = false;            ///< stopped by the steady-state rule (SteadyStopRule)
    std::string status = "ok";      ///< "ok" (the run completed and was analysed) or "failed"
    std::string reason;             ///< why it failed
    double wallSeconds = 0.0;

    bool ok() const { return status == "ok"; }
    bool tankTreading() const { return regime == "tank-treading"; }
};

/// case_id,v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,eta_out_mPa_s,shear_rate_per_s,eta_in_mPa_s,start_seed,regime,
/// inclination_deg,inclination_se_deg,swing_deg,swing_se_deg,ttf_4pi_f_over_rate,ttf_se,turns,steady,status,reason,wall_s
const std::string& shearCampaignCsvHeader();
/// 17 significant digits (a row read back reproduces the values bit for bit); "nan" for no value.
std::string formatShearCampaignRow(const ShearCampaignRow& r);
/// Strict: a wrong header, field count or number is an InputError naming the file and line. With
/// `dropTornTail`, a last line without its line break (a write cut by a kill) is ignored.
std::vector<ShearCampaignRow> readShearCampaignCsv(const std::filesystem::path& path, bool dropTornTail = false);

struct ShearCampaignOptions {
    DesignKind design = DesignKind::Sobol;
    long cases = 100;
    std::uint64_t seed = 1;
    int level = 3;
    double maxRotations = 10.0;  ///< the longest a case runs; it stops earlier once steady
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

/// The rows of a shear campaign: cases.csv when complete, otherwise the finished cases of the part
/// files; a CSV file path reads that table.
std::vector<ShearCampaignRow> readShearCampaignRows(const std::filesystem::path& dirOrFile, bool* complete = nullptr);

}  // namespace trbc
