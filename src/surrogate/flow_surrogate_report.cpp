// The reports of a flow training (training.json, accuracy.md), the learning curve's rows and the
// check that campaigns trained together match (surrogate/flow_surrogate.hpp).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {

namespace fs = std::filesystem;

namespace {

std::string percent(long k, long n) { return n > 0 ? fmt::format("{:.1f} % ({}/{})", 100.0 * double(k) / double(n), k, n) : "-"; }

constexpr const char* kTableHead =
    "| set | cases | angle RMSE (deg) | swing RMSE (deg) | TTF RMSE | angle / TTF RMSE, steady cases (count) | campaign's own "
    "uncertainty, angle / TTF (RMS of *_se) | misclassified far from the boundary | near it | Brier |\n"
    "|---|---|---|---|---|---|---|---|---|---|";

}  // namespace

void checkShearCampaignsMatch(const std::vector<fs::path>& campaigns) {
    std::optional<nlohmann::json> first;
    for (const fs::path& c : campaigns) {
        fs::path dir = c;
        if (fs::is_regular_file(dir)) dir = dir.parent_path();
        const fs::path meta = dir / "campaign.json";
        if (campaigns.size() < 2 || !fs::exists(meta)) continue;
        nlohmann::json settings;
        try {
            std::ifstream in(meta);
            settings = nlohmann::json::parse(in).at("settings");
        } catch (const std::exception& e) {
            throw InputError(fmt::format("--campaign {}: {} is not a campaign description ({})", c.string(), meta.string(), e.what()));
        }
        settings.erase("level");
        settings.erase("cases");
        settings.erase("inject_failures");
        settings.erase("start");  // the mix of starts is the training's to judge (random with in-plane)
        if (!first) {
            first = settings;
            continue;
        }
        for (const auto& [key, value] : settings.items())
            if (!first->contains(key) || (*first)[key] != value)
                throw InputError(fmt::format("--campaign {}: its setting '{}' ({}) differs from the first campaign's ({}); campaigns trained "
                                             "together differ only in level, size and start", c.string(), key, value.dump(),
                                             first->contains(key) ? (*first)[key].dump() : "absent"));
        for (const auto& [key, value] : first->items())
            if (!settings.contains(key))
                throw InputError(fmt::format("--campaign {}: it lacks the first campaign's setting '{}' ({}); campaigns trained "
                                             "together differ only in level, size and start", c.string(), key, value.dump()));
    }
}

namespace {

/// The rows of one mesh level sorted by case id, their distinct case ids (one per case when the
/// campaigns of two starts are given), and the rows of the other levels in their order.
struct LearningCurveDesign {
    std::vector<ShearCampaignRow> level, other;
    std::vector<long> ids;

    LearningCurveDesign(const std::vector<ShearCampaignRow>& rows, int meshLevel) {
        for (const ShearCampaignRow& r : rows) (r.meshLevel == meshLevel ? level : other).push_back(r);
        std::stable_sort(level.begin(), level.end(), [](const auto& a, const auto& b) { return a.point.caseId < b.point.caseId; });
        for (const ShearCampaignRow& r : level)
            if (ids.empty() || ids.back() != r.point.caseId) ids.push_back(r.point.caseId);
    }
    /// The rows of the first n case ids, then the other levels'.
    std::vector<ShearCampaignRow> rows(long n) const {
        if (n < 0 || n > long(ids.size()))
            throw InputError(fmt::format("learning curve: {} cases asked, {} in the campaign", n, ids.size()));
        std::vector<ShearCampaignRow> out;
        for (const ShearCampaignRow& r : level)
            if (n > 0 && r.point.caseId <= ids[std::size_t(n - 1)]) out.push_back(r);
        out.insert(out.end(), other.begin(), other.end());
        return out;
    }
};

}  // namespace

std::vector<ShearCampaignRow> flowLearningCurveRows(const std::vector<ShearCampaignRow>& rows, int level, long n) {
    return LearningCurveDesign(rows, level).rows(n);
}

