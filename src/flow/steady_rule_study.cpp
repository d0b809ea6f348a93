#include "flow/steady_rule_study.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <regex>

#include "core/error.hpp"
#include "core/file_io.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

ShearRegime regimeFromName(const std::string& name, const fs::path& file) {
    for (ShearRegime r : {ShearRegime::TankTreading, ShearRegime::Tumbling, ShearRegime::Intermittent})
        if (regimeName(r) == name) return r;
    throw InputError(fmt::format("{}: unknown regime '{}'", file.string(), name));
}

double numberOrNan(const nlohmann::json& j) { return j.is_null() ? NAN : j.get<double>(); }
nlohmann::json nullIfNan(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

ShearObservables observablesFromJson(const nlohmann::json& j, const fs::path& file) {
    ShearObservables o;
    o.regime = regimeFromName(j.at("regime").get<std::string>(), file);
    o.inclinationDeg = numberOrNan(j.at("inclination_deg"));
    o.swingAmplitudeDeg = numberOrNan(j.at("swing_deg"));
    o.ttf4piFOverRate = numberOrNan(j.at("ttf_4pi_f_over_rate"));
    o.ttf.defined = std::isfinite(o.ttf4piFOverRate);
    return o;
}

nlohmann::json observablesJson(const ShearObservables& o) {
    return {{"regime", regimeName(o.regime)},
            {"inclination_deg", nullIfNan(o.inclinationDeg)},
            {"swing_deg", nullIfNan(o.swingAmplitudeDeg)},
            {"ttf_4pi_f_over_rate", o.ttf.defined ? nullIfNan(o.ttf4piFOverRate) : nlohmann::json()}};
}

}  // namespace

std::vector<TurnRecord> turnRecords(const CellFlowResult& flow) {
    std::vector<TurnRecord> out;
    const std::vector<double>& t = flow.times;
    for (TurnObservables& k : observablesByTurn(t, flow.frames, flow.tReached)) {
        TurnRecord r;
        r.turn = k.turn;
        // The stopping step records frame k.frames - 1 (the first at or after the turn); when the
        // run ends before such a frame, the record is the whole run.
        double stepEnd = flow.tReached;
        if (k.frames < t.size())
            for (const CellFlowStepRecord& s : flow.stepLog)
                if (s.t >= t[k.frames - 1] * (1.0 - 1e-12)) {
                    stepEnd = s.t;
                    break;
                }
        for (const CellFlowStepRecord& s : flow.stepLog)
            if (s.t <= stepEnd) ++r.steps, r.gmresIterations += s.gmresIterations;
        std::size_t recorded = k.frames;
        while (recorded < t.size() && t[recorded] <= stepEnd * (1.0 + 1e-12)) ++recorded;
        r.stop = recorded == k.frames ? k.observables : analyzeFirstShearFrames(t, flow.frames, recorded);
        r.rule = std::move(k.observables);
        out.push_back(std::move(r));
    }
    return out;
}

nlohmann::json turnRecordsJson(long caseId, const std::vector<TurnRecord>& turns) {
    nlohmann::json list = nlohmann::json::array();
    for (const TurnRecord& r : turns)
        list.push_back({{"turn", r.turn},
                        {"steps", r.steps},
                        {"gmres_iterations", r.gmresIterations},
                        {"rule", observablesJson(r.rule)},
                        {"stop", observablesJson(r.stop)}});
    return {{"case", caseId}, {"turns", std::move(list)}};
}

std::vector<FullLengthCase> readFullLengthCases(const fs::path& campaignDir) {
    const fs::path dir = campaignDir / "by_turn";
    std::vector<FullLengthCase> out;
    static const std::regex name(R"(case([0-9]+)\.json)");
    std::error_code ec;
    for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
        std::smatch m;
        const std::string file = e.path().filename().string();
        if (!std::regex_match(file, m, name)) continue;
        FullLengthCase c;
        try {
            std::ifstream in(e.path());
            const nlohmann::json j = nlohmann::json::parse(in);
            c.caseId = j.at("case").get<long>();
            for (const nlohmann::json& t : j.at("turns")) {
                TurnRecord r;
                r.turn = t.at("turn").get<int>();
                r.steps = t.at("steps").get<long>();
                r.gmresIterations = t.at("gmres_iterations").get<long>();
                r.rule = observablesFromJson(t.at("rule"), e.path());
                r.stop = observablesFromJson(t.at("stop"), e.path());
                c.turns.push_back(std::move(r));
            }
        } catch (const nlohmann::json::exception& x) {
            throw InputError(fmt::format("{}: not a by-turn record: {}", e.path().string(), x.what()));
        }
        if (fmt::format("case{}.json", c.caseId) != file)
            throw InputError(fmt::format("{}: holds case {}, not the case of its name", e.path().string(), c.caseId));
        if (c.turns.empty()) throw InputError(fmt::format("{}: no turns", e.path().string()));
        for (std::size_t k = 1; k < c.turns.size(); ++k)
            if (c.turns[k].turn <= c.turns[k - 1].turn)
                throw InputError(fmt::format("{}: turn {} after turn {}: turns must increase", e.path().string(), c.turns[k].turn,
                                             c.turns[k - 1].turn));
        out.push_back(std::move(c));
    }
    if (out.empty())
        throw InputError(fmt::format("{} holds no by_turn/case<id>.json (made by `trbc flow campaign --full-length`)", campaignDir.string()));
    std::sort(out.begin(), out.end(), [](const FullLengthCase& a, const FullLengthCase& b) { return a.caseId < b.caseId; });
    return out;
}

