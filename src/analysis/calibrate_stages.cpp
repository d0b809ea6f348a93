#include "analysis/calibrate_stages.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

#include "analysis/report.hpp"
#include "analysis/toml_reader.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/shell_quote.hpp"
#include "core/version.hpp"
#include "inference/rbc_problem.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc {
namespace fs = std::filesystem;

FingerprintPart FingerprintPart::literal(std::string text) { return {.kind = Kind::Text, .text = std::move(text)}; }

FingerprintPart FingerprintPart::of(std::string entry, std::string prefix) {
    return {.kind = Kind::Entry, .text = std::move(prefix), .entry = std::move(entry)};
}

FingerprintPart FingerprintPart::bytesOf(fs::path file, std::string missing) {
    return {.kind = Kind::File, .file = std::move(file), .missing = std::move(missing)};
}

FingerprintPart FingerprintPart::recorded(std::string stage) { return {.kind = Kind::Recorded, .entry = std::move(stage)}; }

namespace {

using Part = FingerprintPart;

/// The command lines of the stages: trbc and the figure scripts, every path quoted.
struct Commands {
    const CalibrateTools& tools;
    std::string trbc(const std::string& args) const { return shellQuote(tools.trbc) + " " + args; }
    std::string script(const std::string& name, const std::string& args) const {
        return shellQuote(tools.python) + " " + shellQuote(tools.scripts / name) + " " + args;
    }
};

/// A step of one stage of the same name, run by `commands`, recording them and the optional ones.
CalibrateStep commandStep(CalibrateStage stage, std::vector<std::string> commands, std::vector<std::string> optionalCommands = {}) {
    CalibrateStep s;
    s.name = stage.name;
    s.stage = std::move(stage);
    s.commands = std::move(commands);
    s.optionalCommands = std::move(optionalCommands);
    s.recorded = s.commands;
    s.recorded.insert(s.recorded.end(), s.optionalCommands.begin(), s.optionalCommands.end());
    return s;
}

CalibrateStep fingerprintStep(std::string name, std::vector<Part> inputs) {
    CalibrateStep s;
    s.action = CalibrateAction::Fingerprint;
    s.name = name;
    s.stage = {.name = std::move(name), .inputs = std::move(inputs)};
    return s;
}

std::string dataSetEntry(const CalibrateDataSet& d) { return "dataset." + d.name; }

/// Each data set's bytes, the data stage, and all data sets by name (the fingerprint of the
/// stages that read every data set).
void addDataSteps(std::vector<CalibrateStep>& steps, const CalibrateConfig& cfg, const fs::path& out) {
    std::vector<Part> data = {Part::literal("data"), Part::literal(kVersion)};
    for (const CalibrateDataSet& d : cfg.data) {
        steps.push_back(fingerprintStep(dataSetEntry(d), {Part::literal(d.name), Part::literal(d.experiment), Part::bytesOf(d.file)}));
        data.push_back(Part::of(dataSetEntry(d)));
    }
    CalibrateStep s;
    s.action = CalibrateAction::StageData;
    s.name = "data";
    s.stage = {.name = "data", .inputs = data, .outputs = {out / "data" / kRbcDataManifest}};
    steps.push_back(s);
    std::vector<const CalibrateDataSet*> byName;
    for (const CalibrateDataSet& d : cfg.data) byName.push_back(&d);
    std::sort(byName.begin(), byName.end(), [](const auto* a, const auto* b) { return a->name < b->name; });
    std::vector<Part> all = {Part::literal("data")};
    for (const CalibrateDataSet* d : byName) all.push_back(Part::of(dataSetEntry(*d), d->name));
    steps.push_back(fingerprintStep("datasets", all));
}

/// Campaign and surrogate training when configured, then the networks' fingerprint ("model").
void addSurrogateSteps(std::vector<CalibrateStep>& steps, const CalibrateConfig& cfg, const fs::path& out, const std::string& threads,
                       const Commands& c, const fs::path& modelDir) {
    const std::string seed = std::to_string(cfg.seed);
    if (cfg.campaignMode == "run")
        steps.push_back(commandStep(
            {.name = "campaign",
             .inputs = {Part::literal("campaign"), Part::literal(kVersion), Part::literal(std::to_string(cfg.campaignSamples)),
                        Part::literal(std::to_string(cfg.campaignForcesPerCell)), Part::literal(cfg.campaignDesign),
                        Part::literal(std::to_string(cfg.campaignLevel)), Part::literal(seed)},
             .outputs = {out / "campaign" / "samples.csv"}},
            {c.trbc(fmt::format("campaign --samples {} --forces-per-cell {} --design {} --seed {} --level {} --threads {} --out {} --resume",
                                cfg.campaignSamples, cfg.campaignForcesPerCell, cfg.campaignDesign, seed, cfg.campaignLevel, threads,
                                shellQuote(out / "campaign")))}));
    if (cfg.surrogateMode == "train")
        steps.push_back(commandStep({.name = "surrogate",
                                     .inputs = {Part::literal("surrogate"), Part::literal(kVersion), Part::of("campaign"), Part::literal(seed)},
                                     .outputs = {modelDir / "relaxation.json"}},
                                    {c.trbc(fmt::format("surrogate train --data {} --out {} --seed {} --threads {}",
                                                        shellQuote(out / "campaign"), shellQuote(modelDir), seed, threads))}));
    std::vector<Part> model = {Part::literal("model")};
    for (const std::string& name : surrogateNetworkNames())
        model.push_back(Part::bytesOf(modelDir / (name + ".json"),
                                      fmt::format("surrogate directory {} lacks {}.json (make one with `trbc surrogate train`)",
                                                  modelDir.string(), name)));
    // A branched model's classifier decides its outputs as much as the networks do.
    if (fs::exists(modelDir / "branch.json")) model.push_back(Part::bytesOf(modelDir / "branch.json", ""));
    steps.push_back(fingerprintStep("model", model));
}

CalibrateStep sobolStep(const CalibrateConfig& cfg, const fs::path& out, const std::string& threads, const Commands& c,
                        const fs::path& modelDir) {
    const std::string seed = std::to_string(cfg.seed);
    return commandStep({.name = "sobol",
                        .inputs = {Part::literal("sobol"), Part::literal(kVersion), Part::of("model"),
                                   Part::literal(std::to_string(cfg.sobolSamples)), Part::literal(std::to_string(cfg.sobolForces)),
                                   Part::literal(std::to_string(cfg.sobolResamples)), Part::literal(seed)},
                        .outputs = {out / "sobol" / "sobol_indices.csv"},
                        .clean = {out / "sobol"}},
                       {c.trbc(fmt::format("sobol --model {} --samples {} --forces {} --resamples {} --seed {} --threads {} --no-plot --out {}",
                                           shellQuote(modelDir), cfg.sobolSamples, cfg.sobolForces, cfg.sobolResamples, seed, threads,
                                           shellQuote(out / "sobol")))},
                       {c.script("plot_sobol.py", shellQuote(out / "sobol"))});
}

/// The inference settings' fingerprint, then one step: phase 1 of every data set (its parts) and
/// phases 2-3 (its own stage), all by one `trbc infer`.
void addInferenceSteps(std::vector<CalibrateStep>& steps, const CalibrateConfig& cfg, const fs::path& out, const std::string& threads,
                       const Commands& c, const fs::path& modelDir) {
    const fs::path inf = out / "inference";
    const std::string seed = std::to_string(cfg.seed);
    std::string priorArgs;
    for (const auto& [name, b] : cfg.inferencePrior) priorArgs += fmt::format(" --prior {}={:.17g}:{:.17g}", name, b.first, b.second);
    steps.push_back(fingerprintStep("inference.settings", {Part::literal("inference"), Part::literal(kVersion), Part::of("model"),
                                                           Part::literal(std::to_string(cfg.inferenceSamples)), Part::literal(cfg.fvkDensity),
                                                           Part::literal(seed), Part::literal(priorArgs)}));
    CalibrateStep s;
    s.name = "inference";
    s.stage = {.name = "inference.phase23",
               .inputs = {Part::of("inference.settings")},
               .outputs = {inf / "posterior_stats.csv"},
               .clean = {inf / "phase2", inf / "phase3", out / "figures"}};
    for (const CalibrateDataSet& d : cfg.data) {
        const std::string name = "inference.phase1." + d.name;
        s.parts.push_back({.name = name,
                           .inputs = {Part::of("inference.settings"), Part::of(dataSetEntry(d))},
                           .outputs = {inf / "phase1" / d.name / "samples.csv"},
                           .clean = {inf / "phase1" / d.name},
                           .wallRecord = inf / "phase1" / d.name / "run.json"});
        s.stage.inputs.push_back(Part::of(name));
    }
    s.partsNote = "phase 1 for {} data set(s), then phases 2-3";
    s.prune = inf / "phase1";
    s.commands = {c.trbc(fmt::format("infer --out {} --data-dir {} --model {} --samples {} --seed {} --fvk-density {} --threads {} --resume{}",
                                     shellQuote(inf), shellQuote(out / "data"), shellQuote(modelDir), cfg.inferenceSamples, seed,
                                     cfg.fvkDensity, threads, priorArgs))};
    s.optionalCommands = {c.script("plot_posterior.py", shellQuote(inf) + " --out " + shellQuote(out / "figures"))};
    s.recorded = s.commands;
    steps.push_back(s);
}

CalibrateStep predictStep(const CalibrateConfig& cfg, const fs::path& out, const std::string& threads, const Commands& c,
                          const fs::path& modelDir) {
    return commandStep(
        {.name = "predict",
         .inputs = {Part::literal("predict"), Part::literal(kVersion), Part::of("inference.phase23"), Part::of("datasets"), Part::of("model"),
                    Part::literal(std::to_string(cfg.predictionMaxSamples)), Part::literal(std::to_string(cfg.predictionGrid)),
                    Part::literal(std::to_string(cfg.seed))},
         .outputs = {out / "predict" / "coverage.csv"},
         .clean = {out / "predict"}},
        {c.trbc(fmt::format("predict --inference {} --out {} --data-dir {} --model {} --max-samples {} --grid {} --seed {} --threads {} --quiet",
                            shellQuote(out / "inference"), shellQuote(out / "predict"), shellQuote(out / "data"), shellQuote(modelDir),
                            cfg.predictionMaxSamples, cfg.predictionGrid, cfg.seed, threads))},
        {c.script("plot_predict.py", shellQuote(out / "predict") + " --data-dir " + shellQuote(out / "data"))});
}

CalibrateStep cellStep(const CalibrateConfig& cfg, const fs::path& out, const std::string& threads, const Commands& c) {
    return commandStep({.name = "cell",
                        .inputs = {Part::literal("cell"), Part::literal(kVersion), Part::of("inference.phase23"),
                                   Part::literal(fmt::format("{:.17g}", cfg.cellQuantile)), Part::literal(std::to_string(cfg.cellLevel))},
                        .outputs = {out / "cell" / "cell.json"},
                        .clean = {out / "cell"}},
                       {c.trbc(fmt::format("export --posterior {} --quantile {:.17g} --level {} --threads {} --out {} > /dev/null",
                                           shellQuote(out / "inference" / "phase3" / "theta_new"), cfg.cellQuantile, cfg.cellLevel, threads,
                                           shellQuote(out / "cell")))});
}

/// The flow validations with the theta_new means (hours): optional, and never cleaned, since
/// `trbc validate` keeps every finished case whose command and cell are unchanged.
CalibrateStep validationStep(const CalibrateConfig& cfg, const fs::path& out, const Commands& c) {
    const fs::path vcfg = cfg.validationConfig.empty() ? c.tools.validationConfig : cfg.validationConfig;
    std::string only;
    for (const std::string& k : cfg.validationOnly) only += (only.empty() ? " --only " : ",") + k;
    std::vector<Part> inputs = {Part::literal("validation"), Part::literal(kVersion), Part::of("inference.phase23"), Part::bytesOf(vcfg),
                                Part::literal(only)};
    // Every file of the validation config's base chain: `trbc validate` reads them all, so a change to
    // any of them re-runs the stage.
    if (fs::is_regular_file(vcfg)) {
        std::vector<fs::path> chain, bases;
        parseWithBases(vcfg, chain, bases);
        for (const fs::path& b : bases) inputs.push_back(Part::bytesOf(b));
    }
    return commandStep({.name = "validation",
                        .inputs = inputs,
                        .outputs = {out / "validation" / "validation.json"}},
                       {},
                       {c.trbc(fmt::format("validate --config {} --posterior {} --out {} --threads {}{} --quiet", shellQuote(vcfg),
                                           shellQuote(out / "inference" / "phase3" / "theta_new"), shellQuote(out / "validation"), 1, only))});
}

/// The report: cheap, but recorded like a stage so that an unchanged run leaves it alone. Its
/// mesh-convergence section reads the records of `meshDir` (<point>_L<level>.json), so a remade
/// record remakes the report.
CalibrateStep reportStep(const CalibrateConfig& cfg, const fs::path& out, const fs::path& meshDir) {
    std::vector<Part> inputs = {Part::literal("report"), Part::literal(kVersion), Part::bytesOf(cfg.file)};
    for (const fs::path& b : cfg.bases) inputs.push_back(Part::bytesOf(b));  // the report shows them
    for (const MeshConvergenceRecord& r : meshConvergenceRecords(meshDir))  // the report's mesh table reads them
        inputs.push_back(Part::literal(r.file.filename().string())), inputs.push_back(Part::bytesOf(r.file));
    for (Part p : {Part::of("datasets"), Part::of("model"), Part::of("inference.phase23"), Part::of("predict"),
                   cfg.cellEnabled ? Part::of("cell") : Part::literal("disabled"), Part::recorded("sobol"),
                   cfg.validationEnabled ? Part::of("validation") : Part::literal("disabled")})
        inputs.push_back(std::move(p));
    CalibrateStep s;
    s.action = CalibrateAction::Report;
    s.name = "report";
    s.stage = {.name = "report", .inputs = inputs, .outputs = {out / "report.html", out / "report.md"}};
    return s;
}

}  // namespace

