#pragma once
// The campaign table: one CSV row per sample (docs/CAMPAIGN_AND_SURROGATE.md, campaign), physical units,
// canonical column names. Doubles are written with 17 significant digits so a table read back
// reproduces the computed values bit for bit; a missing output is written as "nan".
#include <filesystem>
#include <string>
#include <vector>

#include "sampling/design.hpp"

namespace trbc {

struct CampaignRow {
    CampaignPoint point;
    std::uint64_t seed = 0;
    double D = NAN, hmin = NAN, hmax = NAN, D0 = NAN, D1 = NAN, tc = NAN;  ///< um, s
    std::string status = "ok";  ///< "ok" (all six outputs finite) or "failed"
    std::string reason;         ///< why a sample failed (no commas or newlines)
    double wallSeconds = 0.0;   ///< this row's share of its cell's wall time

    bool ok() const { return status == "ok"; }
};

/// sample_id,cell_id,seed,v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN,D_um,hmin_um,hmax_um,D0_um,D1_um,tc_s,status,reason,wall_s
const std::string& campaignCsvHeader();
std::string formatCampaignRow(const CampaignRow& r);

/// Reads a campaign table. Strict: a wrong header, a wrong field count or a non-numeric field
/// throws InputError naming the file and line. With `dropTruncatedTail`, a last line without its
/// newline (a write cut by SIGKILL) is ignored instead; `truncated` tells whether that happened.
std::vector<CampaignRow> readCampaignCsv(const std::filesystem::path& path, bool dropTruncatedTail = false,
                                         bool* truncated = nullptr);

/// Replaces commas and line breaks so a message fits one CSV field.
std::string csvSafe(std::string text);

}  // namespace trbc
