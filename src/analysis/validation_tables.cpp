#include "analysis/validation_tables.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <optional>

#include "core/csv.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "experiments/parameters.hpp"
#include "flow/flow_record.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
/// A number as the tables write it: "%.6g", "" for NaN (a failed or undefined observable).
std::string num(double x) { return std::isfinite(x) ? fmt::format("{:.6g}", x) : ""; }

/// The flow record of a case's record (cases/<case>.json), a damaged field named with that file.
FlowRecordView caseResult(const json& rec) {
    return readFlowRecord(rec.at("result"), fmt::format("cases/{}.json", rec.value("case", std::string("?"))));
}

/// The predictions against the experimental scatter: records, counts by verdict and the rows of
/// the markdown table.
struct ComparisonTable {
    json rows = json::array();
    int inside = 0, outside = 0, noData = 0, other = 0;
    std::string md = "| case | observable | prediction | experimental scatter | verdict |\n|---|---|---|---|---|\n";

    void record(const std::string& id, const std::string& observable, double predicted, const ScatterComparison& s,
                const std::string& shown) {
        (s.verdict == "inside" ? inside : s.verdict == "outside" ? outside : s.verdict == "no data" ? noData : other)++;
        rows.push_back({{"case", id}, {"observable", observable}, {"predicted", predicted}, {"scatter_lo", s.lo},
                        {"scatter_hi", s.hi}, {"points", s.points}, {"window", s.window}, {"verdict", s.verdict}});
        md += fmt::format("| {} | {} | {} | {} | {} |\n", markdownCell(id), markdownCell(observable), markdownCell(shown),
                          s.points == 0 ? std::string("–") : fmt::format("{:.3g} – {:.3g} ({} values)", s.lo, s.hi, s.points),
                          s.verdict == "outside" ? "**outside**" : s.verdict);
    }

    std::string csv() const {
        std::string cmp = csvProvenance() + "case,observable,predicted,scatter_lo,scatter_hi,points,verdict,window\n";
        for (const json& c : rows)
            cmp += fmt::format("{},{},{:.6g},{:.6g},{:.6g},{},{},{}\n", csvField(c["case"].get<std::string>()),
                               csvField(c["observable"].get<std::string>()), c["predicted"].get<double>(), c["scatter_lo"].get<double>(),
                               c["scatter_hi"].get<double>(), c["points"].get<int>(), csvField(c["verdict"].get<std::string>()),
                               csvField(c["window"].get<std::string>()));
        return cmp;
    }
};

const char* kShearHeader =
    "case_id,sweep,eta_out_mPa_s,shear_rate_per_s,shear_stress_Pa,regime,inclination_deg,swing_amplitude_deg,"
    "ttf_4pi_f_over_shear_rate,status,area_drift_max,volume_drift_max,wall_s,level\n";
const char* kTubeHeader = "case_id,pg_mmHg_per_mm,radius_um,velocity_cm_per_s,length_um,width_um,plateau,settled,"
                          "length_change_main_vs_settled,cell_frame_motion_ratio,status,area_drift_max,volume_drift_max,wall_s,"
                          "level\n";

/// A row of tube.csv; a finished case's velocity and length against the data.
std::string tubeCase(const ValidationCase& c, const json& rec, const ValidationConfig& cfg, const ValidationEvidence& evidence,
                     ComparisonTable& table) {
    const FlowRecordView r = caseResult(rec);
    const std::string row = fmt::format("{},{:g},{:g},{},{},{},{},{},{},{},{},{},{},{:.1f},{}\n", csvField(c.id), c.pressureGradient,
                                        cfg.tubeRadius, num(r.velocityCmPerS), num(r.lengthUm), num(r.widthUm),
                                        r.plateauReached ? "true" : "false", r.settled, num(r.lengthChangeMainVsSettled),
                                        num(r.cellFrameMotionRatio), csvField(r.status), num(r.areaDriftMax), num(r.volumeDriftMax),
                                        rec.value("wall_s", 0.0), cfg.tubeLevel > 0 ? cfg.tubeLevel : cfg.level);
    if (!r.ok() || !std::isfinite(r.velocityCmPerS)) return row;
    const double v = r.velocityCmPerS, l = r.lengthUm;
    table.record(c.id, "velocity [cm/s]", v, evidence.tubeVelocity(c.pressureGradient, v), fmt::format("{:.3g}", v));
    table.record(c.id, "length [um]", l, evidence.tubeLength(v, l), fmt::format("{:.3g} (at {:.3g} cm/s)", l, v));
    return row;
}

