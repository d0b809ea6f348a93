#include "analysis/validation_runner.hpp"

#include <fmt/format.h>
#include <sys/wait.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <exception>
#include <fstream>
#include <iostream>
#include <iterator>
#include <thread>

#include "analysis/calibrated_cell.hpp"
#include "core/child_process.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/shell_quote.hpp"
#include "core/version.hpp"
#include "experiments/parameters.hpp"
#include "flow/flow_record.hpp"
#include "flow/tube.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
/// A string field of the runner's own case file, "" when absent or not a string.
std::string stringOr(const json& o, const char* key) {
    const auto it = o.find(key);
    return it != o.end() && it->is_string() ? it->get<std::string>() : "";
}
std::string num(double x) { return std::isfinite(x) ? fmt::format("{:.6g}", x) : ""; }

/// FNV-1a of a table's bytes after its leading '#' lines, "missing" when it does not exist: the
/// provenance line names the command and build that wrote the samples, not their values, so a
/// posterior rewritten by `infer --resume` keeps its cases.
std::string tableFingerprint(const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) return "missing";
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::size_t start = 0;
    while (start < text.size() && text[start] == '#') start = std::min(text.find('\n', start), text.size() - 1) + 1;
    return fmt::format("{:016x}", fnv1a(std::string_view(text).substr(start)));
}

}  // namespace

const PosteriorDraw& ValidationRunner::drawOf(long sample) const {
    return *std::find_if(draws.begin(), draws.end(), [&](const PosteriorDraw& d) { return d.sample == sample; });
}

std::string ValidationRunner::cellArgs(const ValidationCase& c) const {
    if (c.sample >= 0) {
        const PosteriorDraw& d = drawOf(c.sample);
        return fmt::format("--v {} --mu {} --kb {} --b2 {} --etam {} --allow-outside-prior", d.v, d.mu, d.kbJ, d.b2,
                           d.etam);
    }
    if (cfg.cellSource == "posterior") return "--posterior " + shellQuote(cfg.posterior);
    if (cfg.cellSource == "explicit")
        return fmt::format("--v {} --mu {} --kb {} --b2 {} --etam {}", cfg.v, cfg.mu, cfg.kbJ, cfg.b2, cfg.etam);
    return "";  // the flow commands' default: the paper's Table 1 means
}

std::string ValidationRunner::cellKey(const ValidationCase& c) const {
    if (c.sample >= 0) return cellArgs(c);
    if (cfg.cellSource == "posterior") {
        // The calibrated cell reads the inference's posterior_stats.csv when there is one (calibratedCell).
        const fs::path stats = posteriorStatsOf(cfg.posterior);
        const fs::path samples = fs::is_directory(cfg.posterior) ? cfg.posterior / "samples.csv" : cfg.posterior;
        return fmt::format("{} {}{}{}", cellArgs(c), tableFingerprint(samples), stats.empty() ? "" : " ",
                           stats.empty() ? std::string() : tableFingerprint(stats));
    }
    if (cfg.cellSource == "explicit") return cellArgs(c);
    return fmt::format("table1 v={} mu={} kb={} b2={} etam={}", table1::v, table1::mu, table1::kbJ, table1::b2, table1::etam);
}

std::string ValidationRunner::caseArgs(const ValidationCase& c) const {
    if (c.kind == "tube")
        return fmt::format("flow tube --radius {} --pressure-gradient {} --eta-out {} --level {} --duration {} "
                           "--settle {} {} --settle-tol {} --step-tol {} {}",
                           cfg.tubeRadius, c.pressureGradient, cfg.tubeEtaOut, cfg.tubeLevel > 0 ? cfg.tubeLevel : cfg.level,
                           cfg.tubeDuration, cfg.tubeSettle,
                           cfg.tubeSettleEtam > 0.0 ? fmt::format("--settle-etam {}", cfg.tubeSettleEtam)
                                                    : fmt::format("--settle-relax {}", cfg.tubeSettleRelax),
                           cfg.tubeSettleTol, cfg.tubeStepTol > 0.0 ? cfg.tubeStepTol : kTubeStepTolerance, cellArgs(c));
    // An ensemble member starts at random (seed = member), not from the configured tilt; a
    // fluctuating member starts from it, its noise seeded by the member.
    const bool ensemble = c.member > 0 && cfg.thresholdProtocol == "ensemble";
    const std::string tilt = cfg.tiltDeg > 0.0 ? fmt::format(" --tilt-deg {}", cfg.tiltDeg) : std::string();
    const std::string start = ensemble       ? fmt::format(" --start random --seed {}", c.member)
                              : c.member > 0 ? fmt::format("{} --temperature {} --seed {}", tilt, cfg.temperatureK, c.member)
                                             : tilt;
    return fmt::format("flow shear --eta-out {} --shear-rate {} --eta-in {} --level {} --rotations {} "
                       "--step-tol {}{}{} {}",
                       c.etaOut, c.rate, cfg.etaIn, cfg.level, cfg.rotations, cfg.stepTol, start,
                       cfg.stopWhenSteady ? " --stop-when-steady" : "", cellArgs(c));
}

