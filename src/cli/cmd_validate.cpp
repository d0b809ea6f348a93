// trbc validate: the flow-validation set of docs/VALIDATE.md and docs/VALIDATION_RESULTS.md. Every
// case is a `trbc flow shear|tube` child process whose JSON is kept in OUT/cases/<id>.json with a
// key of its command; a killed run loses no finished case (resume = run again). The tumbling /
// tank-treading brackets are refined by bisection; the results are tabulated against the
// experimental scatter and drawn by scripts/plot_validation.py.
#include <fmt/format.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "analysis/stage_ledger.hpp"
#include "analysis/validation.hpp"
#include "analysis/validation_draws.hpp"
#include "cli/child_process.hpp"
#include "cli/common.hpp"
#include "core/output_dir.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "analysis/flow_bands.hpp"
#include "experiments/parameters.hpp"
#include "flow/tube.hpp"

namespace trbc::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string num(const json& j) { return j.is_number() ? fmt::format("{:.6g}", j.get<double>()) : ""; }

/// A string field of an object, "" when absent or not a string.
std::string stringOr(const json& o, const char* key) {
    const auto it = o.find(key);
    return it != o.end() && it->is_string() ? it->get<std::string>() : "";
}

/// A numeric field of an object, NaN when absent or null (a failed or undefined observable).
double numberOr(const json& o, const char* key) {
    const auto it = o.find(key);
    return it != o.end() && it->is_number() ? it->get<double>() : NAN;
}

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

struct Runner {
    ValidationConfig cfg;
    fs::path out, exe, python, scripts;
    bool quiet = false, retryFailed = false, dryRun = false;
    std::vector<fs::path> imports;  ///< other OUT directories whose finished cases count as finished here
    int imported = 0;               ///< cases taken from them
    std::mutex mutex;
    std::map<std::string, json> results;  ///< case id -> {"key", "command", "exit", "wall_s", "result"}
    std::vector<ValidationCase> cases;    ///< every case so far, in order
    std::vector<PosteriorDraw> draws;     ///< --draws: the posterior draws run beside the configured cell
    std::uint64_t seed = 0;               ///< of their choice
    long posteriorSamples = 0;            ///< samples in the posterior they are drawn from
    int done = 0, total = 0;
    double caseSeconds = 0.0;
    int ranHere = 0;
    SteadyClock::time_point start = SteadyClock::now();

    const PosteriorDraw& drawOf(long sample) const {
        return *std::find_if(draws.begin(), draws.end(), [&](const PosteriorDraw& d) { return d.sample == sample; });
    }

