#include "analysis/validation_run.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <iostream>

#include "analysis/flow_bands.hpp"
#include "analysis/flow_cross_check.hpp"
#include "analysis/validation_runner.hpp"
#include "analysis/validation_tables.hpp"
#include "core/child_process.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/output_dir.hpp"
#include "core/shell_quote.hpp"
#include "core/version.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

/// The finished `validate --draws` run in `dir` read back into D (loadOnly): the angle, TTF and
/// threshold cases of R's config for the draws its validation.json names, which must be those of
/// its count and seed in R's posterior.
void readDirectRun(ValidationRunner& D, const ValidationRunner& R, const fs::path& dir) {
    const fs::path record = dir / "validation.json";
    const std::optional<json> j = tryReadJson(record);
    if (!j || !j->contains("draws") || !(*j)["draws"].is_object())
        throw InputError(fmt::format("--direct {}: no validation.json with posterior draws (the output of `trbc validate --draws N`)", dir.string()));
    D.cfg = R.cfg;
    D.out = fs::absolute(dir).lexically_normal();
    D.quiet = true;
    D.loadOnly = true;
    const NumericTable samples = readThetaNewSamples(R.cfg.posterior);
    std::vector<long> recorded;
    try {
        const json& d = (*j)["draws"];
        D.seed = d.at("seed").get<std::uint64_t>();
        D.draws = selectPosteriorDraws(samples, d.at("count").get<int>(), D.seed, fmt::format("--direct {}: its draws' count", dir.string()));
        recorded = d.at("samples").get<std::vector<long>>();
    } catch (const json::exception& e) {
        throw InputError(fmt::format("{}: 'draws' needs count, seed and samples ({})", record.string(), e.what()));
    }
    std::vector<long> chosen;
    for (const PosteriorDraw& d : D.draws) chosen.push_back(d.sample);
    if (chosen != recorded)
        throw InputError(fmt::format("--direct {}: its draws are not the samples that seed {} chooses from the {} of {} (a posterior of "
                                     "another size?)",
                                     dir.string(), D.seed, samples.values.rows(), R.cfg.posterior.string()));
    D.posteriorSamples = static_cast<long>(samples.values.rows());
    std::vector<ValidationCase> shear = initialValidationCases(R.cfg);
    std::erase_if(shear, [](const ValidationCase& c) { return c.kind == "tube"; });
    D.runAll(casesWithDraws(shear, D.draws));
    D.refineThresholds();
}

/// `validate --surrogate --direct`: the networks against the direct run (analysis/flow_cross_check.hpp).
json writeCrossCheck(const ValidationRunner& R, const ValidationRunOptions& o, const FlowSurrogate& model, std::string& md) {
    ValidationRunner D{};
    readDirectRun(D, R, o.direct);
    const std::vector<FlowCrossCheckRow> rows = flowCrossCheck(D, model, R.draws);
    if (rows.empty())
        throw InputError(fmt::format("--direct {}: none of the config's angle, TTF or threshold cases has a finished draw there (a run of another config or posterior?)", o.direct.string()));
    // What the comparison holds beside the networks' error: another mesh level, another threshold protocol.
    std::string differs;
    if (model.level > 0 && model.level != D.cfg.level)
        differs += fmt::format(" The networks answer at level {}, the direct runs are of level {}.", model.level, D.cfg.level);
    const std::string directStart = D.cfg.tiltDeg > 0.0 ? fmt::format("tilted by {:g} deg", D.cfg.tiltDeg) : "in-plane";
    if (!model.tankTreadingStart.empty() && model.tankTreadingStart != directStart)
        differs += fmt::format(" The direct angles and TTF start {}, the networks' from {} starts.", directStart, model.tankTreadingStart);
    if (flowSurrogateProtocol(model) != D.cfg.thresholdProtocol)
        differs += fmt::format(" The direct thresholds are of the {} protocol, the networks' of the {}.", D.cfg.thresholdProtocol,
                               flowSurrogateProtocol(model));
    md = fmt::format("# The flow networks against direct runs\n\n{} direct draws (seed {}) of {}, level {}, from {}; the networks' "
                     "{} draws (seed {}); command: `{}`{}\n\n",
                     D.draws.size(), D.seed, R.cfg.posterior.string(), D.cfg.level, D.out.string(), R.draws.size(), R.seed, o.command,
                     differs) +
         flowCrossCheckMarkdown(rows);
    if (!D.missing.empty())
        md += fmt::format("\n{} cases of the configuration (of the configured cell, of the draws, or refinements of their thresholds) "
                          "have no finished record in the direct run; a threshold draw with one of them is left out.\n",
                          D.missing.size());
    writeFileAtomically(R.out / "surrogate_cross_check.csv", flowCrossCheckCsv(rows));
    writeFileAtomically(R.out / "surrogate_cross_check.md", md);
    int agree = 0;
    for (const FlowCrossCheckRow& r : rows) agree += r.agrees;
    return {{"direct", D.out.string()}, {"direct_draws", D.draws.size()}, {"direct_seed", D.seed}, {"compared", rows.size()},
            {"agree", agree}, {"direct_runs_missing", D.missing.size()}};
}