fs::path calibrateModelDirectory(const CalibrateConfig& cfg, const fs::path& out, const CalibrateTools& tools) {
    if (cfg.surrogateMode == "train") return out / "surrogate";
    return cfg.surrogateMode == "path" ? cfg.surrogateDir : tools.shippedSurrogates;
}

std::vector<CalibrateStep> calibrateSteps(const CalibrateConfig& cfg, const fs::path& out, int threadCount, const CalibrateTools& tools) {
    const Commands c{tools};
    const std::string threads = std::to_string(threadCount);
    const fs::path modelDir = calibrateModelDirectory(cfg, out, tools);
    std::vector<CalibrateStep> steps;
    addDataSteps(steps, cfg, out);
    addSurrogateSteps(steps, cfg, out, threads, c, modelDir);
    if (cfg.sobolEnabled) steps.push_back(sobolStep(cfg, out, threads, c, modelDir));
    addInferenceSteps(steps, cfg, out, threads, c, modelDir);
    steps.push_back(predictStep(cfg, out, threads, c, modelDir));
    if (cfg.cellEnabled) steps.push_back(cellStep(cfg, out, threads, c));
    if (cfg.validationEnabled) steps.push_back(validationStep(cfg, out, c));
    steps.push_back(reportStep(cfg, out, tools.meshConvergence));
    return steps;
}

