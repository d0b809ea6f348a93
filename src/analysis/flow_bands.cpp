#include "analysis/flow_bands.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "core/csv.hpp"

namespace trbc {

namespace {

Eigen::MatrixXd drawInputs(const std::vector<PosteriorDraw>& draws, double etaOut, double rate) {
    Eigen::MatrixXd x(7, Eigen::Index(draws.size()));
    for (std::size_t k = 0; k < draws.size(); ++k) {
        const PosteriorDraw& d = draws[k];
        x.col(Eigen::Index(k)) = flowInput({d.v, d.mu, CellParameters::fvkFromKb(d.mu, d.kbJ), d.b2, d.etam}, etaOut, rate);
    }
    return x;
}

SurrogateBandRow bandRow(const ValidationCase& c, std::string observable, const std::vector<DrawOutcome>& outcomes,
                         const std::optional<ScatterComparison>& scatter, bool noValueDisagrees) {
    SurrogateBandRow r;
    r.c = c;
    r.observable = std::move(observable);
    r.band = drawBand(outcomes);
    r.scatter = scatter.value_or(ScatterComparison{"no data", 0.0, 0.0, 0, ""});
    r.verdict = bandVerdict(r.band, r.scatter, noValueDisagrees);
    r.withinMcse = bandVerdictWithinMcse(r.band, r.scatter);
    return r;
}

std::string g(double x) { return std::isfinite(x) ? fmt::format("{:.6g}", x) : std::string(); }

}  // namespace

std::vector<DrawOutcome> networkDrawOutcomes(const FlowSurrogate& model, const std::vector<PosteriorDraw>& draws, const ValidationCase& c,
                                             double etaIn, FlowPrediction* prediction) {
    const Eigen::VectorXd etaInCol = Eigen::VectorXd::Constant(Eigen::Index(draws.size()), etaIn);
    std::vector<DrawOutcome> outcomes;
    if (c.kind == "threshold") {
        const Eigen::VectorXd tc = model.criticalStressPa(drawInputs(draws, c.etaOut, 1.0), etaInCol);
        for (Eigen::Index k = 0; k < tc.size(); ++k)
            outcomes.push_back(std::isfinite(tc(k)) ? DrawOutcome{true, tc(k), ""}
                                                    : DrawOutcome{true, NAN, "no value (no crossing in the campaign's stress range)"});
        return outcomes;
    }
    FlowPrediction p = model.predict(drawInputs(draws, c.etaOut, c.rate), etaInCol);
    for (Eigen::Index k = 0; k < p.pTankTreading.size(); ++k) {
        if (p.pTankTreading(k) <= 0.5)
            outcomes.push_back({true, NAN, "no value (tumbling: probability of tank-treading <= 1/2)"});
        else
            outcomes.push_back({true, c.kind == "angle" ? p.inclinationDeg(k) : p.ttf(k), ""});
    }
    if (prediction) *prediction = std::move(p);
    return outcomes;
}

std::vector<SurrogateBandRow> surrogateShearBands(const ValidationConfig& cfg, const FlowSurrogate& model,
                                                  const std::vector<PosteriorDraw>& draws, const ValidationEvidence& evidence) {
    std::vector<SurrogateBandRow> rows;
    const Eigen::VectorXd etaIn = Eigen::VectorXd::Constant(Eigen::Index(draws.size()), cfg.etaIn);
    for (const ValidationCase& c : initialValidationCases(cfg)) {
        if (c.kind != "angle" && c.kind != "ttf") continue;
        FlowPrediction p;
        const std::vector<DrawOutcome> outcomes = networkDrawOutcomes(model, draws, c, cfg.etaIn, &p);
        const DrawBand b = drawBand(outcomes);
        const auto scatter = c.kind == "angle" ? evidence.inclination(c.etaOut, c.rate, b.median, "")
                                               : std::optional(evidence.tankTreadingFrequency(c.rate, b.median, ""));
        if (!scatter) continue;  // no data at this viscosity
        SurrogateBandRow r = bandRow(c, c.kind == "angle" ? "inclination [deg]" : "4 pi f / rate", outcomes, scatter, true);
        r.outsideBox = long(std::count(p.outsideBox.begin(), p.outsideBox.end(), true));
        r.meanPTankTreading = p.pTankTreading.mean();
        rows.push_back(std::move(r));
    }
    for (double eta : thresholdViscosities(cfg)) {
        const ValidationCase c = thresholdBandCase(eta);
        const std::vector<DrawOutcome> outcomes = networkDrawOutcomes(model, draws, c, cfg.etaIn);
        const DrawBand b = drawBand(outcomes);
        const std::optional<double> tau = std::isfinite(b.median) ? std::optional(b.median) : std::nullopt;
        SurrogateBandRow r = bandRow(c, "critical stress [Pa]", outcomes, evidence.criticalStress(eta, tau, tau), false);
        // The cell and eta_out decide whether a draw lies in the box; the stress axis is searched whole.
        const DesignAxis& stress = kShearCampaignAxes[6];
        Eigen::MatrixXd inside = drawInputs(draws, eta, 1.0);
        inside.row(6).setConstant(shearRateFromStress(eta, std::sqrt(stress.lo * stress.hi)));
        const FlowPrediction p = model.predict(inside, etaIn);
        r.outsideBox = long(std::count(p.outsideBox.begin(), p.outsideBox.end(), true));
        rows.push_back(std::move(r));
    }
    return rows;
}

std::string surrogateBandsCsv(const std::vector<SurrogateBandRow>& rows) {
    std::string csv = csvProvenance() +
                      "case,kind,observable,eta_out_mPa_s,shear_rate_per_s,median,q05,q95,median_mcse,q05_mcse,q95_mcse,draws,with_value,"
                      "mean_p_tank_treading,outside_box,scatter_lo,scatter_hi,points,band_verdict,band_verdict_within_mcse,reasons\n";
    for (const SurrogateBandRow& r : rows) {
        const DrawBand& b = r.band;
        csv += fmt::format("{},{},{},{:g},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", csvField(r.c.id), csvField(r.c.kind),
                           csvField(r.observable), r.c.etaOut, r.c.rate > 0 ? fmt::format("{:.6g}", r.c.rate) : "", g(b.median), g(b.lo),
                           g(b.hi), g(b.medianMcse), g(b.loMcse), g(b.hiMcse), b.draws, b.withValue, g(r.meanPTankTreading), r.outsideBox,
                           g(r.scatter.lo), g(r.scatter.hi), r.scatter.points, csvField(r.verdict), r.withinMcse ? "yes" : "no",
                           csvField(drawReasonsText(b)));
    }
    return csv;
}

std::string surrogateBandsMarkdown(const std::vector<SurrogateBandRow>& rows) {
    std::map<std::string, std::array<int, 3>> tally;  // kind -> compared, overlap, within MC error
    std::string table =
        "| case | observable | median [5 – 95 %] | MC error (median / 5 % / 95 %) | with a value / draws | P(tank-treading) | "
        "experimental scatter | band verdict |\n|---|---|---|---|---|---|---|---|\n";
    for (const SurrogateBandRow& r : rows) {
        const DrawBand& b = r.band;
        auto& t = tally[r.c.kind];
        ++t[0], t[1] += r.verdict == "overlap", t[2] += r.withinMcse;
        table += fmt::format("| {} | {} | {} | {} | {} / {} | {} | {} | {}{} |\n", markdownCell(r.c.id), markdownCell(r.observable),
                             b.withValue > 0 ? fmt::format("{:.3g} [{:.3g} – {:.3g}]", b.median, b.lo, b.hi) : "–",
                             b.withValue > 0 ? fmt::format("{:.2g} / {:.2g} / {:.2g}", b.medianMcse, b.loMcse, b.hiMcse) : "–",
                             b.withValue, b.draws, std::isfinite(r.meanPTankTreading) ? fmt::format("{:.2f}", r.meanPTankTreading) : "–",
                             r.scatter.points == 0 ? std::string("–") : fmt::format("{:.3g} – {:.3g}", r.scatter.lo, r.scatter.hi),
                             r.verdict == "no overlap" ? "**no overlap**" : r.verdict, r.withinMcse ? " (within MC error)" : "");
    }
    std::string md = "| kind | compared | band overlaps | verdicts within MC error |\n|---|---|---|---|\n";
    for (const auto& [kind, t] : tally) md += fmt::format("| {} | {} | {} | {} |\n", kind, t[0], t[1], t[2]);
    return md + "\n" + table;
}

}  // namespace trbc