/// `validate --surrogate`: the bands of the shear cases through the flow networks (analysis/flow_bands.hpp).
void runSurrogateBands(const ValidationRunner& R, const ValidationRunOptions& o) {
    if (R.draws.empty())
        throw InputError("--surrogate: give --draws N (and --posterior DIR or [cell] posterior): the bands are over posterior draws");
    const auto t0 = SteadyClock::now();
    const FlowSurrogate model = FlowSurrogate::load(o.surrogate);
    ValidationEvidence evidence(R.cfg.dataDir);
    const std::vector<SurrogateBandRow> rows = surrogateShearBands(R.cfg, model, R.draws, evidence);
    const OutputDirectory outDir(R.out, "validate", "--out", {"surrogate_bands.json"}, {o.config.string()});
    ensureWritableDirectory(R.out.string());
    // The direct run first: a --direct that cannot be read leaves no band file behind, and no
    // cross-check of an earlier run stays beside new bands.
    for (const char* f : {"surrogate_cross_check.csv", "surrogate_cross_check.md"}) fs::remove(R.out / f);
    std::string crossMd;
    const json cross = o.direct.empty() ? json() : writeCrossCheck(R, o, model, crossMd);
    const std::string protocol = flowSurrogateProtocol(model);
    const std::string md = fmt::format("# Shear validations through the flow networks\n\n{} draws of theta_new ({}, {} samples; seed {}), "
                                       "networks {}; command: `{}`\n\nRegimes and thresholds are those of the networks' campaign, "
                                       "threshold protocol: {}{}.{}{}\n\n",
                                       R.draws.size(), R.cfg.posterior.string(), R.posteriorSamples, R.seed, o.surrogate.string(), o.command,
                                       protocol, protocol == "ensemble" ? " (random starts, a draw tank-treads when more than half of them do)" : "",
                                       protocol == R.cfg.thresholdProtocol
                                           ? ""
                                           : fmt::format(" The configuration's threshold protocol, {}, is not the networks'.",
                                                         R.cfg.thresholdProtocol),
                                       model.tankTreadingStart.empty()
                                           ? ""
                                           : fmt::format(" The angles and TTF are the tank-treading state's from {} starts.",
                                                         model.tankTreadingStart)) +
                           surrogateBandsMarkdown(rows);
    writeFileAtomically(R.out / "surrogate_bands.csv", surrogateBandsCsv(rows));
    writeFileAtomically(R.out / "surrogate_bands.md", md);
    json tally = json::object();
    for (const SurrogateBandRow& r : rows) {
        json& t = tally[r.c.kind];
        if (t.is_null()) t = {{"compared", 0}, {"band_overlap", 0}, {"within_mcse", 0}};
        t["compared"] = t["compared"].get<int>() + 1;
        t["band_overlap"] = t["band_overlap"].get<int>() + (r.verdict == "overlap");
        t["within_mcse"] = t["within_mcse"].get<int>() + r.withinMcse;
    }
    json j = {{"provenance", withBuild({{"command", o.command}})},
              {"surrogate", fs::absolute(o.surrogate).lexically_normal().string()},
              {"posterior", R.cfg.posterior.string()},
              {"draws", R.draws.size()},
              {"seed", R.seed},
              {"config", R.cfg.file.string()},
              {"threshold_protocol", protocol},
              {"kinds", tally}};
    if (!cross.is_null()) j["cross_check"] = cross;
    j["wall_s"] = secondsSince(t0);
    writeFileAtomically(R.out / "surrogate_bands.json", j.dump(2) + "\n");
    if (!R.quiet) std::cerr << fmt::format("validate --surrogate: {} rows in {:.2f} s\n", rows.size(), secondsSince(t0));
    std::cout << md << (crossMd.empty() ? "" : "\n" + crossMd);
}