std::vector<std::string> stageDependencies(const CalibrateStage& stage) {
    std::vector<std::string> d;
    for (const FingerprintPart& p : stage.inputs)
        if (p.kind == FingerprintPart::Kind::Entry) d.push_back(p.entry);
    return d;
}

std::string stageFingerprint(const CalibrateStage& stage, const std::map<std::string, std::string>& known, const StageLedger& ledger) {
    std::vector<std::string> parts;
    for (const FingerprintPart& p : stage.inputs) {
        switch (p.kind) {
            case FingerprintPart::Kind::Text:
                parts.push_back(p.text);
                break;
            case FingerprintPart::Kind::Entry: {
                const auto it = known.find(p.entry);
                if (it == known.end())  // a table whose dependencies are out of order
                    throw std::logic_error(fmt::format("calibrate: stage '{}' depends on '{}', which has no fingerprint yet", stage.name, p.entry));
                parts.push_back(p.text + it->second);
                break;
            }
            case FingerprintPart::Kind::File:
                if (!p.missing.empty() && !fs::exists(p.file)) throw InputError(p.missing);
                parts.push_back(p.text + fileFingerprint(p.file));
                break;
            case FingerprintPart::Kind::Recorded:
                parts.push_back(p.text + ledger.fingerprint(p.entry));
                break;
        }
    }
    return fingerprintOf(parts);
}