/// A row of shear.csv; a finished angle or TTF case against the data.
std::string shearCase(const ValidationCase& c, const json& rec, const ValidationConfig& cfg, const ValidationEvidence& evidence,
                      ComparisonTable& table) {
    const FlowRecordView r = caseResult(rec);
    const std::string& regime = r.regime;
    const std::string row = fmt::format("{},{},{:g},{:.6g},{:.6g},{},{},{},{},{},{},{},{:.1f},{}\n", csvField(c.id), csvField(c.kind),
                                        c.etaOut, c.rate, shearStressPa(c.etaOut, c.rate), csvField(regime), num(r.inclinationDeg),
                                        num(r.swingDeg), num(r.ttf), csvField(r.status), num(r.areaDriftMax), num(r.volumeDriftMax),
                                        rec.value("wall_s", 0.0), cfg.level);
    if (!r.ok()) return row;
    if (c.kind == "angle") {
        const double a = r.inclinationDeg;
        if (const std::optional<ScatterComparison> s = evidence.inclination(c.etaOut, c.rate, a, regime))
            table.record(c.id, "inclination [deg]", a, *s, std::isfinite(a) ? fmt::format("{:.3g}", a) : regime);
    } else if (c.kind == "ttf") {
        const double f = r.ttf;
        table.record(c.id, "4 pi f / rate", f, evidence.tankTreadingFrequency(c.rate, f, regime),
                     std::isfinite(f) ? fmt::format("{:.3g}", f) : regime);
    }
    return row;
}

/// threshold.csv: the bracket per outer viscosity, compared with Fischer 2013 and Abkarian 2007.
std::string thresholdTable(const ValidationRunner& R, const ValidationEvidence& evidence, ComparisonTable& table) {
    std::string thr = csvProvenance() + "eta_out_mPa_s,gamma_lo_per_s,gamma_hi_per_s,tau_lo_Pa,tau_hi_Pa,monotone,intermittent_rates_per_s\n";
    for (double eta : thresholdViscosities(R.cfg)) {
        if (R.thresholdPoints(eta).empty()) continue;  // not run (--only)
        const ThresholdBracket b = thresholdBracket(R.thresholdPoints(eta));
        std::string inter;
        for (double r : b.intermittentRates) inter += fmt::format("{}{:.4g}", inter.empty() ? "" : ";", r);
        auto opt = [](std::optional<double> v, double s) { return v ? fmt::format("{:.6g}", *v * s) : std::string(); };
        thr += fmt::format("{:g},{},{},{},{},{},{}\n", eta, opt(b.gammaLo, 1.0), opt(b.gammaHi, 1.0), opt(b.gammaLo, shearStressPa(eta, 1.0)),
                           opt(b.gammaHi, shearStressPa(eta, 1.0)), b.monotone ? "true" : "false", inter);
        const auto [tlo, thi] = criticalStressInterval(b, eta);
        table.record(fmt::format("threshold_eta{:g}", eta), "critical stress [Pa]", thi.value_or(NAN), evidence.criticalStress(eta, tlo, thi),
                     fmt::format("[{}, {}]", tlo ? fmt::format("{:.3g}", *tlo) : "–", thi ? fmt::format("{:.3g}", *thi) : "–"));
    }
    return thr;
}

std::string thresholdProtocolText(const ValidationConfig& c) {
    const int n = thresholdMemberCount(c);
    if (n == 0) return "one run per rate from the configured start";
    const std::string members =
        c.thresholdProtocol == "ensemble"
            ? fmt::format("{} members per rate from random starts (`flow shear --start random --seed k`, k = 1..{})", n, n)
            : fmt::format("{} thermally fluctuating members per rate at {:g} K (`flow shear --temperature {:g} --seed k`, k = 1..{})", n,
                          c.temperatureK, c.temperatureK, n);
    return members + "; a rate tank-treads when more than half of its members do";
}

/// `withThreshold`: the set ran threshold cases, so its text names their protocol.
std::string validationMarkdown(std::size_t cases, int failed, const ComparisonTable& t, const ValidationConfig& c, bool withThreshold) {
    const std::string protocol = withThreshold ? " Threshold protocol: " + thresholdProtocolText(c) + "." : std::string();
    return fmt::format("# Flow validations against experiments\n\n{} cases ({} failed); {} predictions inside the experimental "
                       "scatter, {} outside, {} without data nearby, {} neither (threshold not bracketed or not monotone, "
                       "tank-treading without a TTF). A tumbling or intermittent cell where the donors tank-tread counts as "
                       "outside. Windows: inclination and TTF use the data at shear rates "
                       "within a factor 1.5 (angle) or 1.25 (TTF) of the case, the velocity the data at pressure gradients within "
                       "a factor 1.25, the length the Tomaiuolo band interpolated at the predicted velocity, the critical stress "
                       "the data within 10 % of the outer viscosity (inside = the interval [eta gamma_lo, eta gamma_hi] overlaps "
                       "them).{}\n\n",
                       cases, failed, t.inside, t.outside, t.noData, t.other, protocol) +
           t.md;
}