FlowLearningCurve flowLearningCurve(const std::vector<ShearCampaignRow>& rows, int level, const std::vector<long>& sizes,
                                    const FlowSurrogateTrainingOptions& opt, int folds) {
    const LearningCurveDesign design(rows, level);
    FlowLearningCurve curve;
    curve.available = long(design.ids.size());
    for (long n : sizes) {
        if (n > curve.available) {
            curve.skipped.push_back(n);
            continue;
        }
        curve.points.push_back({n, crossValidateFlowSurrogate(design.rows(n), opt, folds).pooled});
    }
    return curve;
}

nlohmann::json flowAccuracyJson(const FlowAccuracy& a) {
    auto num = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(nullptr); };
    return {{"cases", a.cases},
            {"tank_treading_cases", a.tankTreading},
            {"inclination_rmse_deg", num(a.inclinationRmseDeg)},
            {"swing_rmse_deg", num(a.swingRmseDeg)},
            {"ttf_relative_rmse", num(a.ttfRelativeRmse)},
            {"steady_cases", a.steady},
            {"inclination_rmse_steady_deg", num(a.inclinationRmseSteadyDeg)},
            {"ttf_relative_rmse_steady", num(a.ttfRelativeRmseSteady)},
            {"campaign_inclination_se_rms_deg", num(a.inclinationNoiseDeg)},
            {"campaign_ttf_relative_se_rms", num(a.ttfRelativeNoise)},
            {"brier", num(a.brier)},
            {"far_cases", a.far},
            {"far_misclassified", a.farMisclassified},
            {"near_cases", a.near},
            {"near_misclassified", a.nearMisclassified}};
}

std::string flowAccuracyRow(const std::string& label, const FlowAccuracy& a) {
    return fmt::format("| {} | {} | {:.3f} | {:.3f} | {:.2f} % | {:.3f} / {:.2f} % ({}) | {:.3f} / {:.2f} % | {} | {} | {:.4f} |", label,
                       a.cases, a.inclinationRmseDeg, a.swingRmseDeg, 100.0 * a.ttfRelativeRmse, a.inclinationRmseSteadyDeg,
                       100.0 * a.ttfRelativeRmseSteady, a.steady, a.inclinationNoiseDeg, 100.0 * a.ttfRelativeNoise,
                       percent(a.farMisclassified, a.far), percent(a.nearMisclassified, a.near), a.brier);
}

nlohmann::json flowTrainingJson(const FlowTrainingSummary& s) {
    const FlowSurrogateTrainingReport& rep = s.training;
    nlohmann::json sources = nlohmann::json::array();
    for (const FlowTrainingSource& c : s.sources)
        sources.push_back({{"campaign", c.campaign}, {"cases", c.cases}, {"level", c.level}, {"complete", c.complete}});
    nlohmann::json j = withBuild({{"command", s.options.command}, {"campaigns", sources}, {"restarts", s.options.restarts},
                                  {"ensemble", s.options.ensemble}, {"boundary_factor", s.options.boundaryFactor}});
    j["levels"] = rep.model.levels;
    j["predicts_level"] = rep.model.level;
    if (!rep.model.start.empty()) j["start"] = rep.model.start;
    if (!rep.model.tankTreadingStart.empty()) j["tank_treading_start"] = rep.model.tankTreadingStart;
    j["hidden_layers"] = s.options.network.hiddenLayers;
    j["goals"] = {{"inclination_rmse_deg", kFlowAccuracyGoals.inclinationRmseDeg},
                  {"ttf_relative_rmse", kFlowAccuracyGoals.ttfRelativeRmse},
                  {"far_misclassified_fraction", kFlowAccuracyGoals.farMisclassifiedFraction}};
    j["data_hash"] = rep.dataHash;
    j["rows"] = rep.rows;
    j["finished_rows"] = rep.used;
    j["training_rows"] = {{"regime", rep.regimeRows}, {"tank_treading", rep.tankTreadingRows}};
    j["test"] = flowAccuracyJson(rep.test);
    j["wall_s"] = rep.wallSeconds;
    if (s.crossValidation) j["cross_validation"] = {{"folds", s.crossValidation->folds}, {"pooled", flowAccuracyJson(s.crossValidation->pooled)}};
    if (s.learningCurve) {
        nlohmann::json curve = nlohmann::json::array();
        for (const FlowLearningCurvePoint& p : *s.learningCurve) curve.push_back({{"cases", p.cases}, {"pooled", flowAccuracyJson(p.pooled)}});
        j["learning_curve"] = curve;
    }
    return j;
}

