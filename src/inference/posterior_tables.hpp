#pragma once
// The Markdown report of the posterior statistics, DIR/posterior_table.md of `trbc infer`: theta_new
// in the layout of the paper's Table 1 and every data set given all data. Internal to the inference layer.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "inference/rbc_pipeline.hpp"

namespace trbc::detail {

/// The Markdown of DIR/posterior_table.md from the rows of DIR/posterior_stats.csv. `extrapolation`:
/// share of the samples outside the relaxation network's training range per posterior;
/// `check`: the ancestral cross-check of theta_new (null for the joint method, which has none).
std::string posteriorTableMarkdown(const RbcInferenceOptions& o, const std::vector<PosteriorStatsRow>& rows,
                                   const std::vector<RbcDataSet>& data, const nlohmann::json& extrapolation,
                                   const nlohmann::json& check);

}  // namespace trbc::detail
