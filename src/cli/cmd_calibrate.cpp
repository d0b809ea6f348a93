// trbc calibrate: the whole pipeline of the paper from one TOML file. The stages, their inputs
// and their commands are the table of analysis/calibrate_stages.hpp; this command runs it: each
// command as a child process with its log in OUT/logs/, each stage skipped while the stage ledger
// (analysis/stage_ledger.hpp) says it is up to date.
#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <optional>

#include "analysis/calibrate_config.hpp"
#include "analysis/calibrate_stages.hpp"
#include "analysis/report.hpp"
#include "analysis/stage_ledger.hpp"
#include "core/child_process.hpp"
#include "cli/common.hpp"
#include "core/output_dir.hpp"
#include "core/clock.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"

namespace trbc::cli {
namespace {

namespace fs = std::filesystem;

std::string lastLines(const fs::path& file, int n) {
    std::ifstream in(file);
    std::vector<std::string> lines;
    std::string line;
    while (std::getline(in, line)) lines.push_back(line);
    std::string s;
    for (std::size_t k = lines.size() > static_cast<std::size_t>(n) ? lines.size() - n : 0; k < lines.size(); ++k) s += "  " + lines[k] + "\n";
    return s;
}

/// The wall time a part's own record states (0 when it has none).
double recordedWallSeconds(const fs::path& record) {
    const std::optional<nlohmann::json> j = tryReadJson(record);
    if (!j || !j->contains("wall_s") || !(*j)["wall_s"].is_number()) return 0.0;
    return (*j)["wall_s"].get<double>();
}

/// Runs the steps of the table in order, keeping the fingerprint of every entry for those that follow.
class StageRunner {
public:
    StageRunner(CalibrateConfig cfg, fs::path out, CalibrateTools tools, bool quiet)
        : cfg_(std::move(cfg)), out_(std::move(out)), tools_(std::move(tools)), quiet_(quiet), ledger_(out_) {}

    void run(const CalibrateStep& step) {
        switch (step.action) {
            case CalibrateAction::Fingerprint:
                fingerprints_[step.stage.name] = fingerprint(step.stage);
                break;
            case CalibrateAction::StageData:
                runData(step);
                break;
            case CalibrateAction::Commands:
                runCommands(step);
                break;
            case CalibrateAction::Report:
                runReport(step);
                break;
        }
    }

    const StageLedger& ledger() const { return ledger_; }

private:
    void say(const std::string& s) const {
        if (!quiet_) std::cerr << s << std::endl;
    }
    void sayStep(const std::string& step, const std::string& what) const { say(fmt::format("calibrate: {:<28} {}", step, what)); }

    std::string fingerprint(const CalibrateStage& s) const { return stageFingerprint(s, fingerprints_, ledger_); }

    /// Fingerprints the stage; true when the ledger has it done with that fingerprint.
    bool current(const CalibrateStage& s) {
        fingerprints_[s.name] = fingerprint(s);
        return ledger_.upToDate(s.name, fingerprints_[s.name], s.outputs);
    }

    /// Forgets the stage and removes what it leaves behind.
    void reset(const CalibrateStage& s) {
        ledger_.invalidate(s.name);
        for (const fs::path& p : s.clean) fs::remove_all(p);
    }

    void finished(const CalibrateStage& s, const nlohmann::json& details, double wall) {
        ledger_.finished(s.name, fingerprints_.at(s.name), details, wall);
    }