// ---- the posterior draws ------------------------------------------------------------------------

}  // namespace

std::vector<std::pair<std::string, std::string>> drawObservables(const std::string& kind) {
    if (kind == "angle") return {{"inclination [deg]", "inclination_deg"}};
    if (kind == "ttf") return {{"4 pi f / rate", "ttf_4pi_f_over_shear_rate"}};
    if (kind == "tube") return {{"velocity [cm/s]", "velocity_cm_per_s"}, {"length [um]", "length_um"}};
    return {};
}

DrawOutcome drawOutcome(const json& rec, const std::string& key) {
    const FlowRecordView r = caseResult(rec);
    if (!r.ok()) return {false, NAN, shortenedReason(r.reason, 100)};
    const double x = r.observable(key);
    return {true, x, std::isfinite(x) ? "" : "no value (" + (r.regime.empty() ? std::string("?") : r.regime) + ")"};
}

namespace {

/// The bands over the draws against the scatter, beside the configured cell's verdict: rows of
/// bands.csv, validation.md and validation.json, and the agreeing count per kind under each verdict.
struct BandTable {
    json rows = json::array();
    /// kind -> compared, configured cell inside, band overlap, band verdict within the MC error
    std::map<std::string, std::array<int, 4>> tally;
    std::string csv = csvProvenance() + "case,kind,observable,eta_out_mPa_s,shear_rate_per_s,pg_mmHg_per_mm,mean_cell,mean_cell_verdict,median,q05,q95,"
                      "median_mcse,q05_mcse,q95_mcse,draws,finished,failed,with_value,scatter_lo,scatter_hi,points,band_verdict,"
                      "band_verdict_within_mcse,reasons\n";
    std::string md = "| case | observable | mean cell | median [5 – 95 %] | MC error (median / 5 % / 95 %) | finished / failed / "
                     "with a value | experimental scatter | mean-cell verdict | band verdict | draws without a value |\n"
                     "|---|---|---|---|---|---|---|---|---|---|\n";