/// The configuration with the command line's overrides, the output and import directories, the tools.
void configureRunner(ValidationRunner& R, const ValidationRunOptions& o) {
    setProvenanceSeed(o.seed);
    R.cfg = readValidationConfig(o.config, o.experimentDir);
    if (!o.posterior.empty()) R.cfg.cellSource = "posterior", R.cfg.posterior = fs::absolute(o.posterior).lexically_normal();
    if (o.jobs > 0) R.cfg.jobs = o.jobs;
    if (o.level > 0) R.cfg.level = o.level;
    if (!o.thresholdProtocol.empty()) R.cfg.thresholdProtocol = o.thresholdProtocol;
    if (o.threads > 0) R.cfg.threads = o.threads;
    if (o.draws > 0 && R.cfg.cellSource != "posterior")
        throw InputError(fmt::format("--draws {}: draws are taken from a theta_new posterior; give --posterior DIR (or [cell] "
                                     "source = \"posterior\" in {})", o.draws, o.config.string()));
    if (R.cfg.cellSource == "posterior") {
        const NumericTable samples = readThetaNewSamples(R.cfg.posterior, o.posterior.empty() ? "cell.posterior" : "--posterior");
        if (o.draws > 0) R.draws = selectPosteriorDraws(samples, o.draws, o.seed, "--draws");
        R.seed = o.seed;
        R.posteriorSamples = static_cast<long>(samples.values.rows());
    }
    R.out = fs::absolute(o.out).lexically_normal();
    R.quiet = o.quiet;
    R.retryFailed = o.retryFailed;
    R.dryRun = o.dryRun;
    for (const std::string& d : o.imports) {
        const fs::path dir = fs::absolute(d).lexically_normal();
        if (!fs::is_directory(dir / "cases"))
            throw InputError(fmt::format("--import {}: not a validate output directory (no cases/ in it)", d));
        R.imports.push_back(dir);
    }
    R.exe = o.exe;
}

/// The initial cases of --only and --shard.
std::vector<ValidationCase> selectedCases(std::vector<ValidationCase> initial, const ValidationRunOptions& o) {
    if (!o.only.empty())
        std::erase_if(initial, [&](const ValidationCase& c) { return std::find(o.only.begin(), o.only.end(), c.kind) == o.only.end(); });
    if (!o.shard.empty()) {
        const auto [part, parts] = parseShard(o.shard, "--shard");
        initial = validationShard(initial, part, parts);
    }
    return initial;
}

/// --dry-run: every case with its command. A case whose record in OUT has the same key is marked:
/// a run would not repeat it ([failed]: kept as failed unless --retry-failed, which makes
/// loadFinished refuse it).
void listCases(ValidationRunner& R, const std::vector<ValidationCase>& initial) {
    int finished = 0, failed = 0;
    for (const ValidationCase& c : initial) {
        const bool done = R.loadFinished(c);
        const bool ok = done && R.resultOf(c.id).value("status", "") == "ok";
        finished += ok;
        failed += done && !ok;
        std::cout << c.id << (ok ? " [finished]" : done ? " [failed]" : "") << ": trbc " << R.caseArgs(c) << "\n";
    }
    if (!R.quiet)
        std::cerr << fmt::format("validate: {} case(s) in {}: {} finished{}, {} failed and kept, {} to run\n",
                                 initial.size(), R.out.string(), finished,
                                 R.imports.empty() ? std::string() : fmt::format(" ({} in --import directories)", R.imported),
                                 failed, initial.size() - finished - failed);
}

