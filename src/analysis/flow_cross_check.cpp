#include "analysis/flow_cross_check.hpp"

#include <fmt/format.h>

#include <array>
#include <cmath>
#include <map>

#include "analysis/flow_bands.hpp"
#include "analysis/validation_tables.hpp"
#include "core/csv.hpp"

namespace trbc {

namespace {

std::string g(double x) { return std::isfinite(x) ? fmt::format("{:.6g}", x) : std::string(); }

double shareWithValue(const DrawBand& b) { return b.finished > 0 ? double(b.withValue) / b.finished : NAN; }

std::string bandText(const DrawBand& b, bool withMcse) {
    if (b.withValue == 0) return "–";
    std::string s = fmt::format("{:.3g} [{:.3g} – {:.3g}]", b.median, b.lo, b.hi);
    if (withMcse)
        s += fmt::format(" ± {:.2g} / {}{:.2g} / {}{:.2g}", b.medianMcse, b.endsMcseIsLowerBound ? "≥ " : "", b.loMcse,
                         b.endsMcseIsLowerBound ? "≥ " : "", b.hiMcse);
    return s;
}

/// What the direct run gave each of its draws for case c, and those draws: a draw without its
/// record is left out, and for a threshold a draw with any of its rates or members missing (a
/// bracket of part of the rates is not the run's).
struct PairedOutcomes {
    std::vector<PosteriorDraw> draws;
    std::vector<DrawOutcome> direct;
};

bool thresholdIncomplete(const ValidationRunner& R, double etaOut, long sample) {
    for (const auto& [id, c] : R.missing)
        if (c.kind == "threshold" && c.etaOut == etaOut && c.sample == sample) return true;
    return false;
}

PairedOutcomes directOutcomes(const ValidationRunner& R, const ValidationCase& c, const std::string& key) {
    PairedOutcomes p;
    for (const PosteriorDraw& d : R.draws) {
        if (c.kind == "threshold") {
            const std::vector<RegimePoint> points = R.thresholdPoints(c.etaOut, d.sample);
            if (points.empty() || thresholdIncomplete(R, c.etaOut, d.sample)) continue;
            p.direct.push_back(criticalStressOutcome(points, c.etaOut));
        } else {
            const auto it = R.results.find(drawCaseId(c.id, d.sample));
            if (it == R.results.end()) continue;
            p.direct.push_back(drawOutcome(it->second, key));
        }
        p.draws.push_back(d);
    }
    return p;
}

}  // namespace

FlowCrossCheckRow compareWithDirect(const ValidationCase& c, std::string observable, const std::vector<DrawOutcome>& direct,
                                    const std::vector<DrawOutcome>& networkPaired, const DrawBand& network) {
    FlowCrossCheckRow r;
    r.c = c;
    r.observable = std::move(observable);
    r.direct = drawBand(direct);
    std::vector<DrawOutcome> atFinished;  // the networks at the draws the direct run finished
    for (std::size_t k = 0; k < std::min(direct.size(), networkPaired.size()); ++k)
        if (direct[k].finished) atFinished.push_back(networkPaired[k]);
    r.networkPaired = drawBand(atFinished);
    r.network = network;
    double sum = 0.0, sumSq = 0.0;
    for (std::size_t k = 0; k < std::min(direct.size(), networkPaired.size()); ++k) {
        const DrawOutcome &d = direct[k], &n = networkPaired[k];
        if (!d.finished || !n.finished) continue;
        ++r.pairs;
        r.pairsAlike += std::isfinite(d.value) == std::isfinite(n.value);
        if (!std::isfinite(d.value) || !std::isfinite(n.value)) continue;
        ++r.paired;
        sum += n.value - d.value;
        sumSq += (n.value - d.value) * (n.value - d.value);
    }
    if (r.paired > 0) r.meanDifference = sum / r.paired, r.rmsDifference = std::sqrt(sumSq / r.paired);

    std::vector<std::string> differs;
    // The share of draws with a value: binomial errors of the pooled share.
    const double pd = shareWithValue(r.direct), pn = shareWithValue(network);
    if (std::isfinite(pd) && std::isfinite(pn)) {
        const double pooled = double(r.direct.withValue + network.withValue) / double(r.direct.finished + network.finished);
        const double se = std::sqrt(pooled * (1.0 - pooled) * (1.0 / r.direct.finished + 1.0 / network.finished));
        if (std::abs(pn - pd) > kCrossCheckSigmas * se)
            differs.push_back(se > 0.0 ? fmt::format("share with a value {:.2f} against {:.2f} ({:.1f} errors)", pn, pd, std::abs(pn - pd) / se)
                                       : fmt::format("share with a value {:.2f} against {:.2f}", pn, pd));
    } else {
        differs.push_back("no finished draw in one of them");
    }
    std::vector<std::string> notCompared;
    const bool quantiles = r.direct.withValue >= kCrossCheckMinValues && network.withValue >= kCrossCheckMinValues;
    // Ends whose MC errors are only lower bounds could not fail honestly (bandVerdictWithinMcse
    // counts them as undecided too).
    const bool ends = quantiles && !r.direct.endsMcseIsLowerBound && !network.endsMcseIsLowerBound;
    if (quantiles) {
        const std::array<std::array<double, 4>, 3> q = {{{network.median, r.direct.median, network.medianMcse, r.direct.medianMcse},
                                                          {network.lo, r.direct.lo, network.loMcse, r.direct.loMcse},
                                                          {network.hi, r.direct.hi, network.hiMcse, r.direct.hiMcse}}};
        const char* names[] = {"median", "5 %", "95 %"};
        for (int i = 0; i < (ends ? 3 : 1); ++i) {
            const double diff = std::abs(q[i][0] - q[i][1]), se = std::hypot(q[i][2], q[i][3]);
            if (!(diff <= kCrossCheckSigmas * se))
                differs.push_back(se > 0.0 ? fmt::format("{} by {:.3g} ({:.1f} errors)", names[i], q[i][0] - q[i][1], diff / se)
                                           : fmt::format("{} by {:.3g}", names[i], q[i][0] - q[i][1]));
        }
        if (!ends) notCompared.push_back("the 5-95 % ends not compared: their MC errors are lower bounds (fewer than 19 values)");
    } else if (r.direct.withValue > 0 || network.withValue > 0) {
        notCompared.push_back(fmt::format("quantiles not compared: fewer than {} values", kCrossCheckMinValues));
    }
    r.agrees = differs.empty();
    for (const std::string& d : differs) r.note += (r.note.empty() ? "" : "; ") + d;
    for (const std::string& d : notCompared) r.note += (r.note.empty() ? "" : "; ") + d;
    return r;
}

std::vector<FlowCrossCheckRow> flowCrossCheck(const ValidationRunner& direct, const FlowSurrogate& model,
                                              const std::vector<PosteriorDraw>& manyDraws) {
    std::vector<FlowCrossCheckRow> rows;
    auto compare = [&](const ValidationCase& c, const std::string& observable, const std::string& key) {
        const PairedOutcomes p = directOutcomes(direct, c, key);
        if (p.draws.empty()) return;  // not run directly
        const std::vector<DrawOutcome> paired = networkDrawOutcomes(model, p.draws, c, direct.cfg.etaIn);
        const DrawBand many = drawBand(networkDrawOutcomes(model, manyDraws, c, direct.cfg.etaIn));
        rows.push_back(compareWithDirect(c, observable, p.direct, paired, many));
    };
    for (const ValidationCase& c : initialValidationCases(direct.cfg))
        if (c.kind == "angle" || c.kind == "ttf")
            for (const auto& [name, key] : drawObservables(c.kind)) compare(c, name, key);
    for (double eta : thresholdViscosities(direct.cfg)) compare(thresholdBandCase(eta), "critical stress [Pa]", "");
    return rows;
}

std::string flowCrossCheckCsv(const std::vector<FlowCrossCheckRow>& rows) {
    std::string csv = csvProvenance() +
                      "case,kind,observable,eta_out_mPa_s,shear_rate_per_s,direct_draws,direct_failed,direct_with_value,direct_median,direct_q05,direct_q95,"
                      "direct_median_mcse,direct_q05_mcse,direct_q95_mcse,paired_network_with_value,paired_network_median,pairs,pairs_alike,"
                      "paired,mean_difference,rms_difference,network_draws,network_with_value,network_median,network_q05,network_q95,"
                      "network_median_mcse,network_q05_mcse,network_q95_mcse,agrees,note\n";
    for (const FlowCrossCheckRow& r : rows) {
        const DrawBand &d = r.direct, &n = r.network;
        csv += fmt::format("{},{},{},{:g},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", csvField(r.c.id),
                           csvField(r.c.kind), csvField(r.observable), r.c.etaOut, r.c.rate > 0 ? fmt::format("{:.6g}", r.c.rate) : "",
                           d.draws, d.failed, d.withValue, g(d.median), g(d.lo), g(d.hi), g(d.medianMcse), g(d.loMcse), g(d.hiMcse),
                           r.networkPaired.withValue, g(r.networkPaired.median), r.pairs, r.pairsAlike, r.paired, g(r.meanDifference),
                           g(r.rmsDifference), n.finished, n.withValue, g(n.median), g(n.lo), g(n.hi), g(n.medianMcse), g(n.loMcse),
                           g(n.hiMcse), r.agrees ? "yes" : "no", csvField(r.note));
    }
    return csv;
}

std::string flowCrossCheckMarkdown(const std::vector<FlowCrossCheckRow>& rows) {
    std::map<std::string, std::array<int, 2>> tally;  // kind -> compared, agreeing
    std::string table =
        "| case | observable | direct: median [5 – 95 %] ± MC error | networks, same draws | networks, all draws: median [5 – 95 %] ± MC "
        "error | with a value: direct / same / all | same draws: alike / pairs; mean, RMS of network − direct | agrees |\n"
        "|---|---|---|---|---|---|---|---|\n";
    for (const FlowCrossCheckRow& r : rows) {
        auto& t = tally[r.c.kind];
        ++t[0], t[1] += r.agrees;
        table += fmt::format("| {} | {} | {} | {} | {} | {}/{} / {}/{} / {}/{} | {} / {}; {} | {}{} |\n", markdownCell(r.c.id),
                             markdownCell(r.observable), bandText(r.direct, true), bandText(r.networkPaired, false),
                             bandText(r.network, true), r.direct.withValue, r.direct.finished, r.networkPaired.withValue,
                             r.networkPaired.finished, r.network.withValue, r.network.finished, r.pairsAlike, r.pairs,
                             r.paired > 0 ? fmt::format("{:.3g}, {:.3g}", r.meanDifference, r.rmsDifference) : "–",
                             r.agrees ? "yes" : "**no**", r.note.empty() ? "" : " (" + markdownCell(r.note) + ")");
    }
    std::string md = fmt::format("Agreement: the share of draws with a value within {0:g} binomial errors, the median and the 5 % and "
                                 "95 % quantiles within {0:g} combined Monte Carlo errors (the quantiles from {1} values on, the ends "
                                 "where neither band's end errors are lower bounds).\n\n"
                                 "| kind | compared | agree |\n|---|---|---|\n",
                                 kCrossCheckSigmas, kCrossCheckMinValues);
    for (const auto& [kind, t] : tally) md += fmt::format("| {} | {} | {} |\n", kind, t[0], t[1]);
    return md + "\n" + table;
}

}  // namespace trbc