SteadyRuleEffect steadyRuleEffect(const std::vector<FullLengthCase>& cases, const SteadyStopRule& rule) {
    SteadyRuleEffect e;
    e.rule = rule;
    double turns = 0.0, costStop = 0.0, costFull = 0.0, angle2 = 0.0, swing2 = 0.0, ttf2 = 0.0;
    for (const FullLengthCase& c : cases) {
        if (c.turns.empty() || c.turns.back().turn < rule.minRotations) continue;
        ++e.cases;
        const TurnRecord& full = c.turns.back();
        const TurnRecord* stop = &full;
        for (std::size_t k = 1; k + 1 < c.turns.size(); ++k)
            if (c.turns[k].turn >= rule.minRotations && c.turns[k - 1].turn == c.turns[k].turn - 1 &&
                steadyBetween(c.turns[k].rule, c.turns[k - 1].rule, rule)) {
                stop = &c.turns[k];
                break;
            }
        e.stopped += stop != &full;
        turns += stop->turn;
        costStop += double(stop->gmresIterations), costFull += double(full.gmresIterations);
        const ShearObservables &a = stop->stop, &b = full.stop;
        e.regimeChanged += a.regime != b.regime;
        if (a.regime != ShearRegime::TankTreading || b.regime != ShearRegime::TankTreading) continue;
        ++e.tankTreading;
        const double dAngle = std::abs(a.inclinationDeg - b.inclinationDeg), dSwing = std::abs(a.swingAmplitudeDeg - b.swingAmplitudeDeg);
        angle2 += dAngle * dAngle, swing2 += dSwing * dSwing;
        e.angleMaxDeg = std::max(e.angleMaxDeg, dAngle), e.swingMaxDeg = std::max(e.swingMaxDeg, dSwing);
        if (a.ttf.defined && b.ttf.defined) {
            const double dTtf = std::abs(a.ttf4piFOverRate / b.ttf4piFOverRate - 1.0);
            ttf2 += dTtf * dTtf;
            e.ttfRelMax = std::max(e.ttfRelMax, dTtf);
        }
    }
    if (e.cases > 0) e.meanTurns = turns / e.cases;
    if (costFull > 0) e.costFraction = costStop / costFull;
    if (e.tankTreading > 0) {
        e.angleRmsDeg = std::sqrt(angle2 / e.tankTreading);
        e.swingRmsDeg = std::sqrt(swing2 / e.tankTreading);
        e.ttfRelRms = std::sqrt(ttf2 / e.tankTreading);
    }
    return e;
}

void validateSteadyRule(const SteadyStopRule& r, double lastTurn, const std::string& option) {
    if (!(r.minRotations >= 2.0 && r.minRotations <= lastTurn && r.angleToleranceDeg > 0.0 && r.angleToleranceDeg <= 10.0 &&
          r.ttfTolerance > 0.0 && r.ttfTolerance <= 0.5))
        throw InputError(fmt::format("{} {:g},{:g},{:g}: the first turn must be in [2, {:g}], the angle tolerance in (0, 10] deg and "
                                     "the TTF tolerance in (0, 0.5]",
                                     option, r.minRotations, r.angleToleranceDeg, r.ttfTolerance, lastTurn));
}

std::string steadyRuleTable(const std::vector<SteadyRuleEffect>& effects) {
    std::string md =
        "| rule: from turn, angle and swing (deg), TTF | cases | stopped early | mean turns | cost of the full runs | regime changed | "
        "tank-treading | angle RMS / max (deg) | swing RMS / max (deg) | TTF RMS / max |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n";
    for (const SteadyRuleEffect& e : effects) {
        const bool counted = e.cases > 0, tt = e.tankTreading > 0;
        const auto pair = [](bool have, double a, double b, const char* spec) {
            return have ? fmt::format(fmt::runtime(spec), a, b) : std::string("–");
        };
        md += fmt::format("| {:g}, {:g}, {:g} % | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", e.rule.minRotations,
                          e.rule.angleToleranceDeg, 100.0 * e.rule.ttfTolerance, e.cases, e.stopped,
                          counted ? fmt::format("{:.2f}", e.meanTurns) : "–", counted ? fmt::format("{:.0f} %", 100.0 * e.costFraction) : "–",
                          e.regimeChanged, e.tankTreading, pair(tt, e.angleRmsDeg, e.angleMaxDeg, "{:.3f} / {:.3f}"),
                          pair(tt, e.swingRmsDeg, e.swingMaxDeg, "{:.3f} / {:.3f}"),
                          pair(tt, 100.0 * e.ttfRelRms, 100.0 * e.ttfRelMax, "{:.2f} % / {:.2f} %"));
    }
    return md;
}

std::string steadyRuleStudyTitle(const fs::path& campaignDir, std::size_t cases) {
    if (const auto j = tryReadJson(campaignDir / "campaign.json")) {
        try {
            const nlohmann::json& st = j->at("settings");
            return fmt::format("{} full-length cases (level {}, design {}, seed {}, {:g} turns)", cases, st.at("level").get<int>(),
                               st.at("design").get<std::string>(), st.at("seed").get<std::uint64_t>(), st.at("max_rotations").get<double>());
        } catch (const nlohmann::json::exception&) {  // another layout: named by its folder
        }
    }
    fs::path folder = campaignDir.lexically_normal();
    if (folder.filename().empty()) folder = folder.parent_path();  // "DIR/"
    return fmt::format("{} full-length cases of {}", cases, folder.filename().string());
}

}  // namespace trbc