    /// One observable of case c (a threshold viscosity: the id threshold_eta<eta>, no rate) with
    /// the configured cell's value: `meanValue`, or the prediction of its comparison when NaN.
    void record(const ValidationCase& c, const std::string& observable, const DrawBand& b, const ScatterComparison& s,
                const ComparisonTable& mean, double meanValue = NAN) {
        const std::string& id = c.id;
        const std::string& kind = c.kind;
        const auto m = std::find_if(mean.rows.begin(), mean.rows.end(),
                                    [&](const json& r) { return r["case"] == id && r["observable"] == observable; });
        if (std::isnan(meanValue) && kind != "threshold" && m != mean.rows.end()) meanValue = (*m)["predicted"].is_number() ? (*m)["predicted"].get<double>() : NAN;
        const std::string meanVerdict = m == mean.rows.end() ? "not compared" : (*m)["verdict"].get<std::string>();
        const std::string verdict = bandVerdict(b, s, kind != "threshold");
        const bool marginal = bandVerdictWithinMcse(b, s);
        const std::string reasons = drawReasonsText(b);  // a failure's text: through csvField and markdownCell
        std::array<int, 4>& t = tally[kind];
        ++t[0], t[1] += meanVerdict == "inside", t[2] += verdict == "overlap", t[3] += marginal;
        rows.push_back({{"case", id}, {"kind", kind}, {"observable", observable}, {"mean_cell", meanValue},
                        {"mean_cell_verdict", meanVerdict}, {"median", b.median}, {"q05", b.lo}, {"q95", b.hi},
                        {"median_mcse", b.medianMcse}, {"q05_mcse", b.loMcse}, {"q95_mcse", b.hiMcse},
                        {"draws", b.draws}, {"finished", b.finished}, {"failed", b.failed}, {"with_value", b.withValue},
                        {"scatter_lo", s.lo}, {"scatter_hi", s.hi}, {"points", s.points}, {"band_verdict", verdict},
                        {"band_verdict_within_mcse", marginal},
                        {"reasons", b.reasons}});
        const auto g = [](double x) { return std::isfinite(x) ? fmt::format("{:.6g}", x) : std::string(); };
        csv += fmt::format("{},{},{},{:g},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", csvField(id), csvField(kind),
                           csvField(observable), c.etaOut,
                           c.rate > 0.0 ? fmt::format("{:.6g}", c.rate) : "", kind == "tube" ? fmt::format("{:g}", c.pressureGradient) : "",
                           g(meanValue), csvField(meanVerdict),
                           g(b.median), g(b.lo), g(b.hi), g(b.medianMcse), g(b.loMcse), g(b.hiMcse), b.draws, b.finished, b.failed,
                           b.withValue, g(s.lo), g(s.hi), s.points, csvField(verdict), marginal ? "yes" : "no", csvField(reasons));
        md += fmt::format("| {} | {} | {} | {} | {} | {} / {} / {} | {} | {} | {}{} | {} |\n", markdownCell(id), markdownCell(observable),
                          std::isfinite(meanValue) ? fmt::format("{:.3g}", meanValue) : "–",
                          b.withValue > 0 ? fmt::format("{:.3g} [{:.3g} – {:.3g}]", b.median, b.lo, b.hi) : "–",
                          b.withValue > 0 ? fmt::format("{:.2g} / {}{:.2g} / {}{:.2g}", b.medianMcse, b.endsMcseIsLowerBound ? "≥ " : "",
                                                        b.loMcse, b.endsMcseIsLowerBound ? "≥ " : "", b.hiMcse)
                                          : "–",
                          b.finished, b.failed, b.withValue,
                          s.points == 0 ? std::string("–") : fmt::format("{:.3g} – {:.3g}", s.lo, s.hi), meanVerdict,
                          verdict == "no overlap" ? "**no overlap**" : verdict, marginal ? " (within MC error)" : "",
                          reasons.empty() ? "–" : markdownCell(reasons));
    }

    /// Per kind: observables compared and agreeing under each verdict; the draw runs and their failures.
    json summary(const ValidationRunner& R) const {
        int runs = 0, failed = 0;
        for (const ValidationCase& c : R.cases)
            if (c.sample >= 0) ++runs, failed += R.resultOf(c.id).value("status", "failed") != "ok";
        json kinds = json::object();
        for (const auto& [kind, t] : tally)
            kinds[kind] = {{"compared", t[0]}, {"mean_cell_inside", t[1]}, {"band_overlap", t[2]}, {"band_verdict_within_mcse", t[3]}};
        return {{"runs", runs}, {"runs_failed", failed}, {"kinds", kinds}};
    }