    /// Runs one command line, appending its output to OUT/logs/<step>.log. A failing command of a
    /// required step is a NumericalError quoting the log's last lines; an optional one (figures)
    /// only warns.
    void shell(const std::string& step, const std::string& command, bool required) const {
        const fs::path log = out_ / "logs" / (step + ".log");
        {
            std::ofstream l(log, std::ios::app);
            l << "$ " << command << '\n';
        }
        const int rc = childExitCode(runChildProcess(command + " >> " + shellQuote(log) + " 2>&1"));
        if (rc == 0) return;
        if (required)
            throw NumericalError(fmt::format("calibrate: stage '{}' failed (exit {}) running\n  {}\nlast lines of {}:\n{}", step, rc,
                                             command, log.string(), lastLines(log, 15)));
        std::cerr << fmt::format("calibrate: warning: stage '{}': optional step failed (exit {}): {} (see {})\n", step, rc, command,
                                 log.string());
    }

    void runData(const CalibrateStep& step) {
        if (current(step.stage)) return skip(step);
        const auto t0 = SteadyClock::now();
        const nlohmann::json manifest = stageCalibrateData(cfg_, out_ / "data");
        finished(step.stage, {{"files", manifest}}, secondsSince(t0));
        sayStep(step.name, fmt::format("staged {} data sets", cfg_.data.size()));
    }

    void runReport(const CalibrateStep& step) {
        if (current(step.stage)) return skip(step);
        ledger_.invalidate(step.stage.name);
        const auto t0 = SteadyClock::now();
        writeCalibrationReport(calibrationReportInputs(cfg_, out_, tools_));
        finished(step.stage, {{"commands", nlohmann::json::array()}}, secondsSince(t0));
    }

    void skip(const CalibrateStep& step) {
        for (const CalibrateStage& p : step.parts) ledger_.skipped(p.name);
        ledger_.skipped(step.stage.name);
        sayStep(step.name, "up to date (skipped)");
    }

    /// Subdirectories of step.prune that no part cleans: results of data no longer configured.
    void prune(const CalibrateStep& step) const {
        if (step.prune.empty() || !fs::is_directory(step.prune)) return;
        for (const auto& e : fs::directory_iterator(step.prune))
            if (e.is_directory() && std::none_of(step.parts.begin(), step.parts.end(), [&](const CalibrateStage& p) {
                    return std::find(p.clean.begin(), p.clean.end(), e.path()) != p.clean.end();
                }))
                fs::remove_all(e.path());
    }

    /// A command step: skipped when its stage and every part are up to date; otherwise the parts
    /// that are out of date and the step's own stage are reset, the commands run and recorded.
    void runCommands(const CalibrateStep& step) {
        std::vector<const CalibrateStage*> stale;
        for (const CalibrateStage& p : step.parts)
            if (!current(p)) stale.push_back(&p);
        prune(step);
        if (current(step.stage) && stale.empty()) return skip(step);
        for (const CalibrateStage& p : step.parts)
            if (std::find(stale.begin(), stale.end(), &p) == stale.end()) ledger_.skipped(p.name);
        for (const CalibrateStage* p : stale) reset(*p);
        reset(step.stage);
        sayStep(step.name, step.parts.empty() ? std::string("running ...")
                                              : "running " + fmt::format(fmt::runtime(step.partsNote), stale.size()) + " ...");
        fs::remove(out_ / "logs" / (step.name + ".log"));
        const auto t0 = SteadyClock::now();
        for (const std::string& c : step.commands) shell(step.name, c, true);
        for (const std::string& c : step.optionalCommands) shell(step.name, c, false);
        const double wall = secondsSince(t0);
        const nlohmann::json details = {{"commands", step.recorded}};
        for (const CalibrateStage* p : stale) finished(*p, details, recordedWallSeconds(p->wallRecord));
        finished(step.stage, details, wall);
        sayStep(step.name, fmt::format("done in {:.1f} s", wall));
    }