nlohmann::json stageCalibrateData(const CalibrateConfig& cfg, const fs::path& dir) {
    fs::remove_all(dir);
    nlohmann::json manifest = nlohmann::json::array();
    for (const CalibrateDataSet& d : cfg.data) {
        const fs::path rel = fs::path(d.experiment) / (d.name + ".csv");
        fs::create_directories(dir / d.experiment);
        fs::copy_file(d.file, dir / rel, fs::copy_options::overwrite_existing);
        manifest.push_back({{"name", d.name}, {"experiment", d.experiment}, {"file", rel.string()}, {"source", d.file.string()}});
    }
    writeFileAtomically(dir / kRbcDataManifest, manifest.dump(2) + "\n");
    return manifest;
}

CalibrationReportInputs calibrationReportInputs(const CalibrateConfig& cfg, const fs::path& out, const CalibrateTools& tools) {
    CalibrationReportInputs ri;
    ri.outputDirectory = out;
    ri.configFile = cfg.file;
    ri.configBases = cfg.bases;
    ri.surrogateDirectory = calibrateModelDirectory(cfg, out, tools);
    ri.meshConvergenceDirectory = tools.meshConvergence;
    ri.version = kVersion;
    for (const CalibrateDataSet& d : cfg.data) ri.dataSets.push_back(fmt::format("{} ({}): {}", d.name, d.experiment, d.file.string()));
    return ri;
}

}  // namespace trbc
