// trbc calibrate: the whole pipeline of the paper from one TOML file. Each stage is the
// very trbc command a user could type (so its own outputs carry their provenance), run as a child
// process with its log in OUT/logs/; the stage ledger (analysis/stage_ledger.hpp) skips stages
// whose inputs have not changed. Stages and what they depend on:
//   data                 the configured CSVs, copied to OUT/data with a datasets.json manifest
//   campaign             (mode run) campaign settings and seed           -> OUT/campaign
//   surrogate            (mode train) the campaign                       -> OUT/surrogate
//   sobol                the surrogate, Sobol' settings                  -> OUT/sobol
//   inference.phase1.X   the surrogate, data set X, inference settings   -> OUT/inference/phase1/X
//   inference.phase23    every phase-1 stage                             -> OUT/inference/phase{2,3}, OUT/figures
//   predict              phase 2-3, the data, prediction settings        -> OUT/predict
//   cell                 phase 2-3, quantile and level                   -> OUT/cell
//   report               all of the above                                -> OUT/report.{md,html}
// Changing one data CSV therefore re-runs that data set's phase 1, phases 2-3, predict, cell and
// the report, and nothing else.
#include <fmt/format.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

#include "analysis/calibrate_config.hpp"
#include "analysis/report.hpp"
#include "analysis/stage_ledger.hpp"
#include "cli/child_process.hpp"
#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "inference/rbc_problem.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string lastLines(const fs::path& file, int n) {
    std::ifstream in(file);
    std::vector<std::string> lines;
    std::string line;
    while (std::getline(in, line)) lines.push_back(line);
    std::string s;
    for (std::size_t k = lines.size() > static_cast<std::size_t>(n) ? lines.size() - n : 0; k < lines.size(); ++k) s += "  " + lines[k] + "\n";
    return s;
}

struct Pipeline {
    CalibrateConfig cfg;
    fs::path out, exe, scripts, python;
    int threads = 2;
    bool quiet = false;
    StageLedger ledger;

    Pipeline(CalibrateConfig c, fs::path o) : cfg(std::move(c)), out(std::move(o)), ledger(out) {}

    void say(const std::string& s) const {
        if (!quiet) std::cerr << s << std::endl;
    }

    /// Runs one command line, appending its output to OUT/logs/<stage>.log. A failing command of a
    /// required step is a NumericalError quoting the log's last lines; an optional one (figures)
    /// only warns.
    bool shell(const std::string& stage, const std::string& command, bool required = true) const {
        const fs::path log = out / "logs" / (stage + ".log");
        {
            std::ofstream l(log, std::ios::app);
            l << "$ " << command << '\n';
        }
        const int rc = childExitCode(runChildProcess(command + " >> " + shellQuote(log) + " 2>&1"));
        if (rc == 0) return true;
        if (required)
            throw NumericalError(fmt::format("calibrate: stage '{}' failed (exit {}) running\n  {}\nlast lines of {}:\n{}", stage, rc,
                                             command, log.string(), lastLines(log, 15)));
        std::cerr << fmt::format("calibrate: warning: stage '{}': optional step failed (exit {}): {} (see {})\n", stage, rc, command,
                                 log.string());
        return false;
    }

    /// Runs a stage unless up to date: removes `clean`, runs the commands, records the fingerprint.
    bool stage(const std::string& name, const std::string& fingerprint, const std::vector<fs::path>& outputs,
               const std::vector<std::string>& commands, const std::vector<std::string>& optionalCommands = {},
               const std::vector<fs::path>& clean = {}) {
        if (ledger.upToDate(name, fingerprint, outputs)) {
            ledger.skipped(name);
            say(fmt::format("calibrate: {:<28} up to date (skipped)", name));
            return false;
        }
        say(fmt::format("calibrate: {:<28} running ...", name));
        ledger.invalidate(name);
        for (const fs::path& p : clean) fs::remove_all(p);
        fs::remove(out / "logs" / (name + ".log"));
        const auto t0 = Clock::now();
        for (const std::string& c : commands) shell(name, c);
        for (const std::string& c : optionalCommands) shell(name, c, false);
        const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
        std::vector<std::string> all = commands;
        all.insert(all.end(), optionalCommands.begin(), optionalCommands.end());
        ledger.finished(name, fingerprint, {{"commands", all}}, wall);
        say(fmt::format("calibrate: {:<28} done in {:.1f} s", name, wall));
        return true;
    }

