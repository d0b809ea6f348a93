#include "flow/shear_campaign.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>

#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "flow/shear_case.hpp"
#include "flow/steady_rule_study.hpp"
#include "sampling/part_file.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

constexpr double kPi = std::numbers::pi;

fs::path partsDir(const ShearCampaignOptions& o) { return o.outDir / "parts"; }
fs::path partPath(const ShearCampaignOptions& o, int rank) { return partsDir(o) / fmt::format("rank{}.csv", rank); }
fs::path provenancePath(const ShearCampaignOptions& o) { return o.outDir / "campaign.json"; }
fs::path casesPath(const ShearCampaignOptions& o) { return o.outDir / "cases.csv"; }

/// Everything that decides the rows; a resume must match it exactly.
nlohmann::json settingsJson(const ShearCampaignOptions& o) {
    const SteadyStopRule& rule = o.steadyRule;
    nlohmann::json j = {{"design", designName(o.design)},
                        {"cases", o.cases},
                        {"seed", o.seed},
                        {"level", o.level},
                        {"max_rotations", o.maxRotations},
                        {"start", o.randomStart ? "random" : "in-plane"},
                        {"kick_temperature_K", ShearCaseOptions{}.kickTemperatureK},
                        {"eta_in_mPa_s", o.etaIn},
                        {"box", shearCampaignBoxJson()},
                        {"inject_failures", std::vector<long>(o.injectFailures.begin(), o.injectFailures.end())}};
    // A full-length campaign stops no case, so it has no rule.
    if (o.fullLength)
        j["full_length"] = true;
    else
        j["steady_rule"] = {{"min_rotations", rule.minRotations}, {"angle_tolerance_deg", rule.angleToleranceDeg},
                            {"ttf_tolerance", rule.ttfTolerance}};
    return j;
}

void validateOptions(const ShearCampaignOptions& o) {
    if (o.cases < 1 || o.cases > 10'000'000) throw InputError(fmt::format("--cases {} is outside [1, 1e7]", o.cases));
    if (o.threads < 1 || o.threads > 1024) throw InputError(fmt::format("--threads {} is outside [1, 1024]", o.threads));
    if (o.level < 1 || o.level > 5) throw InputError(fmt::format("--level {} is outside [1, 5]", o.level));
    if (!(o.maxRotations >= 5.0 && o.maxRotations <= 1000.0))
        throw InputError(fmt::format("--rotations {} is outside [5, 1000] (the default stop rule compares turns 3 and 4 at the earliest)",
                                     o.maxRotations));
    if (!(o.etaIn > 0.0 && o.etaIn <= 1e6)) throw InputError(fmt::format("--eta-in {} is outside (0, 1e6] mPa s", o.etaIn));
    if (o.outDir.empty()) throw InputError("--out: an output directory is required");
    if (o.fullLength && o.maxRotations != std::floor(o.maxRotations))
        throw InputError(fmt::format("--rotations {:g}: a --full-length campaign runs whole turns (an integer)", o.maxRotations));
    validateSteadyRule(o.steadyRule, o.maxRotations, "--steady-rule");
}

std::string settingsDiff(const nlohmann::json& have, const nlohmann::json& want) {
    std::string diff;
    for (auto& [k, v] : want.items())
        if (!have.contains(k) || have[k] != v)
            diff += fmt::format(" {} (was {}, now {})", k, have.value(k, nlohmann::json()).dump(), v.dump());
    for (auto& [k, v] : have.items())
        if (!want.contains(k)) diff += fmt::format(" {} (was {}, now absent)", k, v.dump());
    return diff;
}

/// A Sobol' or uniform design is a prefix of any larger one with the same seed.
bool canGrow(const nlohmann::json& before, const nlohmann::json& now) {
    if (!before.contains("cases") || now["design"] == "lhs" || before["cases"].get<long>() > now["cases"].get<long>()) return false;
    nlohmann::json same = before;
    same["cases"] = now["cases"];
    return same == now;
}

/// The observables of the frames up to time tEnd (1/rate), or none when too few frames remain.
std::optional<ShearObservables> observablesUpTo(const CellFlowResult& flow, double tEnd) {
    std::vector<double> t;
    std::vector<Vertices> frames;
    for (std::size_t k = 0; k < flow.times.size() && flow.times[k] <= tEnd + 1e-9; ++k) {
        t.push_back(flow.times[k]);
        frames.push_back(flow.frames[k]);
    }
    if (frames.size() < 16) return std::nullopt;
    return analyzeShearFrames(t, frames, 1.0);
}

}  // namespace