std::string ValidationRunner::caseKey(const ValidationCase& c) const { return fingerprintOf({kVersion, caseArgs(c), cellKey(c)}); }

json ValidationRunner::drawJson(long sample) const {
    const PosteriorDraw& d = drawOf(sample);
    return {{"sample", d.sample}, {"seed", seed}, {"posterior", cfg.posterior.string()},
            {"cell", {{"v", d.v}, {"mu_uN_per_m", d.mu}, {"kb_J", d.kbJ}, {"b2", d.b2}, {"etam_Pa_s_um", d.etam}}}};
}

fs::path ValidationRunner::caseFile(const ValidationCase& c) const { return out / "cases" / (c.id + ".json"); }

std::optional<json> ValidationRunner::matchingRecord(const fs::path& file, const ValidationCase& c) const {
    std::optional<json> j = tryReadJson(file);  // a damaged record is run again
    if (!j || stringOr(*j, "key") != caseKey(c) || !j->contains("result")) return std::nullopt;
    try {
        if (!readFlowRecord((*j)["result"], file.string()).ok() && retryFailed) return std::nullopt;
    } catch (const InputError&) {
        return std::nullopt;
    }
    return j;
}

bool ValidationRunner::loadFinished(const ValidationCase& c) {
    std::optional<json> j = matchingRecord(caseFile(c), c);
    for (auto from = imports.begin(); !j && from != imports.end(); ++from) {
        const fs::path source = *from / "cases";
        j = matchingRecord(source / (c.id + ".json"), c);
        if (!j) continue;
        ++imported;
        if (dryRun) continue;
        const fs::path dir = out / "cases" / c.id;
        fs::remove_all(dir);
        if (fs::is_directory(source / c.id)) fs::copy(source / c.id, dir, fs::copy_options::recursive);
        writeFileAtomically(caseFile(c), j->dump(1) + "\n");
    }
    if (!j) return false;
    std::lock_guard lock(mutex);
    results[c.id] = std::move(*j);
    return true;
}

void ValidationRunner::runCase(const ValidationCase& c) {
    // A case interrupted earlier continues from its snapshots (flow --resume, docs/FLOW.md
    // "Checkpoints"); otherwise its directory starts empty.
    // "checkpoint.key" tells whether the snapshots are of this case as configured now.
    const fs::path dir = out / "cases" / c.id, keyFile = dir / "checkpoint.key";
    const std::string key = caseKey(c);
    const bool resuming = fs::is_directory(dir / "checkpoint") && fs::exists(keyFile) && readFileBytes(keyFile) == key;
    if (!resuming) fs::remove_all(dir);
    fs::create_directories(dir);
    writeFileAtomically(keyFile, key);
    const fs::path stdoutFile = out / "cases" / (c.id + ".stdout"), log = out / "cases" / (c.id + ".log");
    const std::string command =
        fmt::format("{} {} --threads {} --out {} --vtk-every 50 --resume --checkpoint-interval {}", shellQuote(exe),
                    caseArgs(c), cfg.threads, shellQuote(dir), cfg.checkpointInterval);
    const auto t0 = SteadyClock::now();
    // exec: the shell becomes the case, so no process stands between validate and the solver.
    const int rc = childExitCode(runChildProcess("exec " + command + " > " + shellQuote(stdoutFile) + (resuming ? " 2>> " : " 2> ") +
                                                 shellQuote(log) + " < /dev/null"));
    const double wall = secondsSince(t0);
    // SIGINT/SIGTERM/SIGHUP of validate are forwarded to the cases and end validate itself
    // (child_process.hpp): those cases run again on resume. A case interrupted on its own is not
    // recorded either; one killed alone otherwise (out of memory, a kill of the child) is recorded
    // as failed with the signal.
    if (rc == 130 || rc == 128 + SIGINT || forwardedSignal() != 0)
        throw NumericalError(fmt::format("validate: case {} interrupted (exit {}); run the same command again to resume", c.id, rc));
    // Exit 5: the case could not write its outputs (a full disk): not a result of the case,
    // so nothing is recorded and the run stops; the same command resumes once there is room.
    if (rc == 5) {
        std::string tail = readFileBytes(log);
        if (tail.size() > 600) tail = tail.substr(tail.size() - 600);
        while (!tail.empty() && tail.back() == '\n') tail.pop_back();
        throw IoError(fmt::format("validate: case {} could not write its outputs in {} ({})", c.id, dir.string(),
                                  tail.substr(tail.rfind('\n') == std::string::npos ? 0 : tail.rfind('\n') + 1)));
    }
    json result = tryReadJson(stdoutFile).value_or(json());
    if (!result.is_object()) {
        std::string tail = readFileBytes(log);
        if (tail.size() > 600) tail = "..." + tail.substr(tail.size() - 600);
        result = {{"status", "failed"},
                  {"reason", rc > 128 ? fmt::format("killed by signal {} without a result: {}", rc - 128, tail)
                                      : fmt::format("exit {} without a result: {}", rc, tail)}};
    }
    // A result the record reader refuses fails its case, as one that is not JSON does.
    bool ok = false;
    try {
        ok = readFlowRecord(result, caseFile(c).string()).ok();
    } catch (const InputError& e) {
        result = {{"status", "failed"}, {"reason", e.what()}};
    }
    if (rc != 0 && ok) result["status"] = "failed";
    json record = {{"key", caseKey(c)}, {"case", c.id}, {"kind", c.kind}, {"command", command},
                   {"exit", rc},         {"wall_s", wall}, {"result", result}};
    if (c.sample >= 0) record["draw"] = drawJson(c.sample);
    if (c.member > 0) record["member"] = c.member;
    writeFileAtomically(caseFile(c), record.dump(1) + "\n");
    fs::remove(stdoutFile);
    std::lock_guard lock(mutex);
    results[c.id] = record;
    ++done;
    ++ranHere;
    caseSeconds += wall;
    if (!quiet) {
        const FlowRecordView r = readFlowRecord(result, caseFile(c).string());
        std::string what;
        if (r.ok() && c.kind != "tube")
            what = fmt::format("{} angle {} TTF {}", r.regime.empty() ? "?" : r.regime, num(r.inclinationDeg), num(r.ttf));
        else if (r.ok())
            what = fmt::format("v {} cm/s, length {} um", num(r.velocityCmPerS), num(r.lengthUm));
        else
            what = "FAILED: " + shortenedReason(r.reason.empty() ? "?" : r.reason, 160);
        const double elapsed = secondsSince(start);
        const double eta = (total - done) * (caseSeconds / ranHere) / cfg.jobs;
        std::cerr << fmt::format("validate: [{}/{}] {} ({:.0f} s): {}; elapsed {:.0f} min, ETA {:.0f} min\n", done, total, c.id, wall, what,
                                 elapsed / 60.0, eta / 60.0);
    }
}