    std::string trbc(const std::string& args) const { return shellQuote(exe) + " " + args; }
    std::string script(const std::string& name, const std::string& args) const {
        return shellQuote(python) + " " + shellQuote(scripts / name) + " " + args;
    }
};

/// Copies the configured data sets to OUT/data/<experiment>/<name>.csv and writes the manifest
/// that `trbc infer --data-dir` and `trbc predict --data-dir` read. Returns the per-set fingerprints.
std::map<std::string, std::string> stageData(Pipeline& P) {
    std::map<std::string, std::string> fp;
    std::vector<std::string> all = {"data", kVersion};
    for (const CalibrateDataSet& d : P.cfg.data) {
        fp[d.name] = fingerprintOf({d.name, d.experiment, fileFingerprint(d.file)});
        all.push_back(fp[d.name]);
    }
    const std::string fingerprint = fingerprintOf(all);
    const fs::path dir = P.out / "data";
    if (P.ledger.upToDate("data", fingerprint, {dir / kRbcDataManifest})) {
        P.ledger.skipped("data");
        P.say(fmt::format("calibrate: {:<28} up to date (skipped)", "data"));
        return fp;
    }
    const auto t0 = Clock::now();
    fs::remove_all(dir);
    nlohmann::json manifest = nlohmann::json::array();
    for (const CalibrateDataSet& d : P.cfg.data) {
        const fs::path rel = fs::path(d.experiment) / (d.name + ".csv");
        fs::create_directories(dir / d.experiment);
        fs::copy_file(d.file, dir / rel, fs::copy_options::overwrite_existing);
        manifest.push_back({{"name", d.name}, {"experiment", d.experiment}, {"file", rel.string()}, {"source", d.file.string()}});
    }
    writeFileAtomically(dir / kRbcDataManifest, manifest.dump(2) + "\n");
    P.ledger.finished("data", fingerprint, {{"files", manifest}}, std::chrono::duration<double>(Clock::now() - t0).count());
    P.say(fmt::format("calibrate: {:<28} staged {} data sets", "data", P.cfg.data.size()));
    return fp;
}

std::string modelFingerprint(const fs::path& dir) {
    std::vector<std::string> parts = {"model"};
    for (const std::string& name : surrogateNetworkNames()) {
        const std::string f = name + ".json";
        if (!fs::exists(dir / f))
            throw InputError(fmt::format("surrogate directory {} lacks {} (make one with `trbc surrogate train`)", dir.string(), f));
        parts.push_back(fileFingerprint(dir / f));
    }
    return fingerprintOf(parts);
}

}  // namespace