std::string flowAccuracyMarkdown(const FlowTrainingSummary& s) {
    std::string from;
    for (const FlowTrainingSource& c : s.sources)
        from += fmt::format("{}{} ({} cases{}{})", from.empty() ? "" : " and ", c.campaign, c.cases,
                            c.level > 0 ? fmt::format(", level {}", c.level) : "", c.complete ? "" : ", not complete");
    std::string md;
    if (s.training.model.multiLevel())
        md = fmt::format("Multi-level networks (the mesh level an input); every accuracy below is on held-out level-{} cases, "
                         "with every coarser case in training.\n\n", s.training.model.level);
    const FlowSurrogate& m = s.training.model;
    if (!m.tankTreadingStart.empty() && m.tankTreadingStart != m.start)
        md += fmt::format("The regime network learns from the {} starts, the tank-treading network from the {} starts of the same "
                          "design; a held-out case is out of both.\n\n", m.start, m.tankTreadingStart);
    md += fmt::format("Flow networks from {}; command: `{}`\n\nGoals: angle RMSE ≤ {:g}°, TTF RMSE ≤ {:g} %, misclassified far from "
                      "the boundary ≤ {:g} %.\n\n{}\n",
                      from, s.options.command, kFlowAccuracyGoals.inclinationRmseDeg, 100.0 * kFlowAccuracyGoals.ttfRelativeRmse,
                      100.0 * kFlowAccuracyGoals.farMisclassifiedFraction, kTableHead);
    md += flowAccuracyRow(fmt::format("held out ({:.0f} %)", 100.0 * s.options.testFraction), s.training.test) + "\n";
    if (s.crossValidation) md += flowAccuracyRow(fmt::format("{}-fold CV", s.crossValidation->folds), s.crossValidation->pooled) + "\n";
    if (s.learningCurve) {
        md += fmt::format("\nLearning curve ({}-fold CV on the first N cases of the design)\n\n{}\n", s.learningCurveFolds, kTableHead);
        for (const FlowLearningCurvePoint& p : *s.learningCurve) md += flowAccuracyRow(fmt::format("N = {}", p.cases), p.pooled) + "\n";
    }
    return md;
}

std::string flowCrossValidationCsv(const FlowCrossValidation& cv) {
    std::string csv = "case_id,start,fold,v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,eta_out_mPa_s,shear_rate_per_s,shear_stress_Pa,regime,steady,"
                      "p_tank_treading,critical_stress_Pa,inclination_deg,inclination_pred_deg,swing_deg,swing_pred_deg,"
                      "ttf_4pi_f_over_rate,ttf_pred\n";
    for (const FlowHeldOutPrediction& e : cv.predictions) {
        const ShearCampaignRow& r = e.row;
        const ShearCampaignPoint& q = r.point;
        csv += fmt::format("{},{},{},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{},{},{:.17g},{:.17g},{:.17g},{:.17g},"
                           "{:.17g},{:.17g},{:.17g},{:.17g}\n",
                           q.caseId, r.start, e.fold, q.cell.v, q.cell.mu, q.cell.FvK, q.cell.b2, q.cell.etam, q.etaOut, q.shearRate,
                           shearStressPa(q.etaOut, q.shearRate), r.regime, int(r.steady), e.pTankTreading, e.criticalStressPa,
                           r.inclinationDeg, e.inclinationDeg, r.swingDeg, e.swingDeg, r.ttf, e.ttf);
    }
    return csv;
}

std::string writeFlowTrainingReport(const fs::path& dir, const FlowTrainingSummary& s) {
    const std::string md = flowAccuracyMarkdown(s);
    if (s.crossValidation) writeFileAtomically(dir / "cv_predictions.csv", flowCrossValidationCsv(*s.crossValidation));
    writeFileAtomically(dir / "training.json", flowTrainingJson(s).dump(2) + "\n");
    writeFileAtomically(dir / "accuracy.md", md);
    return md;
}

}  // namespace trbc