void drawValidationFigures(const ValidationRunner& R, const ValidationRunOptions& o) {
    const std::string plot = shellQuote(o.python) + " " + shellQuote(o.scripts / "plot_validation.py") + " " + shellQuote(R.out) + " --data " +
                             shellQuote(R.cfg.dataDir) + " > " + shellQuote(R.out / "plot.log") + " 2>&1";
    if (std::system(plot.c_str()) != 0)
        std::cerr << fmt::format("validate: warning: the figures failed (see {})\n", (R.out / "plot.log").string());
}

void printValidationSummary(const ValidationRunner& R, const json& summary, std::size_t selected, std::size_t configured, double wall) {
    if (selected < configured)
        std::cout << fmt::format("trbc validate: --only/--shard: {} of the {} configured initial cases selected\n", selected, configured);
    std::cout << fmt::format("trbc validate: {} cases ({} failed, {} run now) in {:.1f} min; {} predictions inside the experimental "
                             "scatter, {} outside, {} without data, {} neither\n  tables: {}/{{shear,threshold,tube,comparison}}.csv\n  "
                             "summary: {}\n  figures: {}\n",
                             summary["cases"].get<int>(), summary["failed"].get<int>(), R.ranHere, wall / 60.0,
                             summary["inside"].get<int>(), summary["outside"].get<int>(), summary["no_data"].get<int>(),
                             summary["other"].get<int>(),
                             R.out.string(), (R.out / "validation.md").string(), (R.out / "figures").string());
    if (!summary.contains("draws")) return;
    int compared = 0, inside = 0, overlap = 0, marginal = 0;
    for (const auto& [kind, t] : summary["draws"]["kinds"].items())
        compared += t["compared"].get<int>(), inside += t["mean_cell_inside"].get<int>(), overlap += t["band_overlap"].get<int>(),
            marginal += t["band_verdict_within_mcse"].get<int>();
    std::cout << fmt::format("  posterior draws: {} (seed {}), {} runs ({} failed); of {} observables compared, the 5-95 % band "
                             "overlaps the scatter in {} (the configured cell is inside in {}); {} band verdicts within the "
                             "bands' Monte Carlo error; tables: {}/{{draws,bands}}.csv\n",
                             R.draws.size(), R.seed, summary["draws"]["runs"].get<int>(), summary["draws"]["runs_failed"].get<int>(),
                             compared, overlap, inside, marginal, R.out.string());
}

}  // namespace

void runValidation(const ValidationRunOptions& o) {
    if (!o.direct.empty() && o.surrogate.empty())
        throw InputError(fmt::format("--direct {}: compares the flow networks with a direct run; give --surrogate MODEL", o.direct.string()));
    ValidationRunner R{};
    configureRunner(R, o);
    const std::vector<ValidationCase> all = initialValidationCases(R.cfg);
    const std::vector<ValidationCase> selected = selectedCases(all, o);
    const std::vector<ValidationCase> initial = casesWithDraws(selected, R.draws);
    if (o.dryRun) return listCases(R, initial);
    if (!o.surrogate.empty()) return runSurrogateBands(R, o);
    const OutputDirectory outDir(R.out, "validate", "--out", {"validation.json", "cases"}, {o.config.string()});
    ensureWritableDirectory(R.out.string());
    fs::create_directories(R.out / "cases");
    forwardSignalsToChildren();
    const auto t0 = SteadyClock::now();
    R.runAll(initial);
    if (o.only.empty() || std::find(o.only.begin(), o.only.end(), "threshold") != o.only.end()) R.refineThresholds();
    json bandRows;
    const json summary = writeValidationTables(R, bandRows);
    const double wall = secondsSince(t0);
    const ValidationSelection selection{o.only, o.imports, o.shard, o.command};
    writeFileAtomically(R.out / "validation.json", validationRecord(R, selection, summary, bandRows, all.size(), wall).dump(2) + "\n");
    drawValidationFigures(R, o);
    printValidationSummary(R, summary, selected.size(), all.size(), wall);
    if (summary["failed"].get<int>() > 0)
        throw NumericalError(fmt::format("validate: {} case(s) failed (see validation.md and cases/)", summary["failed"].get<int>()));
}

}  // namespace trbc