    std::string markdown(const ValidationRunner& R) const {
        std::string samples;
        for (const PosteriorDraw& d : R.draws) samples += fmt::format("{}{}", samples.empty() ? "" : ", ", d.sample);
        std::string md = fmt::format(
            "\n## Posterior draws\n\n{} draws of theta_new ({}, {} samples; seed {}: samples {}) ran every case beside the "
            "cell above. Per case and observable: the median and the 5 – 95 % band (type-7 quantiles) over the draws that "
            "gave a value (a tumbling cell has no angle); the critical stress of a draw is sqrt(tau_lo tau_hi) of its "
            "bracket. Band verdict: overlap when the band meets the experimental scatter of the window above, taken at the "
            "median (the length's band at the median velocity). Monte Carlo error of each quantile: half the distance "
            "between the quantiles at p -+ sqrt(p (1 - p) / n) over the n draws with a value (independent draws); a band "
            "verdict is *within MC error* when the band's deciding end lies within its MC error of the scatter's edge, so "
            "that more draws could flip it. With fewer than 19 draws with a value the ends' errors are lower bounds (the "
            "level p - sqrt(p (1 - p) / n) falls below 0; shown with ≥), and the verdict counts as within MC error. An MC error of 0 means tied neighbours: a critical stress takes the few values "
            "of its bisection grid, whose spacing is then its resolution.\n\n| kind | compared | mean cell inside | band overlaps | band verdicts within "
            "MC error |\n|---|---|---|---|---|\n",
            R.draws.size(), R.cfg.posterior.string(), R.posteriorSamples, R.seed, samples);
        for (const auto& [kind, t] : tally) md += fmt::format("| {} | {} | {} | {} | {} |\n", kind, t[0], t[1], t[2], t[3]);
        const json runs = summary(R);
        return md + fmt::format("\n{} draw runs, {} failed.\n\n", runs["runs"].get<int>(), runs["runs_failed"].get<int>()) + this->md;
    }
};

/// The scatter of an observable's window, taken at the band's median (the length's at the median velocity).
std::optional<ScatterComparison> drawScatter(const ValidationCase& c, const std::string& observable, double median, double velocity,
                                             const ValidationEvidence& evidence) {
    if (c.kind == "angle") return evidence.inclination(c.etaOut, c.rate, median, "");
    if (c.kind == "ttf") return evidence.tankTreadingFrequency(c.rate, median, "");
    if (observable == "velocity [cm/s]") return evidence.tubeVelocity(c.pressureGradient, median);
    return evidence.tubeLength(velocity, median);
}

/// draws.csv (one row per draw run) and bands.csv; returns the bands.
BandTable drawTables(const ValidationRunner& R, const ValidationEvidence& evidence, const ComparisonTable& mean) {
    BandTable bands;
    std::string runs = csvProvenance() + "case_id,case,kind,sample,status,regime,inclination_deg,ttf_4pi_f_over_shear_rate,velocity_cm_per_s,length_um,wall_s\n";
    for (const ValidationCase& c : R.cases) {
        if (c.sample >= 0) {
            const json& rec = R.results.at(c.id);
            const FlowRecordView r = caseResult(rec);
            runs += fmt::format("{},{},{},{},{},{},{},{},{},{},{:.1f}\n", csvField(c.id), csvField(c.id.substr(0, c.id.rfind("_sample"))),
                                csvField(c.kind), c.sample, csvField(r.status), csvField(r.regime), num(r.inclinationDeg), num(r.ttf),
                                num(r.velocityCmPerS), num(r.lengthUm), rec.value("wall_s", 0.0));
            continue;
        }
        double velocity = NAN;  // the median of the case's draws, where the length's band is read
        for (const auto& [name, key] : drawObservables(c.kind)) {
            std::vector<DrawOutcome> outcomes;
            for (const PosteriorDraw& d : R.draws)
                if (const auto it = R.results.find(drawCaseId(c.id, d.sample)); it != R.results.end())
                    outcomes.push_back(drawOutcome(it->second, key));
            const DrawBand b = drawBand(outcomes);
            if (key == "velocity_cm_per_s") velocity = b.median;
            if (const auto s = drawScatter(c, name, b.median, velocity, evidence)) bands.record(c, name, b, *s, mean);
        }
    }
    for (double eta : thresholdViscosities(R.cfg)) {
        if (R.thresholdPoints(eta).empty()) continue;  // not run (--only)
        std::vector<DrawOutcome> outcomes;
        for (const PosteriorDraw& d : R.draws) outcomes.push_back(criticalStressOutcome(R.thresholdPoints(eta, d.sample), eta));
        const DrawBand b = drawBand(outcomes);
        const std::optional<double> tau = std::isfinite(b.median) ? std::optional(b.median) : std::nullopt;
        bands.record(thresholdBandCase(eta), "critical stress [Pa]", b,
                     evidence.criticalStress(eta, tau, tau), mean, criticalStressOutcome(R.thresholdPoints(eta), eta).value);
    }
    writeFileAtomically(R.out / "draws.csv", runs);
    writeFileAtomically(R.out / "bands.csv", bands.csv);
    return bands;
}

/// The cell of the cases: the source and its parameters (a posterior's means as the flow commands took them).
json cellJson(const ValidationRunner& R) {
    json cell = R.cfg.cellSource == "table1"
                    ? json{{"source", "the paper's Table 1 means"}, {"v", table1::v}, {"mu_uN_per_m", table1::mu}, {"kb_J", table1::kbJ},
                           {"b2", table1::b2}, {"etam_Pa_s_um", table1::etam}}
                : R.cfg.cellSource == "explicit"
                    ? json{{"source", "explicit"}, {"v", R.cfg.v}, {"mu_uN_per_m", R.cfg.mu}, {"kb_J", R.cfg.kbJ}, {"b2", R.cfg.b2},
                           {"etam_Pa_s_um", R.cfg.etam}}
                    : json{{"source", "the calibrated cell (analysis/calibrated_cell.hpp) of " + R.cfg.posterior.string()}};
    if (R.cfg.cellSource == "posterior")
        for (const ValidationCase& c : R.cases)
            if (c.sample < 0 && R.resultOf(c.id).contains("parameters")) {
                cell["parameters"] = R.resultOf(c.id).at("parameters").value("cell", json());
                break;
            }
    return cell;
}

}  // namespace