void ValidationRunner::runAll(const std::vector<ValidationCase>& batch) {
    std::vector<ValidationCase> todo;
    for (const ValidationCase& c : batch) {
        const bool finished = loadFinished(c);
        if (!finished && loadOnly) {  // not a case of this run
            missing.emplace(c.id, c);  // a refinement round asks for the same case again
            continue;
        }
        cases.push_back(c);
        ++total;
        if (finished)
            ++done;
        else
            todo.push_back(c);
    }
    if (loadOnly) return;
    if (!quiet && !batch.empty())
        std::cerr << fmt::format("validate: {} case(s), {} finished earlier{}, {} to run ({} at a time, {} thread(s) each)\n",
                                 batch.size(), batch.size() - todo.size(),
                                 imports.empty() ? std::string() : fmt::format(" ({} imported so far)", imported), todo.size(),
                                 cfg.jobs, cfg.threads);
    std::atomic<std::size_t> next{0};
    std::exception_ptr error;
    auto worker = [&]() {
        for (std::size_t k; (k = next++) < todo.size();) {
            try {
                runCase(todo[k]);
            } catch (...) {
                std::lock_guard lock(mutex);
                if (!error) error = std::current_exception();
                next = todo.size();
            }
        }
    };
    std::vector<std::thread> pool;
    for (int j = 0; j < std::min<int>(cfg.jobs, static_cast<int>(todo.size())); ++j) pool.emplace_back(worker);
    for (std::thread& t : pool) t.join();
    if (error) std::rethrow_exception(error);
}

const json& ValidationRunner::resultOf(const std::string& id) const { return results.at(id).at("result"); }

std::vector<RegimePoint> ValidationRunner::thresholdPoints(double eta, long sample) const {
    std::vector<RegimePoint> p;
    for (const ValidationCase& c : cases)
        if (c.kind == "threshold" && c.etaOut == eta && c.sample == sample) {
            const FlowRecordView r = readFlowRecord(resultOf(c.id), caseFile(c).string());
            p.push_back({c.rate, r.ok() ? r.regime : ""});
        }
    return thresholdMemberCount(cfg) > 0 ? ensembleRegimePoints(p) : p;
}

void ValidationRunner::refineThresholds() {
    std::vector<long> samples = {-1};
    for (const PosteriorDraw& d : draws) samples.push_back(d.sample);
    for (int round = 0; round < cfg.thresholdRefinements; ++round) {
        std::vector<ValidationCase> more;
        for (double eta : thresholdViscosities(cfg))
            for (const long sample : samples)
                if (const auto rate = refinementRate(thresholdPoints(eta, sample))) {
                    const std::string mean = uniqueShearCaseId("threshold", eta, *rate, cases);
                    const int members = thresholdMemberCount(cfg);
                    for (int k = members > 0 ? 1 : 0; k <= members; ++k) {
                        const std::string member = k > 0 ? memberCaseId(mean, k) : mean;
                        const std::string id = sample < 0 ? member : drawCaseId(member, sample);
                        if (!results.count(id)) more.push_back({id, "threshold", eta, *rate, 0.0, sample, k});
                    }
                }
        if (more.empty()) break;
        if (!quiet) std::cerr << fmt::format("validate: threshold refinement {}: {} case(s)\n", round + 1, more.size());
        runAll(more);
    }
}

}  // namespace trbc