    CalibrateConfig cfg_;
    fs::path out_;
    CalibrateTools tools_;
    bool quiet_;
    StageLedger ledger_;
    std::map<std::string, std::string> fingerprints_;
};

struct CalibrateOptions {
    std::string config, out;
    int threads = 0;
    bool quiet = false;
};

/// OUT/config.toml: the configuration, with its bases merged into it so that the copy stands alone.
void copyConfiguration(const CalibrateConfig& cfg, const fs::path& copy) {
    std::error_code ec;
    if (fs::equivalent(cfg.file, copy, ec)) return;  // --config OUT/config.toml is already in place
    if (cfg.bases.empty())
        fs::copy_file(cfg.file, copy, fs::copy_options::overwrite_existing);
    else
        writeFileAtomically(copy, mergedCalibrateConfig(cfg.file));
}

CalibrateTools calibrateTools() {
    CalibrateTools t;
    t.trbc = fs::read_symlink("/proc/self/exe");
    t.python = pythonInterpreter();
    t.scripts = scriptDirectory();
    t.shippedSurrogates = defaultSurrogateDirectory();
    t.validationConfig = resourceRoot() / "configs" / "validation.toml";
    t.meshConvergence = resourceRoot() / "results" / "mesh_convergence";
    return t;
}

void writeSummary(const CalibrateConfig& cfg, const fs::path& out, int threads, const fs::path& modelDir, const StageLedger& ledger,
                  double wall) {
    const nlohmann::json j = withBuild({{"command", commandLine()},
                                        {"config", cfg.file.string()},
                                        {"seed", cfg.seed},
                                        {"threads", threads},
                                        {"surrogate", modelDir.string()},
                                        {"ran", ledger.ran()},
                                        {"skipped", ledger.skippedStages()},
                                        {"wall_s", wall},
                                        {"report", {(out / "report.html").string(), (out / "report.md").string()}}});
    writeFileAtomically(out / "calibrate.json", j.dump(2) + "\n");
    std::cout << fmt::format("trbc calibrate: {} stage(s) ran, {} up to date, {:.1f} s\nreport: {}\n        {}\n", ledger.ran().size(),
                             ledger.skippedStages().size(), wall, (out / "report.html").string(), (out / "report.md").string());
}

void runCalibrate(const CalibrateOptions& o) {
    const auto t0 = SteadyClock::now();
    const CalibrateConfig cfg = readCalibrateConfig(o.config, defaultExperimentDirectory());
    const OutputDirectory outDir(o.out, "calibrate", "--out", {"stages.json"}, {cfg.file});
    ensureWritableDirectory(o.out);
    const fs::path out = outDir.path();
    fs::create_directories(out / "logs");
    forwardSignalsToChildren();
    const CalibrateTools tools = calibrateTools();
    const int threads = o.threads > 0 ? o.threads : cfg.threads;
    copyConfiguration(cfg, out / "config.toml");
    StageRunner runner(cfg, out, tools, o.quiet);
    for (const CalibrateStep& step : calibrateSteps(cfg, out, threads, tools)) runner.run(step);
    writeSummary(cfg, out, threads, calibrateModelDirectory(cfg, out, tools), runner.ledger(), secondsSince(t0));
}

}  // namespace

void registerCalibrate(CLI::App& app) {
    auto o = std::make_shared<CalibrateOptions>();
    CLI::App* cmd = app.add_subcommand(
        "calibrate", "The whole calibration from one TOML file: data, optional training campaign and surrogate training (or the "
                     "shipped ones), Sobol' analysis, three-phase inference, posterior predictions, the calibrated cell and "
                     "OUT/report.html + OUT/report.md. Stages whose inputs did not change are skipped (OUT/stages.json). "
                     "See configs/paper.toml for every key.");
    cmd->add_option("--config", o->config, "TOML configuration (configs/paper.toml: the paper's setup)")->required();
    addOutOption(cmd, o->out, "output directory (re-use it to skip finished stages)");
    addThreadsOption(cmd, o->threads, "OpenMP threads of every stage (overrides [run] threads; results do not depend on it)", 0);
    cmd->add_flag("--quiet", o->quiet, "no progress lines on stderr");
    cmd->callback([o]() { runCalibrate(*o); });
}

}  // namespace trbc::cli
