#include "flow/steady_rule_study.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <regex>

#include "core/error.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

ShearRegime regimeFromName(const std::string& name, const fs::path& file) {
    for (ShearRegime r : {ShearRegime::TankTreading, ShearRegime::Tumbling, ShearRegime::Intermittent})
        if (regimeName(r) == name) return r;
    throw InputError(fmt::format("{}: unknown regime '{}'", file.string(), name));
}

TurnRecord turnFromJson(const nlohmann::json& j, const fs::path& file) {
    TurnRecord r;
    r.turn = j.at("turn").get<int>();
    r.steps = j.at("steps").get<long>();
    r.gmresIterations = j.at("gmres_iterations").get<long>();
    ShearObservables& o = r.observables;
    o.regime = regimeFromName(j.at("regime").get<std::string>(), file);
    o.inclinationDeg = j.at("inclination_deg").get<double>();
    o.swingAmplitudeDeg = j.at("swing_deg").get<double>();
    o.ttf.defined = !j.at("ttf_4pi_f_over_rate").is_null();
    o.ttf4piFOverRate = o.ttf.defined ? j.at("ttf_4pi_f_over_rate").get<double>() : NAN;
    return r;
}

}  // namespace

std::vector<TurnRecord> turnRecords(const CellFlowResult& flow) {
    std::vector<TurnRecord> out;
    const double turn = 4.0 * std::numbers::pi;
    for (TurnObservables& t : observablesByTurn(flow.times, flow.frames, flow.tReached)) {
        TurnRecord r;
        r.turn = t.turn;
        for (const CellFlowStepRecord& s : flow.stepLog)
            if (s.t <= t.turn * turn * (1.0 + 1e-12)) ++r.steps, r.gmresIterations += s.gmresIterations;
        r.observables = std::move(t.observables);
        out.push_back(std::move(r));
    }
    return out;
}

nlohmann::json turnRecordsJson(long caseId, const std::vector<TurnRecord>& turns) {
    nlohmann::json list = nlohmann::json::array();
    for (const TurnRecord& r : turns) {
        const ShearObservables& o = r.observables;
        list.push_back({{"turn", r.turn},
                        {"steps", r.steps},
                        {"gmres_iterations", r.gmresIterations},
                        {"regime", regimeName(o.regime)},
                        {"inclination_deg", o.inclinationDeg},
                        {"swing_deg", o.swingAmplitudeDeg},
                        {"ttf_4pi_f_over_rate", o.ttf.defined ? nlohmann::json(o.ttf4piFOverRate) : nlohmann::json()}});
    }
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
        try {
            std::ifstream in(e.path());
            const nlohmann::json j = nlohmann::json::parse(in);
            FullLengthCase c;
            c.caseId = j.at("case").get<long>();
            for (const nlohmann::json& t : j.at("turns")) c.turns.push_back(turnFromJson(t, e.path()));
            out.push_back(std::move(c));
        } catch (const nlohmann::json::exception& x) {
            throw InputError(fmt::format("{}: not a by-turn record: {}", e.path().string(), x.what()));
        }
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
                steadyBetween(c.turns[k].observables, c.turns[k - 1].observables, rule)) {
                stop = &c.turns[k];
                break;
            }
        e.stopped += stop != &full;
        turns += stop->turn;
        costStop += double(stop->gmresIterations), costFull += double(full.gmresIterations);
        const ShearObservables &a = stop->observables, &b = full.observables;
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

std::string steadyRuleTable(const std::vector<SteadyRuleEffect>& effects) {
    std::string md =
        "| rule: from turn, angle and swing (deg), TTF | cases | stopped early | mean turns | cost of the full runs | regime changed | "
        "tank-treading | angle RMS / max (deg) | swing RMS / max (deg) | TTF RMS / max |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n";
    for (const SteadyRuleEffect& e : effects)
        md += fmt::format("| {:g}, {:g}, {:g} % | {} | {} | {:.2f} | {:.0f} % | {} | {} | {:.3f} / {:.3f} | {:.3f} / {:.3f} | {:.2f} % / {:.2f} % |\n",
                          e.rule.minRotations, e.rule.angleToleranceDeg, 100.0 * e.rule.ttfTolerance, e.cases, e.stopped, e.meanTurns,
                          100.0 * e.costFraction, e.regimeChanged, e.tankTreading, e.angleRmsDeg, e.angleMaxDeg, e.swingRmsDeg,
                          e.swingMaxDeg, 100.0 * e.ttfRelRms, 100.0 * e.ttfRelMax);
    return md;
}

}  // namespace trbc
