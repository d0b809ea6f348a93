#pragma once
// The table of the shear-flow campaign (docs/FLOW_CAMPAIGN.md): the design over the cell and the
// flow, one CSV row per case in physical units with canonical column names, and the finished rows
// of a campaign directory (flow/shear_campaign.hpp runs it). Doubles are written with 17
// significant digits, so a table read back reproduces the computed values bit for bit.
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "experiments/parameters.hpp"
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
/// stresses 0.01-21 Pa); docs/FLOW_CAMPAIGN.md gives the reasons for each range.
inline constexpr DesignAxis kShearCampaignAxes[7] = {
    {"v", 0.65, 1.0, false},
    {"mu_uN_per_m", 0.5, 16.0, true},
    {"FvK", 10.0, 2000.0, true},
    {"b2", 0.0, 9.0, false},
    {"etam_Pa_s_um", 0.03, 3.0, true},
    {"eta_out_mPa_s", 8.0, 130.0, true},
    {"shear_stress_Pa", 0.01, 25.0, true},
};

/// kShearCampaignAxes as campaign.json records it ("box": name, lo, hi, scale per input).
nlohmann::json shearCampaignBoxJson();

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
    /// The campaign's mesh level (its campaign.json; not a column of the table), 0 when not known.
    int meshLevel = 0;
    /// The campaign's start (its campaign.json): "random" or "in-plane"; empty when not known.
    std::string start;

    bool ok() const { return status == "ok"; }
    /// A row the networks learn from: run to the end, with a regime.
    bool finished() const { return ok() && !regime.empty(); }
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

/// Finished rows of the part files DIR/parts/*.csv by case id: whole rows whose inputs are the
/// design's (the first part file in name order wins when a case is in two). InputError naming the
/// file for a row with other inputs (a part file of another design or seed).
std::map<long, ShearCampaignRow> finishedShearCampaignRows(const std::filesystem::path& dir,
                                                           const std::vector<ShearCampaignPoint>& design);

/// The rows of a shear campaign: cases.csv when complete, otherwise the finished cases of the part
/// files; a CSV file path reads that table. Rows of a directory carry the level and the start of its
/// campaign.json (meshLevel, start).
std::vector<ShearCampaignRow> readShearCampaignRows(const std::filesystem::path& dirOrFile, bool* complete = nullptr);

}  // namespace trbc