/// Tables, comparison with the experimental scatter, summary; returns the summary JSON (and the
/// bands over the draws in `bandRows`).
json writeValidationTables(const ValidationRunner& R, json& bandRows) {
    ValidationEvidence evidence(R.cfg.dataDir);
    ComparisonTable table;
    std::string shear = csvProvenance() + kShearHeader, tube = csvProvenance() + kTubeHeader;
    int failed = 0;
    std::size_t cases = 0;
    for (const ValidationCase& c : R.cases) {
        if (c.sample >= 0) continue;  // the draws: drawTables
        ++cases;
        const json& rec = R.results.at(c.id);
        if (rec.at("result").value("status", "failed") != "ok") ++failed;
        if (c.kind == "tube")
            tube += tubeCase(c, rec, R.cfg, evidence, table);
        else
            shear += shearCase(c, rec, R.cfg, evidence, table);
    }
    const std::string thr = thresholdTable(R, evidence, table);
    writeFileAtomically(R.out / "shear.csv", shear);
    writeFileAtomically(R.out / "tube.csv", tube);
    writeFileAtomically(R.out / "threshold.csv", thr);
    writeFileAtomically(R.out / "comparison.csv", table.csv());
    // The points the verdicts compared with, in trbc's units, for the figures and for the record.
    writeFileAtomically(R.out / "experimental_data.json", validationDataJson(evidence.data()).dump(1) + "\n");
    json summary = {{"cases", cases}, {"failed", failed}, {"inside", table.inside}, {"outside", table.outside},
                    {"no_data", table.noData}, {"other", table.other}, {"comparisons", table.rows.size()}};
    const bool withThreshold =
        std::any_of(R.cases.begin(), R.cases.end(), [](const ValidationCase& c) { return c.kind == "threshold"; });
    std::string md = validationMarkdown(cases, failed, table, R.cfg, withThreshold);
    if (!R.draws.empty()) {
        const BandTable bands = drawTables(R, evidence, table);
        md += bands.markdown(R);
        summary["draws"] = bands.summary(R);
        bandRows = bands.rows;
    }
    writeFileAtomically(R.out / "validation.md", md);
    return summary;
}

/// OUT/validation.json: summary, selection, cell, levels, configuration and timing.
json validationRecord(const ValidationRunner& R, const ValidationSelection& o, const json& summary, const json& bandRows, std::size_t configured,
                      double wall) {
    double caseWall = 0.0;
    for (const auto& [id, rec] : R.results) caseWall += rec.value("wall_s", 0.0);
    json j = {{"summary", summary},
            {"initial_cases_configured", configured},
            {"only", o.only},
            {"shard", o.shard.empty() ? json() : json(o.shard)},
            {"imported", o.imports},
            {"cases_imported", R.imported},
            {"cell", cellJson(R)},
            {"level", R.cfg.level},
            {"tube_level", R.cfg.tubeLevel > 0 ? R.cfg.tubeLevel : R.cfg.level},
            {"threshold_protocol", {{"protocol", R.cfg.thresholdProtocol},
                                    {"members_per_rate", thresholdMemberCount(R.cfg)},
                                    {"temperature_K", R.cfg.thresholdProtocol == "fluctuating" ? json(R.cfg.temperatureK) : json()},
                                    {"text", thresholdProtocolText(R.cfg)}}},
            {"config", R.cfg.file.string()},
            {"config_text", readFileBytes(R.cfg.file)},
            {"data_dir", R.cfg.dataDir.string()},
            {"wall_s_this_run", wall},
            {"case_wall_s_total", caseWall},
            {"cases_run_this_time", R.ranHere},
            {"jobs", R.cfg.jobs},
            {"threads_per_case", R.cfg.threads},
            {"provenance", withBuild({{"command", o.command}})}};
    if (!R.cfg.bases.empty()) j["config_bases"] = R.cfg.bases;
    if (R.draws.empty()) return j;
    std::vector<long> samples;
    for (const PosteriorDraw& d : R.draws) samples.push_back(d.sample);
    j["draws"] = {{"count", R.draws.size()}, {"seed", R.seed}, {"posterior", R.cfg.posterior.string()},
                  {"posterior_samples", R.posteriorSamples}, {"samples", samples},
                  {"choice", "subsampleIndices(samples, count, seed): partial Fisher-Yates on mt19937_64(seed), sample order"},
                  {"bands", bandRows}};
    return j;
}

}  // namespace trbc