void registerCalibrate(CLI::App& app) {
    struct Opts {
        std::string config, out;
        int threads = 0;
        bool quiet = false;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = app.add_subcommand(
        "calibrate", "The whole calibration from one TOML file: data, optional training campaign and surrogate training (or the "
                     "shipped ones), Sobol' analysis, three-phase inference, posterior predictions, the calibrated cell and "
                     "OUT/report.html + OUT/report.md. Stages whose inputs did not change are skipped (OUT/stages.json). "
                     "See configs/paper.toml for every key.");
    cmd->add_option("--config", o->config, "TOML configuration (configs/paper.toml: the paper's setup)")->required();
    cmd->add_option("--out", o->out, "output directory (re-use it to skip finished stages)")->required();
    addNumber(cmd, "--threads", o->threads, "OpenMP threads of every stage (overrides [run] threads; results do not depend on it)",
              NumberRange::closed(0, 1024));
    cmd->add_flag("--quiet", o->quiet, "no progress lines on stderr");
    cmd->callback([o]() {
        const auto t0 = Clock::now();
        CalibrateConfig cfg = readCalibrateConfig(o->config, defaultExperimentDirectory());
        // OUT is new, empty, an earlier calibrate output (it has the stage ledger) or holds nothing but
        // the --config file itself: anything else would have its report.md and config.toml overwritten.
        if (fs::is_directory(o->out) && !fs::exists(fs::path(o->out) / "stages.json")) {
            for (const auto& e : fs::directory_iterator(o->out)) {
                std::error_code ec;
                if (!fs::equivalent(e.path(), cfg.file, ec))
                    throw InputError(fmt::format("--out {}: the directory holds files ({}, ...) but is not the output of `trbc "
                                                 "calibrate` (no stages.json); choose a new or empty directory",
                                                 o->out, e.path().filename().string()));
            }
        }
        ensureWritableDirectory(o->out);
        const fs::path out = fs::absolute(o->out).lexically_normal();
        fs::create_directories(out / "logs");
        const DirectoryLock lock(out, ".calibrate.lock", "calibrate");
        forwardSignalsToChildren();
        Pipeline P(cfg, out);
        P.exe = fs::read_symlink("/proc/self/exe");
        P.scripts = scriptDirectory();
        P.python = pythonInterpreter();
        P.threads = o->threads > 0 ? o->threads : cfg.threads;
        P.quiet = o->quiet;
        {
            std::error_code ec;
            if (!fs::equivalent(cfg.file, out / "config.toml", ec))  // --config OUT/config.toml is already in place
                fs::copy_file(cfg.file, out / "config.toml", fs::copy_options::overwrite_existing);
        }
        const std::string seed = std::to_string(cfg.seed), threads = std::to_string(P.threads);

        const std::map<std::string, std::string> dataFp = stageData(P);

        // Training data and surrogates.
        std::string campaignFp = "shipped";
        if (cfg.campaignMode == "run") {
            campaignFp = fingerprintOf({"campaign", kVersion, std::to_string(cfg.campaignSamples), std::to_string(cfg.campaignForcesPerCell),
                                        cfg.campaignDesign, std::to_string(cfg.campaignLevel), seed});
            P.stage("campaign", campaignFp, {out / "campaign" / "samples.csv"},
                    {P.trbc(fmt::format("campaign --samples {} --forces-per-cell {} --design {} --seed {} --level {} --threads {} "
                                        "--out {} --resume",
                                        cfg.campaignSamples, cfg.campaignForcesPerCell, cfg.campaignDesign, seed, cfg.campaignLevel,
                                        threads, shellQuote(out / "campaign")))});
        }
        fs::path modelDir = cfg.surrogateMode == "path" ? cfg.surrogateDir : defaultSurrogateDirectory();
        if (cfg.surrogateMode == "train") {
            modelDir = out / "surrogate";
            P.stage("surrogate", fingerprintOf({"surrogate", kVersion, campaignFp, seed}), {modelDir / "relaxation.json"},
                    {P.trbc(fmt::format("surrogate train --data {} --out {} --seed {} --threads {}", shellQuote(out / "campaign"),
                                        shellQuote(modelDir), seed, threads))});
        }
        const std::string modelFp = modelFingerprint(modelDir);

        if (cfg.sobolEnabled)
            P.stage("sobol",
                    fingerprintOf({"sobol", kVersion, modelFp, std::to_string(cfg.sobolSamples), std::to_string(cfg.sobolForces),
                                   std::to_string(cfg.sobolResamples), seed}),
                    {out / "sobol" / "sobol_indices.csv"},
                    {P.trbc(fmt::format("sobol --model {} --samples {} --forces {} --resamples {} --seed {} --threads {} --no-plot --out {}",
                                        shellQuote(modelDir), cfg.sobolSamples, cfg.sobolForces, cfg.sobolResamples, seed, threads,
                                        shellQuote(out / "sobol")))},
                    {P.script("plot_sobol.py", shellQuote(out / "sobol"))}, {out / "sobol"});

        // Inference: one stage per phase-1 data set, one for phases 2-3 (which need all of them).
        const fs::path inf = out / "inference";
        std::string priorArgs;
        for (const auto& [name, b] : cfg.inferencePrior) priorArgs += fmt::format(" --prior {}={:.17g}:{:.17g}", name, b.first, b.second);
        const std::string infSettings =
            fingerprintOf({"inference", kVersion, modelFp, std::to_string(cfg.inferenceSamples), cfg.fvkDensity, seed, priorArgs});
        std::vector<std::string> phase1Fps = {infSettings};
        std::vector<std::string> changed;
        for (const CalibrateDataSet& d : cfg.data) {
            const std::string name = "inference.phase1." + d.name;
            const std::string fp = fingerprintOf({infSettings, dataFp.at(d.name)});
            phase1Fps.push_back(fp);
            if (!P.ledger.upToDate(name, fp, {inf / "phase1" / d.name / "samples.csv"})) changed.push_back(d.name);
        }
        if (fs::is_directory(inf / "phase1"))  // posteriors of data sets no longer configured
            for (const auto& e : fs::directory_iterator(inf / "phase1"))
                if (e.is_directory() && std::none_of(cfg.data.begin(), cfg.data.end(), [&](const CalibrateDataSet& d) {
                        return d.name == e.path().filename().string();
                    }))
                    fs::remove_all(e.path());
        const std::string phase23Fp = fingerprintOf(phase1Fps);
        const std::string inferCmd = P.trbc(fmt::format("infer --out {} --data-dir {} --model {} --samples {} --seed {} --fvk-density {} "
                                                        "--threads {} --resume{}",
                                                        shellQuote(inf), shellQuote(out / "data"), shellQuote(modelDir), cfg.inferenceSamples, seed,
                                                        cfg.fvkDensity, threads, priorArgs));
        const bool phase23Current = P.ledger.upToDate("inference.phase23", phase23Fp, {inf / "posterior_stats.csv"});
        if (changed.empty() && phase23Current) {
            for (const CalibrateDataSet& d : cfg.data) P.ledger.skipped("inference.phase1." + d.name);
            P.ledger.skipped("inference.phase23");
            P.say(fmt::format("calibrate: {:<28} up to date (skipped)", "inference"));
        } else {
            for (const std::string& name : changed) {
                P.ledger.invalidate("inference.phase1." + name);
                fs::remove_all(inf / "phase1" / name);
            }
            for (const CalibrateDataSet& d : cfg.data)
                if (std::find(changed.begin(), changed.end(), d.name) == changed.end()) P.ledger.skipped("inference.phase1." + d.name);
            P.ledger.invalidate("inference.phase23");
            fs::remove_all(inf / "phase2");
            fs::remove_all(inf / "phase3");
            fs::remove_all(out / "figures");
            P.say(fmt::format("calibrate: {:<28} running phase 1 for {} data set(s), then phases 2-3 ...", "inference", changed.size()));
            fs::remove(out / "logs" / "inference.log");
            const auto ti = Clock::now();
            P.shell("inference", inferCmd);
            P.shell("inference", P.script("plot_posterior.py", shellQuote(inf) + " --out " + shellQuote(out / "figures")), false);
            const double wall = std::chrono::duration<double>(Clock::now() - ti).count();
            for (std::size_t k = 0; k < cfg.data.size(); ++k) {
                const CalibrateDataSet& d = cfg.data[k];
                if (std::find(changed.begin(), changed.end(), d.name) == changed.end()) continue;
                double w = 0.0;
                try {
                    std::ifstream f(inf / "phase1" / d.name / "run.json");
                    w = nlohmann::json::parse(f).value("wall_s", 0.0);
                } catch (const std::exception&) {
                }
                P.ledger.finished("inference.phase1." + d.name, phase1Fps[k + 1], {{"commands", {inferCmd}}}, w);
            }
            P.ledger.finished("inference.phase23", phase23Fp, {{"commands", {inferCmd}}}, wall);
            P.say(fmt::format("calibrate: {:<28} done in {:.1f} s", "inference", wall));
        }

        const std::string allDataFp = [&] {
            std::vector<std::string> v = {"data"};
            for (const auto& [k, f] : dataFp) v.push_back(k + f);
            return fingerprintOf(v);
        }();
        const std::string predictFp = fingerprintOf({"predict", kVersion, phase23Fp, allDataFp, modelFp,
                                                     std::to_string(cfg.predictionMaxSamples), std::to_string(cfg.predictionGrid), seed});
        P.stage("predict", predictFp, {out / "predict" / "coverage.csv"},
                {P.trbc(fmt::format("predict --inference {} --out {} --data-dir {} --model {} --max-samples {} --grid {} --seed {} "
                                    "--threads {} --quiet",
                                    shellQuote(inf), shellQuote(out / "predict"), shellQuote(out / "data"), shellQuote(modelDir), cfg.predictionMaxSamples,
                                    cfg.predictionGrid, seed, threads))},
                {P.script("plot_predict.py", shellQuote(out / "predict") + " --data-dir " + shellQuote(out / "data"))}, {out / "predict"});

        std::string cellFp = "disabled";
        if (cfg.cellEnabled) {
            cellFp = fingerprintOf({"cell", kVersion, phase23Fp, fmt::format("{:.17g}", cfg.cellQuantile), std::to_string(cfg.cellLevel)});
            P.stage("cell", cellFp, {out / "cell" / "cell.json"},
                    {P.trbc(fmt::format("export --posterior {} --quantile {:.17g} --level {} --threads {} --out {} > /dev/null",
                                        shellQuote(inf / "phase3" / "theta_new"), cfg.cellQuantile, cfg.cellLevel, threads, shellQuote(out / "cell")))},
                    {}, {out / "cell"});
        }

        // Transferability: the flow validations with the theta_new means; optional (hours).
        std::string validationFp = "disabled";
        if (cfg.validationEnabled) {
            const fs::path vcfg = cfg.validationConfig.empty() ? resourceRoot() / "configs" / "validation.toml" : cfg.validationConfig;
            std::string only;
            for (const std::string& k : cfg.validationOnly) only += (only.empty() ? " --only " : ",") + k;
            validationFp = fingerprintOf({"validation", kVersion, phase23Fp, fileFingerprint(vcfg), only});
            // Not skipped on a changed fingerprint alone: trbc validate keeps every finished case whose
            // command and cell are unchanged, so a re-run costs only the new cases.
            P.stage("validation", validationFp, {out / "validation" / "validation.json"},
                    {}, {P.trbc(fmt::format("validate --config {} --posterior {} --out {} --threads {}{} --quiet", shellQuote(vcfg),
                                            shellQuote(inf / "phase3" / "theta_new"), shellQuote(out / "validation"), 1, only))});
        }

        // The report: cheap, but recorded like a stage so that an unchanged run leaves it alone.
        CalibrationReportInputs ri;
        ri.outputDirectory = out;
        ri.configFile = cfg.file;
        ri.surrogateDirectory = modelDir;
        ri.meshConvergenceDirectory = resourceRoot() / "results" / "mesh_convergence";
        ri.version = kVersion;
        for (const CalibrateDataSet& d : cfg.data) ri.dataSets.push_back(fmt::format("{} ({}): {}", d.name, d.experiment, d.file.string()));
        const std::string reportFp = fingerprintOf({"report", kVersion, fileFingerprint(cfg.file), allDataFp, modelFp, phase23Fp, predictFp,
                                                    cellFp, P.ledger.fingerprint("sobol"), validationFp});
        if (P.ledger.upToDate("report", reportFp, {out / "report.html", out / "report.md"})) {
            P.ledger.skipped("report");
            P.say(fmt::format("calibrate: {:<28} up to date (skipped)", "report"));
        } else {
            P.ledger.invalidate("report");
            const auto tr = Clock::now();
            writeCalibrationReport(ri);
            P.ledger.finished("report", reportFp, {{"commands", nlohmann::json::array()}},
                              std::chrono::duration<double>(Clock::now() - tr).count());
        }

        const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
        nlohmann::json j = {{"command", commandLine()},
                            {"version", kVersion},
                            {"config", cfg.file.string()},
                            {"seed", cfg.seed},
                            {"threads", P.threads},
                            {"surrogate", modelDir.string()},
                            {"ran", P.ledger.ran()},
                            {"skipped", P.ledger.skippedStages()},
                            {"wall_s", wall},
                            {"report", {(out / "report.html").string(), (out / "report.md").string()}}};
        writeFileAtomically(out / "calibrate.json", j.dump(2) + "\n");
        std::cout << fmt::format("trbc calibrate: {} stage(s) ran, {} up to date, {:.1f} s\nreport: {}\n        {}\n", P.ledger.ran().size(),
                                 P.ledger.skippedStages().size(), wall, (out / "report.html").string(), (out / "report.md").string());
    });
}

}  // namespace trbc::cli
