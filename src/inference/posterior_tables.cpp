// Markdown tables of the posterior statistics (posterior_tables.hpp): number formatting, the row
// layout of each posterior and the whole posterior_table.md.
#include "inference/posterior_tables.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/version.hpp"

namespace trbc::detail {
namespace {

struct TableRow {
    std::string label;  // e.g. "$\\mu$ (µN/m)"
    std::string parameter;
    double factor;      // physical -> table unit
};

std::string formatNumber(double x) {
    if (x == 0.0) return "0";
    const double a = std::abs(x);
    if (a >= 0.01 && a < 1e4) return fmt::format("{:.3g}", x);
    return fmt::format("{:.3e}", x);
}

std::string markdownTable(const std::vector<PosteriorStatsRow>& rows, const std::string& posterior, const std::vector<TableRow>& layout,
                          bool twoDecimals) {
    std::string s = "| | mean | median | ML | MAP | standard deviation | 5 % | 95 % |\n|---|---|---|---|---|---|---|---|\n";
    for (const TableRow& t : layout)
        for (const PosteriorStatsRow& r : rows)
            if (r.posterior == posterior && r.parameter == t.parameter) {
                auto f = [&](double x) { return twoDecimals ? fmt::format("{:.2f}", x * t.factor) : formatNumber(x * t.factor); };
                s += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} |\n", t.label, f(r.mean), f(r.median), f(r.ml), f(r.map),
                                 f(r.sd), f(r.q05), f(r.q95));
            }
    return s;
}

std::vector<TableRow> tableLayout(const std::vector<PosteriorStatsRow>& rows, const std::string& posterior) {
    static const std::vector<TableRow> known = {
        {"$v$", "v", 1.0},
        {"$\\mu$ (µN/m)", "mu_uN_per_m", 1.0},
        {"$\\kappa_b$ ($10^{-19}$ J)", "kb_J", 1e19},
        {"$b_2$", "b2", 1.0},
        {"$\\eta_m$ (Pa s µm)", "etam_Pa_s_um", 1.0},
        {"$\\eta_m/\\mu$ (s)", "etam_over_mu_s", 1.0},
        {"FvK", "FvK", 1.0},
    };
    std::vector<TableRow> out;
    for (const TableRow& t : known)
        for (const PosteriorStatsRow& r : rows)
            if (r.posterior == posterior && r.parameter == t.parameter) out.push_back(t);
    for (const PosteriorStatsRow& r : rows) {  // the remaining (error-model) parameters as they are
        if (r.posterior != posterior) continue;
        bool have = false;
        for (const TableRow& t : out) have = have || t.parameter == r.parameter;
        if (!have) out.push_back({"`" + r.parameter + "`", r.parameter, 1.0});
    }
    return out;
}

}  // namespace

std::string posteriorTableMarkdown(const RbcInferenceOptions& o, const std::vector<PosteriorStatsRow>& rows, const std::vector<RbcDataSet>& data,
                                   const nlohmann::json& extrapolation, const nlohmann::json& check) {
    std::string s = "# Posterior statistics of the t-RBC parameters\n\n";
    const bool flow = std::any_of(data.begin(), data.end(), [](const RbcDataSet& d) { return d.experiment == RbcExperiment::Flow; });
    const int flowCap = rbcSamplerSettings(RbcRun::Phase1, RbcExperiment::Flow).populationCap;
    s += fmt::format("Made by `{}` (trbc {}), seed {}, {} samples per TMCMC/BASIS run{} (docs/BAYESIAN_INFERENCE.md).\n",
                     o.provenance.value("command", std::string("trbc infer")), kVersion, o.seed, o.populationSize,
                     flow ? fmt::format(", {} in a flow data set's phase 1", std::min(o.populationSize, flowCap)) : std::string());
    if (o.provenance.contains("model")) s += fmt::format("Model: `{}`.\n", o.provenance["model"].value("dir", std::string("?")));
    s += "\n## $\\theta^{\\rm new}$: a new cell given all data (phase 3a) — the layout of the paper's Table 1\n\n";
    s += "$\\mu$ in µN/m, $\\kappa_b$ in $10^{-19}$ J, $\\eta_m$ in Pa·s·µm. MAP = ML here (uniform box prior, docs/BAYESIAN_INFERENCE.md).\n\n";
    const std::vector<TableRow> table1 = {{"$v$", "v", 1.0},
                                          {"$\\mu$", "mu_uN_per_m", 1.0},
                                          {"$\\kappa_b$", "kb_J", 1e19},
                                          {"$b_2$", "b2", 1.0},
                                          {"$\\eta_m$", "etam_Pa_s_um", 1.0}};
    s += "| | mean | median | ML | MAP | standard deviation | MCSE of mean | MCSE of median | MCSE of SD |\n"
         "|---|---|---|---|---|---|---|---|---|\n";
    for (const TableRow& t : table1)
        for (const PosteriorStatsRow& r : rows)
            if (r.posterior == "theta_new" && r.parameter == t.parameter)
                s += fmt::format("| {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2g} | {:.2g} | {:.2g} |\n", t.label, r.mean * t.factor,
                                 r.median * t.factor, r.ml * t.factor, r.map * t.factor, r.sd * t.factor, r.mcseMean * t.factor,
                                 r.mcseMedian * t.factor, r.mcseSd * t.factor);
    s += "\nMCSE: Monte Carlo standard error of the estimate (for the joint method from the multi-chain effective sample "
         "size; for a BASIS population a lower bound that ignores its ancestry).\n";
    s += "\nWith the 90 % central credible intervals and $\\eta_m/\\mu$:\n\n";
    s += markdownTable(rows, "theta_new", tableLayout(rows, "theta_new"), false);
    if (!check.is_null() && check.contains("max_mean_difference_in_sd"))
        s += fmt::format("\nCross-check (docs/BAYESIAN_INFERENCE.md): ancestral sampling of the same mixture gives means within {:.3f} "
                         "posterior SD of the TMCMC samples (largest difference over the parameters).\n",
                         check["max_mean_difference_in_sd"].get<double>());
    s += "\n## Each data set given all data (phase 3b)\n";
    for (const RbcDataSet& d : data) {
        s += fmt::format("\n### {} ({}, `{}`)\n\n", d.name, experimentName(d.experiment), d.file.filename().string());
        s += markdownTable(rows, d.name, tableLayout(rows, d.name), false);
    }
    if (!extrapolation.empty()) {
        s += "\n## Relaxation network outside its training range\n\nShare of the samples with $r=\\eta_m/\\mu$ outside "
             "[0.025, 0.25] s, where the network input $\\eta_m=4r$ leaves [0.1, 1] (docs/BAYESIAN_INFERENCE.md):\n\n| posterior | share |\n|---|---|\n";
        for (const auto& [k, v] : extrapolation.items()) s += fmt::format("| {} | {:.3f} |\n", k, v.get<double>());
    }
    return s;
}

}  // namespace trbc::detail