ShearCampaignRow runShearCampaignCase(const ShearCampaignPoint& point, const ShearCampaignOptions& o, bool injectFailure) {
    const auto t0 = SteadyClock::now();
    ShearCampaignRow row;
    row.point = point;
    try {
        if (injectFailure) throw NumericalError("injected failure (--inject-failures)");
        ShearCaseOptions c;
        c.etaOut = point.etaOut;
        c.shearRate = point.shearRate;
        c.etaIn = point.etaIn;
        c.cell = point.cell;
        c.allowOutsidePrior = true;  // the campaign's box is wider than the prior (kShearCampaignAxes)
        c.level = o.level;
        c.rotations = o.maxRotations;
        c.randomStart = o.randomStart;
        c.seed = point.startSeed;
        c.stopWhenSteady = !o.fullLength;
        c.steadyRule = o.steadyRule;
        c.cacheDir = o.cacheDir;
        const ShearCaseResult res = runShearCase(c);
        if (!res.completed || !res.observables) throw NumericalError(res.message.empty() ? "the run did not complete" : res.message);
        if (o.fullLength)  // before the row, so that a case in a part file always has its record
            writeFileAtomically(o.outDir / "by_turn" / fmt::format("case{}.json", point.caseId),
                                turnRecordsJson(point.caseId, turnRecords(res.flow)).dump(1) + "\n");
        const ShearObservables& obs = *res.observables;
        const double tEnd = res.flow.times.empty() ? 0.0 : res.flow.times.back();
        row.turns = tEnd / (4.0 * kPi);
        row.steady = res.flow.stoppedEarly;
        row.regime = regimeName(obs.regime);
        if (obs.regime == ShearRegime::TankTreading) {
            row.inclinationDeg = obs.inclinationDeg, row.swingDeg = obs.swingAmplitudeDeg, row.ttf = obs.ttf4piFOverRate;
            const double lastWholeTurn = std::floor(row.turns + 1e-9);
            if (lastWholeTurn >= 3.0) {
                const auto shorter = observablesUpTo(res.flow, 4.0 * kPi * (lastWholeTurn - 1.0));
                if (shorter && shorter->regime == ShearRegime::TankTreading) {
                    row.inclinationSeDeg = std::abs(obs.inclinationDeg - shorter->inclinationDeg);
                    row.swingSeDeg = std::abs(obs.swingAmplitudeDeg - shorter->swingAmplitudeDeg);
                    row.ttfSe = std::abs(obs.ttf4piFOverRate - shorter->ttf4piFOverRate);
                }
            }
        }
    } catch (const std::exception& e) {
        row.status = "failed";
        row.regime.clear();
        row.reason = csvSafe(e.what());
    }
    row.wallSeconds = secondsSince(t0);
    return row;
}

void prepareShearCampaign(const ShearCampaignOptions& o) {
    validateOptions(o);
    std::error_code ec;
    fs::create_directories(partsDir(o), ec);
    if (!ec && o.fullLength) fs::create_directories(o.outDir / "by_turn", ec);
    if (ec) throw InputError(fmt::format("--out: cannot create {}: {}", partsDir(o).string(), ec.message()));
    const nlohmann::json settings = settingsJson(o);
    if (fs::exists(provenancePath(o))) {
        if (!o.resume)
            throw InputError(fmt::format("--out: {} already holds a campaign; add --resume to continue it or choose another directory",
                                         o.outDir.string()));
        nlohmann::json old;
        try {
            std::ifstream in(provenancePath(o));
            old = nlohmann::json::parse(in);
        } catch (const std::exception& e) {
            throw InputError(fmt::format("{}: cannot parse: {}", provenancePath(o).string(), e.what()));
        }
        const nlohmann::json before = old.contains("settings") && old["settings"].is_object() ? old["settings"] : nlohmann::json::object();
        const bool grows = canGrow(before, settings);
        if (!grows && before != settings)
            throw InputError(fmt::format("--resume: {} was made with different settings:{}{}", provenancePath(o).string(),
                                         settingsDiff(before, settings),
                                         before.value("cases", settings["cases"]) != settings["cases"]
                                             ? "; only a sobol or uniform design grows, to more cases"
                                             : ""));
        nlohmann::json entry = withBuild({{"command", o.command}, {"ranks", o.ranks}, {"threads", o.threads}});
        if (before["cases"] != settings["cases"]) {
            entry["grown_from_cases"] = before["cases"];
            old["settings"] = settings;
            old["status"] = "incomplete";
            fs::remove(casesPath(o));
        }
        old["resumed_by"].push_back(entry);
        writeFileAtomically(provenancePath(o), old.dump(2) + "\n");
        return;
    }
    if (fs::exists(casesPath(o)) || !fs::is_empty(partsDir(o)))
        throw InputError(fmt::format("--out: {} holds campaign files but no campaign.json; choose another directory", o.outDir.string()));
    const nlohmann::json j = withBuild({{"command", o.command},
                                        {"experiment", "shear"},
                                        {"ranks", o.ranks},
                                        {"threads", o.threads},
                                        {"status", "running"},
                                        {"settings", settings},
                                        {"columns", shearCampaignCsvHeader()},
                                        {"units", "mu in uN/m, etam in Pa s um, viscosities in mPa s, rate in 1/s; ttf = 4 pi f / rate"}});
    writeFileAtomically(provenancePath(o), j.dump(2) + "\n");
}