    /// The cell options of a case: a draw's parameters, else the configured cell's. A draw of
    /// theta_new is a cell of the population, whose spread reaches past the box of the single-cell
    /// prior (eta_m above 1 Pa s um, b2 above 4); the flow solver needs no surrogate, so the box
    /// does not bind it.
    std::string cellArgs(const ValidationCase& c) const {
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

    /// What the cell is, for the key: the arguments (a draw's parameters included), the posterior's
    /// bytes, or the Table 1 values the flow commands use by default.
    std::string cellKey(const ValidationCase& c) const {
        if (c.sample >= 0) return cellArgs(c);
        if (cfg.cellSource == "posterior")
            return cellArgs(c) + " " + tableFingerprint(fs::is_directory(cfg.posterior) ? cfg.posterior / "samples.csv" : cfg.posterior);
        if (cfg.cellSource == "explicit") return cellArgs(c);
        return fmt::format("table1 v={} mu={} kb={} b2={} etam={}", table1::v, table1::mu, table1::kbJ, table1::b2, table1::etam);
    }

    /// The flow arguments of a case (without threads and output, which do not change the result).
    std::string caseArgs(const ValidationCase& c) const {
        if (c.kind == "tube")
            return fmt::format("flow tube --radius {} --pressure-gradient {} --eta-out {} --level {} --duration {} "
                               "--settle {} {} --settle-tol {} --step-tol {} {}",
                               cfg.tubeRadius, c.pressureGradient, cfg.tubeEtaOut, cfg.tubeLevel > 0 ? cfg.tubeLevel : cfg.level,
                               cfg.tubeDuration, cfg.tubeSettle,
                               cfg.tubeSettleEtam > 0.0 ? fmt::format("--settle-etam {}", cfg.tubeSettleEtam)
                                                        : fmt::format("--settle-relax {}", cfg.tubeSettleRelax),
                               cfg.tubeSettleTol, cfg.tubeStepTol > 0.0 ? cfg.tubeStepTol : kTubeStepTolerance, cellArgs(c));
        // An ensemble member starts at random (seed = member), not from the configured tilt.
        const std::string start = c.member > 0         ? fmt::format(" --start random --seed {}", c.member)
                                  : cfg.tiltDeg > 0.0 ? fmt::format(" --tilt-deg {}", cfg.tiltDeg)
                                                      : std::string();
        return fmt::format("flow shear --eta-out {} --shear-rate {} --eta-in {} --level {} --rotations {} "
                           "--step-tol {}{}{} {}",
                           c.etaOut, c.rate, cfg.etaIn, cfg.level, cfg.rotations, cfg.stepTol, start,
                           cfg.stopWhenSteady ? " --stop-when-steady" : "", cellArgs(c));
    }

    std::string caseKey(const ValidationCase& c) const { return fingerprintOf({kVersion, caseArgs(c), cellKey(c)}); }

    /// A draw's record entry: its sample, the seed of the choice, the posterior and the parameters.
    json drawJson(long sample) const {
        const PosteriorDraw& d = drawOf(sample);
        return {{"sample", d.sample}, {"seed", seed}, {"posterior", cfg.posterior.string()},
                {"cell", {{"v", d.v}, {"mu_uN_per_m", d.mu}, {"kb_J", d.kbJ}, {"b2", d.b2}, {"etam_Pa_s_um", d.etam}}}};
    }

    fs::path caseFile(const ValidationCase& c) const { return out / "cases" / (c.id + ".json"); }

    /// The record in `file` if it is a finished case with c's key (a failed one only without --retry-failed).
    std::optional<json> matchingRecord(const fs::path& file, const ValidationCase& c) const {
        std::optional<json> j = tryReadJson(file);  // a damaged record is run again
        if (!j || stringOr(*j, "key") != caseKey(c) || !j->contains("result")) return std::nullopt;
        if (retryFailed && stringOr((*j)["result"], "status") != "ok") return std::nullopt;
        return j;
    }

    /// A finished case of an earlier run with the same key, if any: in OUT, else in an --import
    /// directory, whose record and case outputs are then copied into OUT (not in a dry run).
    bool loadFinished(const ValidationCase& c) {
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

    void runCase(const ValidationCase& c) {
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
        if (rc != 0 && stringOr(result, "status") == "ok") result["status"] = "failed";
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
            const json& o = result.value("observables", json::object());
            std::string what = result.value("status", "?");
            if (what == "ok" && c.kind != "tube")
                what = fmt::format("{} angle {} TTF {}", o.value("regime", "?"), num(o.value("inclination_deg", json())),
                                   num(o.value("ttf_4pi_f_over_shear_rate", json())));
            else if (what == "ok")
                what = fmt::format("v {} cm/s, length {} um", num(o.value("velocity_cm_per_s", json())), num(o.value("length_um", json())));
            else
                what = "FAILED: " + shortenedReason(result.value("reason", std::string("?")), 160);
            const double elapsed = secondsSince(start);
            const double eta = (total - done) * (caseSeconds / ranHere) / cfg.jobs;
            std::cerr << fmt::format("validate: [{}/{}] {} ({:.0f} s): {}; elapsed {:.0f} min, ETA {:.0f} min\n", done, total, c.id, wall, what,
                                     elapsed / 60.0, eta / 60.0);
        }
    }

    /// Runs the cases not finished yet, `jobs` at a time.
    void runAll(const std::vector<ValidationCase>& batch) {
        std::vector<ValidationCase> todo;
        for (const ValidationCase& c : batch) {
            cases.push_back(c);
            ++total;
            if (loadFinished(c))
                ++done;
            else
                todo.push_back(c);
        }
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

    const json& resultOf(const std::string& id) const { return results.at(id).at("result"); }

    /// The threshold cases at eta of the configured cell (sample -1) or of one draw.
    std::vector<RegimePoint> thresholdPoints(double eta, long sample = -1) const {
        std::vector<RegimePoint> p;
        for (const ValidationCase& c : cases)
            if (c.kind == "threshold" && c.etaOut == eta && c.sample == sample) {
                const json& r = resultOf(c.id);
                const json reg = r.value("observables", json::object()).value("regime", json());
                p.push_back({c.rate, r.value("status", "") == "ok" && reg.is_string() ? reg.get<std::string>() : ""});
            }
        return cfg.thresholdMembers > 0 ? ensembleRegimePoints(p) : p;
    }
};

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

std::string regimeOf(const json& observables) {
    return observables.value("regime", json()).is_string() ? observables.at("regime").get<std::string>() : "";
}

/// A row of tube.csv; a finished case's velocity and length against the data.
std::string tubeCase(const ValidationCase& c, const json& rec, const ValidationConfig& cfg, ValidationEvidence& evidence,
                     ComparisonTable& table) {
    const json& r = rec.at("result");
    const json o = r.value("observables", json::object()), d = r.value("diagnostics", json::object());
    const std::string status = r.value("status", "failed");
    const json plateau = d.value("plateau", json::object()), settling = d.value("settling", json::object()),
               motion = d.value("cell_frame_motion", json::object());
    const std::string settled = settling.empty() ? "none" : settling.value("settled", false) ? "true" : "false";
    const std::string row = fmt::format("{},{:g},{:g},{},{},{},{},{},{},{},{},{},{},{:.1f},{}\n", csvField(c.id), c.pressureGradient,
                                        cfg.tubeRadius, num(o.value("velocity_cm_per_s", json())), num(o.value("length_um", json())),
                                        num(o.value("width_um", json())), plateau.value("reached", false) ? "true" : "false",
                                        settled, num(settling.value("length_change_main_vs_settled", json())),
                                        num(motion.value("ratio", json())), csvField(status),
                                        num(d.value("area_drift_max", json())), num(d.value("volume_drift_max", json())),
                                        rec.value("wall_s", 0.0), cfg.tubeLevel > 0 ? cfg.tubeLevel : cfg.level);
    if (status != "ok" || !std::isfinite(numberOr(o, "velocity_cm_per_s"))) return row;
    const double v = numberOr(o, "velocity_cm_per_s"), l = numberOr(o, "length_um");
    table.record(c.id, "velocity [cm/s]", v, evidence.tubeVelocity(c.pressureGradient, v), fmt::format("{:.3g}", v));
    table.record(c.id, "length [um]", l, evidence.tubeLength(v, l), fmt::format("{:.3g} (at {:.3g} cm/s)", l, v));
    return row;
}

/// A row of shear.csv; a finished angle or TTF case against the data.
std::string shearCase(const ValidationCase& c, const json& rec, const ValidationConfig& cfg, ValidationEvidence& evidence,
                      ComparisonTable& table) {
    const json& r = rec.at("result");
    const json o = r.value("observables", json::object()), d = r.value("diagnostics", json::object());
    const std::string status = r.value("status", "failed"), regime = regimeOf(o);
    const std::string row = fmt::format("{},{},{:g},{:.6g},{:.6g},{},{},{},{},{},{},{},{:.1f},{}\n", csvField(c.id), csvField(c.kind),
                                        c.etaOut, c.rate, shearStressPa(c.etaOut, c.rate), csvField(regime), num(o.value("inclination_deg", json())),
                                        num(o.value("swing_amplitude_deg", json())), num(o.value("ttf_4pi_f_over_shear_rate", json())),
                                        csvField(status), num(d.value("area_drift_max", json())),
                                        num(d.value("volume_drift_max", json())), rec.value("wall_s", 0.0), cfg.level);
    if (status != "ok") return row;
    if (c.kind == "angle") {
        const double a = numberOr(o, "inclination_deg");
        if (const std::optional<ScatterComparison> s = evidence.inclination(c.etaOut, c.rate, a, regime))
            table.record(c.id, "inclination [deg]", a, *s, std::isfinite(a) ? fmt::format("{:.3g}", a) : regime);
    } else if (c.kind == "ttf") {
        const double f = numberOr(o, "ttf_4pi_f_over_shear_rate");
        table.record(c.id, "4 pi f / rate", f, evidence.tankTreadingFrequency(c.rate, f, regime),
                     std::isfinite(f) ? fmt::format("{:.3g}", f) : regime);
    }
    return row;
}

/// threshold.csv: the bracket per outer viscosity, compared with Fischer 2013 and Abkarian 2007.
std::string thresholdTable(const Runner& R, const ValidationEvidence& evidence, ComparisonTable& table) {
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

std::string validationMarkdown(std::size_t cases, int failed, const ComparisonTable& t, int thresholdMembers) {
    const std::string protocol =
        thresholdMembers > 0
            ? fmt::format(" Threshold protocol: {} members per rate from random starts (`flow shear --start random --seed k`, "
                          "k = 1..{}); a rate tank-treads when more than half of its members do.",
                          thresholdMembers, thresholdMembers)
            : std::string(" Threshold protocol: one run per rate from the configured start.");
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

/// The observables of a kind of case: (name in the tables, key of the flow JSON's observables).
std::vector<std::pair<std::string, std::string>> drawObservables(const std::string& kind) {
    if (kind == "angle") return {{"inclination [deg]", "inclination_deg"}};
    if (kind == "ttf") return {{"4 pi f / rate", "ttf_4pi_f_over_shear_rate"}};
    if (kind == "tube") return {{"velocity [cm/s]", "velocity_cm_per_s"}, {"length [um]", "length_um"}};
    return {};
}

/// What a draw's record gives for one observable; a failure's reason up to its first line break
/// or 100 characters, so that equal failures count together.
DrawOutcome drawOutcome(const json& rec, const std::string& key) {
    const json& r = rec.at("result");
    if (r.value("status", "failed") != "ok") {
        return {false, NAN, shortenedReason(stringOr(r, "reason"), 100)};
    }
    const json o = r.value("observables", json::object());
    const double x = numberOr(o, key.c_str());
    return {true, x, std::isfinite(x) ? "" : "no value (" + (regimeOf(o).empty() ? std::string("?") : regimeOf(o)) + ")"};
}

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
        if (std::isnan(meanValue) && kind != "threshold" && m != mean.rows.end()) meanValue = numberOr(*m, "predicted");
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
    json summary(const Runner& R) const {
        int runs = 0, failed = 0;
        for (const ValidationCase& c : R.cases)
            if (c.sample >= 0) ++runs, failed += R.resultOf(c.id).value("status", "failed") != "ok";
        json kinds = json::object();
        for (const auto& [kind, t] : tally)
            kinds[kind] = {{"compared", t[0]}, {"mean_cell_inside", t[1]}, {"band_overlap", t[2]}, {"band_verdict_within_mcse", t[3]}};
        return {{"runs", runs}, {"runs_failed", failed}, {"kinds", kinds}};
    }

    std::string markdown(const Runner& R) const {
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
                                             ValidationEvidence& evidence) {
    if (c.kind == "angle") return evidence.inclination(c.etaOut, c.rate, median, "");
    if (c.kind == "ttf") return evidence.tankTreadingFrequency(c.rate, median, "");
    if (observable == "velocity [cm/s]") return evidence.tubeVelocity(c.pressureGradient, median);
    return evidence.tubeLength(velocity, median);
}

/// draws.csv (one row per draw run) and bands.csv; returns the bands.
BandTable drawTables(const Runner& R, ValidationEvidence& evidence, const ComparisonTable& mean) {
    BandTable bands;
    std::string runs = csvProvenance() + "case_id,case,kind,sample,status,regime,inclination_deg,ttf_4pi_f_over_shear_rate,velocity_cm_per_s,length_um,wall_s\n";
    for (const ValidationCase& c : R.cases) {
        if (c.sample >= 0) {
            const json& rec = R.results.at(c.id);
            const json& r = rec.at("result");
            const json o = r.value("observables", json::object());
            runs += fmt::format("{},{},{},{},{},{},{},{},{},{},{:.1f}\n", csvField(c.id), csvField(c.id.substr(0, c.id.rfind("_sample"))),
                                csvField(c.kind), c.sample, csvField(r.value("status", "failed")), csvField(regimeOf(o)), num(o.value("inclination_deg", json())),
                                num(o.value("ttf_4pi_f_over_shear_rate", json())), num(o.value("velocity_cm_per_s", json())),
                                num(o.value("length_um", json())), rec.value("wall_s", 0.0));
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
        bands.record({fmt::format("threshold_eta{:g}", eta), "threshold", eta, 0.0, 0.0}, "critical stress [Pa]", b,
                     evidence.criticalStress(eta, tau, tau), mean, criticalStressOutcome(R.thresholdPoints(eta), eta).value);
    }
    writeFileAtomically(R.out / "draws.csv", runs);
    writeFileAtomically(R.out / "bands.csv", bands.csv);
    return bands;
}

/// Tables, comparison with the experimental scatter, summary; returns the summary JSON (and the
/// bands over the draws in `bandRows`).
json writeTables(const Runner& R, json& bandRows) {
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
    json summary = {{"cases", cases}, {"failed", failed}, {"inside", table.inside}, {"outside", table.outside},
                    {"no_data", table.noData}, {"other", table.other}, {"comparisons", table.rows.size()}};
    std::string md = validationMarkdown(cases, failed, table, R.cfg.thresholdMembers);
    if (!R.draws.empty()) {
        const BandTable bands = drawTables(R, evidence, table);
        md += bands.markdown(R);
        summary["draws"] = bands.summary(R);
        bandRows = bands.rows;
    }
    writeFileAtomically(R.out / "validation.md", md);
    return summary;
}

struct ValidateCommandOptions {
    std::string config, out, posterior, shard, surrogate;
    std::vector<std::string> only, imports;
    int jobs = 0, threads = 0, level = 0, draws = 0;
    std::uint64_t seed = 1;
    bool quiet = false, dryRun = false, retryFailed = false;
};

void addValidateOptions(CLI::App* cmd, ValidateCommandOptions& o) {
    cmd->add_option("--config", o.config, "validation configuration (TOML), e.g. configs/validation.toml")->required();
    addOutOption(cmd, o.out);
    cmd->add_option("--posterior", o.posterior,
                    "cell = the means of this theta_new posterior (DIR/phase3/theta_new of `trbc infer`), overriding [cell]; "
                    "--draws takes its samples");
    addNumber(cmd, "--draws", o.draws,
              "also run every case for N draws of the posterior's samples (--posterior or [cell] posterior), chosen with "
              "--seed; tabulates the median and 5-95 % band of each observable (bands.csv, draws.csv, validation.md); 0: "
              "the configured cell only",
              NumberRange::closed(0, 100000));
    addNumber(cmd, "--seed", o.seed, "seed of the choice of the --draws samples (recorded in validation.json and each draw's record)",
              NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--level", o.level,
              "icosphere level of the shear cases (overrides run.level; the tube keeps tube.level unless that is 0)",
              NumberRange::closed(1, 4));
    addNumber(cmd, "--jobs", o.jobs, "cases run at the same time (overrides run.jobs)", NumberRange::closed(1, 256));
    addThreadsOption(cmd, o.threads, "OpenMP threads per case (overrides run.threads)");
    cmd->add_option("--only", o.only, "run only these kinds of case (angle, ttf, threshold, tube; repeatable or comma-separated); "
                                      "the tables cover what has been run")
        ->delimiter(',')
        ->check(CLI::IsMember({"angle", "ttf", "threshold", "tube"}));
    cmd->add_option("--shard", o.shard,
                    "run only part K of N of the (selected) initial cases, e.g. 2/4 on the second of four machines, each with "
                    "its own OUT: dealt round-robin, one part per angle, TTF or tube case and per threshold viscosity (its "
                    "refinements stay with it); merge the parts with --import");
    cmd->add_option("--import", o.imports,
                    "another validate OUT directory (repeatable): a finished case recorded there with the same key (same "
                    "command, cell and version) is copied into OUT with its outputs instead of being run, e.g. the parts "
                    "of a --shard run")
        ->check(CLI::ExistingDirectory);
    cmd->add_flag("--retry-failed", o.retryFailed, "run again the cases recorded as failed (a transient failure; "
                                                  "by default a failed case is kept like a finished one)");
    cmd->add_flag("--dry-run", o.dryRun, "list the initial cases and their commands, marking those recorded in OUT with the same key "
                                      "([finished], or [failed] for a kept failure); run nothing");
    cmd->add_flag("--quiet", o.quiet, "no progress lines on stderr");
    cmd->add_option("--surrogate", o.surrogate,
                    "flow networks (a `trbc flow train` directory): predict every angle, TTF and threshold case of the config "
                    "for the --draws through them in seconds instead of running any case (surrogate_bands.csv, .md, .json)")
        ->check(CLI::ExistingDirectory);
}

/// `validate --surrogate`: the bands of the shear cases through the flow networks (analysis/flow_bands.hpp).
void runSurrogateBands(const Runner& R, const ValidateCommandOptions& o) {
    if (R.draws.empty())
        throw InputError("--surrogate: give --draws N (and --posterior DIR or [cell] posterior): the bands are over posterior draws");
    const auto t0 = SteadyClock::now();
    const FlowSurrogate model = FlowSurrogate::load(o.surrogate);
    ValidationEvidence evidence(R.cfg.dataDir);
    const std::vector<SurrogateBandRow> rows = surrogateShearBands(R.cfg, model, R.draws, evidence);
    const OutputDirectory outDir(R.out, "validate", "--out", {"surrogate_bands.json"}, {o.config});
    ensureWritableDirectory(R.out.string());
    const std::string md = fmt::format("# Shear validations through the flow networks\n\n{} draws of theta_new ({}, {} samples; seed {}), "
                                       "networks {}; command: `{}`\n\n",
                                       R.draws.size(), R.cfg.posterior.string(), R.posteriorSamples, R.seed, o.surrogate, commandLine()) +
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
    const json j = {{"provenance", {{"version", kVersion}, {"command", commandLine()}}},
                    {"surrogate", fs::absolute(o.surrogate).lexically_normal().string()},
                    {"posterior", R.cfg.posterior.string()},
                    {"draws", R.draws.size()},
                    {"seed", R.seed},
                    {"config", R.cfg.file.string()},
                    {"kinds", tally},
                    {"wall_s", secondsSince(t0)}};
    writeFileAtomically(R.out / "surrogate_bands.json", j.dump(2) + "\n");
    if (!R.quiet) std::cerr << fmt::format("validate --surrogate: {} rows in {:.2f} s\n", rows.size(), secondsSince(t0));
    std::cout << md;
}

/// The configuration with the command line's overrides, the output and import directories, the tools.
void configureRunner(Runner& R, const ValidateCommandOptions& o) {
    setProvenanceSeed(o.seed);
    R.cfg = readValidationConfig(o.config, defaultExperimentDirectory());
    if (!o.posterior.empty()) R.cfg.cellSource = "posterior", R.cfg.posterior = fs::absolute(o.posterior).lexically_normal();
    if (o.jobs > 0) R.cfg.jobs = o.jobs;
    if (o.level > 0) R.cfg.level = o.level;
    if (o.threads > 0) R.cfg.threads = o.threads;
    if (o.draws > 0 && R.cfg.cellSource != "posterior")
        throw InputError(fmt::format("--draws {}: draws are taken from a theta_new posterior; give --posterior DIR (or [cell] "
                                     "source = \"posterior\" in {})", o.draws, o.config));
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
    R.exe = fs::read_symlink("/proc/self/exe");
    R.scripts = scriptDirectory();
    R.python = pythonInterpreter();
}

/// The initial cases of --only and --shard.
std::vector<ValidationCase> selectedCases(std::vector<ValidationCase> initial, const ValidateCommandOptions& o) {
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
void listCases(Runner& R, const std::vector<ValidationCase>& initial) {
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

/// Rounds of bisection of every threshold bracket (of the configured cell and of each draw), while a bracket is open.
void refineThresholds(Runner& R) {
    std::vector<long> samples = {-1};
    for (const PosteriorDraw& d : R.draws) samples.push_back(d.sample);
    for (int round = 0; round < R.cfg.thresholdRefinements; ++round) {
        std::vector<ValidationCase> more;
        for (double eta : thresholdViscosities(R.cfg))
            for (const long sample : samples)
                if (const auto rate = refinementRate(R.thresholdPoints(eta, sample))) {
                    const std::string mean = uniqueShearCaseId("threshold", eta, *rate, R.cases);
                    for (int k = R.cfg.thresholdMembers > 0 ? 1 : 0; k <= R.cfg.thresholdMembers; ++k) {
                        const std::string member = k > 0 ? memberCaseId(mean, k) : mean;
                        const std::string id = sample < 0 ? member : drawCaseId(member, sample);
                        if (!R.results.count(id)) more.push_back({id, "threshold", eta, *rate, 0.0, sample, k});
                    }
                }
        if (more.empty()) break;
        if (!R.quiet) std::cerr << fmt::format("validate: threshold refinement {}: {} case(s)\n", round + 1, more.size());
        R.runAll(more);
    }
}

/// The cell of the cases: the source and its parameters (a posterior's means as the flow commands took them).
json cellJson(const Runner& R) {
    json cell = R.cfg.cellSource == "table1"
                    ? json{{"source", "the paper's Table 1 means"}, {"v", table1::v}, {"mu_uN_per_m", table1::mu}, {"kb_J", table1::kbJ},
                           {"b2", table1::b2}, {"etam_Pa_s_um", table1::etam}}
                : R.cfg.cellSource == "explicit"
                    ? json{{"source", "explicit"}, {"v", R.cfg.v}, {"mu_uN_per_m", R.cfg.mu}, {"kb_J", R.cfg.kbJ}, {"b2", R.cfg.b2},
                           {"etam_Pa_s_um", R.cfg.etam}}
                    : json{{"source", "means of " + R.cfg.posterior.string()}};
    if (R.cfg.cellSource == "posterior")
        for (const ValidationCase& c : R.cases)
            if (c.sample < 0 && R.resultOf(c.id).contains("parameters")) {
                cell["parameters"] = R.resultOf(c.id).at("parameters").value("cell", json());
                break;
            }
    return cell;
}

/// OUT/validation.json: summary, selection, cell, levels, configuration and timing.
json validationJson(const Runner& R, const ValidateCommandOptions& o, const json& summary, const json& bandRows, std::size_t configured,
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
            {"config", R.cfg.file.string()},
            {"config_text", readFileBytes(R.cfg.file)},
            {"data_dir", R.cfg.dataDir.string()},
            {"wall_s_this_run", wall},
            {"case_wall_s_total", caseWall},
            {"cases_run_this_time", R.ranHere},
            {"jobs", R.cfg.jobs},
            {"threads_per_case", R.cfg.threads},
            {"provenance", {{"version", kVersion}, {"command", commandLine()}}}};
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

void drawValidationFigures(const Runner& R) {
    const std::string plot = shellQuote(R.python) + " " + shellQuote(R.scripts / "plot_validation.py") + " " + shellQuote(R.out) + " --data " +
                             shellQuote(R.cfg.dataDir) + " > " + shellQuote(R.out / "plot.log") + " 2>&1";
    if (std::system(plot.c_str()) != 0)
        std::cerr << fmt::format("validate: warning: the figures failed (see {})\n", (R.out / "plot.log").string());
}

void printValidationSummary(const Runner& R, const json& summary, std::size_t selected, std::size_t configured, double wall) {
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

void runValidate(const ValidateCommandOptions& o) {
    Runner R{};
    configureRunner(R, o);
    const std::vector<ValidationCase> all = initialValidationCases(R.cfg);
    const std::vector<ValidationCase> selected = selectedCases(all, o);
    const std::vector<ValidationCase> initial = casesWithDraws(selected, R.draws);
    if (o.dryRun) return listCases(R, initial);
    if (!o.surrogate.empty()) return runSurrogateBands(R, o);
    const OutputDirectory outDir(R.out, "validate", "--out", {"validation.json", "cases"}, {o.config});
    ensureWritableDirectory(R.out.string());
    fs::create_directories(R.out / "cases");
    forwardSignalsToChildren();
    const auto t0 = SteadyClock::now();
    R.runAll(initial);
    if (o.only.empty() || std::find(o.only.begin(), o.only.end(), "threshold") != o.only.end()) refineThresholds(R);
    json bandRows;
    const json summary = writeTables(R, bandRows);
    const double wall = secondsSince(t0);
    writeFileAtomically(R.out / "validation.json", validationJson(R, o, summary, bandRows, all.size(), wall).dump(2) + "\n");
    drawValidationFigures(R);
    printValidationSummary(R, summary, selected.size(), all.size(), wall);
    if (summary["failed"].get<int>() > 0)
        throw NumericalError(fmt::format("validate: {} case(s) failed (see validation.md and cases/)", summary["failed"].get<int>()));
}

}  // namespace

void registerValidate(CLI::App& app) {
    auto o = std::make_shared<ValidateCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "validate", "Run the flow-validation set of docs/VALIDATE.md (inclination angle, tank-treading frequency, "
                    "tumbling/tank-treading threshold in shear flow; velocity and length in a microtube) with `trbc flow`, "
                    "compare every case with the experimental scatter and draw the paper's figures. Resumable: run the same "
                    "command again after an interruption and only unfinished cases run. With --draws N, every case also "
                    "runs for N draws of the posterior and each observable gets its median and 5-95 % band. Writes OUT/shear.csv, "
                    "threshold.csv, tube.csv, comparison.csv, validation.md, validation.json, figures/ and cases/");
    addValidateOptions(cmd, *o);
    cmd->callback([o]() { runValidate(*o); });
}

}  // namespace trbc::cli