CampaignSummary runShearCampaignShare(const ShearCampaignOptions& o, int rank, int ranks) {
    validateOptions(o);
    if (rank < 0 || rank >= ranks) throw InputError(fmt::format("rank {} is outside [0, {})", rank, ranks));
    const auto t0 = SteadyClock::now();
    const auto design = shearCampaignDesign(o.design, o.cases, o.seed, o.etaIn);
    const auto finished = finishedShearCampaignRows(o.outDir, design);
    std::string keep;
    {
        const fs::path mine = partPath(o, rank);
        if (fs::exists(mine) && fs::file_size(mine) > 0)
            for (const ShearCampaignRow& r : readShearCampaignCsv(mine, true))
                if (finished.count(r.point.caseId) && formatShearCampaignRow(finished.at(r.point.caseId)) == formatShearCampaignRow(r))
                    keep += formatShearCampaignRow(r) + "\n";
    }
    PartFile part(partPath(o, rank), shearCampaignCsvHeader(), keep);

    std::vector<long> pending;
    CampaignProgress prog;
    for (long id = 0; id < o.cases; ++id) {
        if (id % ranks != rank) continue;
        ++prog.cellsTotal;
        const auto it = finished.find(id);
        if (it != finished.end()) {
            ++prog.cellsResumed;
            (it->second.ok() ? prog.rowsOk : prog.rowsFailed)++;
        } else {
            pending.push_back(id);
        }
    }
    prog.cellsDone = prog.cellsResumed;
    if (o.progress) o.progress(prog);

    return runCampaignUnits(pending.size(), o.threads, prog, t0, [&](std::size_t k) {
        const long id = pending[k];
        const ShearCampaignRow row = runShearCampaignCase(design[std::size_t(id)], o, o.injectFailures.count(id) > 0);
        CampaignUnit unit;
        (row.ok() ? unit.ok : unit.failed)++;
        unit.commit = [&part, line = formatShearCampaignRow(row) + "\n"] { part.append(line); };
        return unit;
    }, o.progress);
}

CampaignSummary finalizeShearCampaign(const ShearCampaignOptions& o, double wallSeconds) {
    const auto rows = finishedShearCampaignRows(o.outDir, shearCampaignDesign(o.design, o.cases, o.seed, o.etaIn));
    CampaignSummary s;
    s.wallSeconds = wallSeconds;
    std::map<std::string, long> regimes;
    double caseSeconds = 0.0;
    for (const auto& [id, r] : rows) {
        (r.ok() ? s.ok : s.failed)++;
        ++regimes[r.ok() ? r.regime : std::string("failed")];
        caseSeconds += r.wallSeconds;
    }
    s.samples = long(rows.size());
    s.complete = s.samples == o.cases;
    nlohmann::json j;
    {
        std::ifstream in(provenancePath(o));
        j = nlohmann::json::parse(in);
    }
    if (s.complete) {
        std::string csv = csvProvenance() + shearCampaignCsvHeader() + "\n";
        for (const auto& [id, r] : rows) csv += formatShearCampaignRow(r) + "\n";
        writeFileAtomically(casesPath(o), csv);
    }
    j["status"] = s.complete ? "complete" : "incomplete";
    j["cases_ok"] = s.ok;
    j["cases_failed"] = s.failed;
    j["cases_done"] = s.samples;
    j["regimes"] = regimes;
    j["mean_case_wall_s"] = s.samples ? caseSeconds / double(s.samples) : 0.0;
    j["last_run_wall_s"] = wallSeconds;
    writeFileAtomically(provenancePath(o), j.dump(2) + "\n");
    return s;
}

CampaignSummary runShearCampaign(const ShearCampaignOptions& o) {
    prepareShearCampaign(o);
    const CampaignSummary share = runShearCampaignShare(o, 0, 1);
    CampaignSummary s = finalizeShearCampaign(o, share.wallSeconds);
    s.cellsComputed = share.cellsComputed;
    s.cellsResumed = share.cellsResumed;
    return s;
}

}  // namespace trbc
