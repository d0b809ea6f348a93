// trbc predict: forward propagation of posteriors (docs/BAYESIAN_INFERENCE.md, prediction). Parses options and
// calls the prediction library (src/analysis/prediction.hpp).
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>

#include "analysis/prediction.hpp"
#include "cli/common.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {
namespace {

namespace fs = std::filesystem;

struct PredictCommandOptions {
    std::vector<std::string> posteriors;
    std::string inference, out, model, dataDir;
    bool single = false, quiet = false;
    int direct = 0, directLevel = 3, maxSamples = 0, threads = 2, gridPoints = 100;
    std::uint64_t seed = 1;
    ExperimentOptions experiment;
    CacheOptions cache;
};

void addPredictOptions(CLI::App* cmd, PredictCommandOptions& o) {
    cmd->add_option("--posterior", o.posteriors, "posterior directory holding samples.csv (e.g. DIR/phase3/mills_2004); repeatable");
    cmd->add_option("--inference", o.inference,
                    "output directory of `trbc infer`: predict every phase-3b posterior DIR/phase3/<data set> (hierarchical)");
    cmd->add_flag("--single", o.single, "with --inference: also the phase-1 posteriors DIR/phase1/<data set> (single)");
    addOutOption(cmd, o.out);
    addSurrogateModelOption(cmd, o.model);
    addDataDirOption(cmd, o.dataDir);
    addNumber(cmd, "--max-samples", o.maxSamples, "use at most this many posterior samples (seeded choice; 0 = all)",
              NumberRange::closed(0, 1e8))
        ->capture_default_str();
    addNumber(cmd, "--grid", o.gridPoints, "forces on [0, 200] pN / times on [0, 0.5] s of the prediction curves",
              NumberRange::closed(2, 100000))
        ->capture_default_str();
    addNumber(cmd, "--direct", o.direct, "run the direct forward model on N posterior samples per posterior and compare",
              NumberRange::closed(0, 100000))
        ->capture_default_str();
    addNumber(cmd, "--direct-level", o.directLevel, "icosphere level of the direct forward model", NumberRange::closed(2, 6))
        ->capture_default_str();
    addNumber(cmd, "--seed", o.seed, "seed of the sample choices (--direct, --max-samples)", NumberRange::nonNegative())
        ->capture_default_str();
    addThreadsOption(cmd, o.threads);
    cmd->add_flag("--quiet", o.quiet, "no progress lines on stderr");
    addSolverOptions(cmd, o.experiment);
    addCacheOptions(cmd, o.cache);
}

/// The --posterior directories, then those of --inference.
std::vector<fs::path> posteriorDirectories(const PredictCommandOptions& o) {
    std::vector<fs::path> dirs(o.posteriors.begin(), o.posteriors.end());
    if (!o.inference.empty()) {
        const std::vector<fs::path> found = inferencePosteriorDirectories(o.inference, o.single);
        dirs.insert(dirs.end(), found.begin(), found.end());
    }
    if (dirs.empty()) throw InputError("predict: give --posterior DIR (repeatable) or --inference DIR");
    return dirs;
}

/// What the predictions are made of, all read and checked before any work.
struct PredictInputs {
    std::vector<PosteriorSamples> posteriors;
    fs::path dataDir, modelDir;
    std::vector<RbcDataSet> data;
    std::shared_ptr<Surrogate> surrogate;
};

PredictInputs readPredictInputs(const PredictCommandOptions& o, const std::vector<fs::path>& dirs) {
    PredictInputs in;
    for (const fs::path& d : dirs) in.posteriors.push_back(readPosteriorSamples(d));
    in.dataDir = experimentDirectory(o.dataDir);
    in.data = loadRbcDataSets(in.dataDir);
    in.modelDir = surrogateModelDirectory(o.model);
    in.surrogate = std::make_shared<Surrogate>(Surrogate::load(in.modelDir));
    return in;
}

/// The predictions of every posterior (with the direct-model comparisons of --direct), the CSV
/// files written and each posterior's record for predict.json.
struct PredictResults {
    std::vector<PosteriorPrediction> predictions;
    std::vector<DirectComparison> direct;
    std::vector<fs::path> files;
    nlohmann::json posteriors = nlohmann::json::array();
};

void predictPosteriors(const PredictCommandOptions& o, const PredictInputs& in, const ExperimentOptions& eopt, PredictResults& res) {
    auto say = [&o](const std::string& line) {
        if (!o.quiet) std::cerr << line << '\n';
    };
    const RbcModel model = surrogateRbcModel(in.surrogate);
    PredictionOptions popt;
    popt.gridPoints = o.gridPoints;
    for (const PosteriorSamples& full : in.posteriors) {
        const RbcDataSet* ds = nullptr;
        for (const RbcDataSet& d : in.data)
            if (d.name == full.name) ds = &d;
        if (!ds) say(fmt::format("predict {}: no data set named {} in {}: no coverage", full.label, full.name, in.dataDir.string()));
        const std::uint64_t seed = o.seed ^ fnv1a(full.label);
        const PosteriorSamples s = o.maxSamples > 0 ? selectSamples(full, subsampleIndices(full.values.cols(), o.maxSamples, seed)) : full;
        say(fmt::format("predict {}: {} {} samples from {}", s.label, s.values.cols(), experimentName(s.experiment), s.file.string()));
        res.predictions.push_back(predictPosterior(s, model, ds, popt));
        for (const fs::path& f : writePredictionCsv(o.out, res.predictions.back())) res.files.push_back(f);
        nlohmann::json pj = {{"label", s.label},
                             {"samples", fs::absolute(s.file).lexically_normal().string()},
                             {"experiment", experimentName(s.experiment)},
                             {"samples_total", full.values.cols()},
                             {"samples_used", s.values.cols()},
                             {"data_set", ds ? ds->name : ""},
                             {"data_file", ds ? ds->file.string() : ""},
                             {"data_hash", ds ? ds->contentHash : ""}};
        if (o.direct > 0) {
            const std::vector<Eigen::Index> idx = subsampleIndices(s.values.cols(), o.direct, seed ^ 0x5EEDULL);
            pj["direct_sample_indices"] = std::vector<long long>(idx.begin(), idx.end());
            say(fmt::format("predict {}: direct forward model (level {}) on {} samples", s.label, eopt.level, idx.size()));
            const std::vector<DirectComparison> rows = compareWithDirectModel(s, model, ds, idx, eopt, say);
            res.direct.insert(res.direct.end(), rows.begin(), rows.end());
        }
        res.posteriors.push_back(pj);
    }
}

/// OUT/predict.json: command, settings, model, data and the files written.
nlohmann::json predictProvenance(const PredictCommandOptions& o, const PredictInputs& in, const PredictResults& res, int directLevel) {
    nlohmann::json directJson = nlohmann::json::array();
    for (const DirectComparison& d : res.direct)
        directJson.push_back({{"posterior", d.label}, {"observable", d.observable}, {"n", d.surrogate.size()}, {"failures", d.failures},
                              {"rmse", d.surrogate.empty() ? nlohmann::json(nullptr) : nlohmann::json(d.rmse())}});
    std::vector<std::string> fileNames;
    for (const fs::path& f : res.files) fileNames.push_back(f.filename().string());
    return withBuild({{"command", commandLine()},
                      {"seed", o.seed},
                      {"max_samples", o.maxSamples},
                      {"grid_points", o.gridPoints},
                      {"levels", predictiveLevels()},
                      {"model", {{"dir", fs::absolute(in.modelDir).lexically_normal().string()}, {"networks", surrogateNetworksJson(*in.surrogate)}}},
                      {"data_dir", fs::absolute(in.dataDir).lexically_normal().string()},
                      {"inference", o.inference},
                      {"posteriors", res.posteriors},
                      {"direct", {{"samples", o.direct}, {"level", directLevel}, {"comparison", directJson}}},
                      {"files", fileNames}});
}

void runPredict(const PredictCommandOptions& o) {
    setProvenanceSeed(o.seed);
    omp_set_num_threads(o.threads);
    const std::vector<fs::path> dirs = posteriorDirectories(o);
    ensureWritableDirectory(o.out);
    const fs::path outDir(o.out);
    const PredictInputs in = readPredictInputs(o, dirs);
    ExperimentOptions eopt = o.experiment;
    eopt.level = o.directLevel;
    eopt.cacheDir = cacheDirectory(o.cache);
    PredictResults res;
    predictPosteriors(o, in, eopt, res);

    writeCoverageCsv(outDir / "coverage.csv", res.predictions);
    std::string md = "# Posterior predictions against the data\n\n";
    md += fmt::format("Made by `{}` (trbc {}), surrogate `{}`, seed {}.\n\n", commandLine(), kVersion,
                      fs::absolute(in.modelDir).lexically_normal().string(), o.seed);
    md += coverageMarkdown(res.predictions);
    if (!res.direct.empty()) md += "\n" + directComparisonMarkdown(res.direct, eopt.level);
    writeFileAtomically(outDir / "coverage.md", md);
    writeFileAtomically(outDir / "predict.json", predictProvenance(o, in, res, eopt.level).dump(2) + "\n");

    int total = 0, inside = 0;
    for (const PosteriorPrediction& p : res.predictions)
        for (const CoveragePoint& c : p.coverage) total += 1, inside += c.inside() ? 1 : 0;
    std::cout << fmt::format("trbc predict: {} posterior(s); {} of {} data points inside their 90 % band\n", res.predictions.size(), inside, total);
    std::cout << fmt::format("coverage: {}\nprovenance: {}\n", (outDir / "coverage.md").string(), (outDir / "predict.json").string());
}

}  // namespace

void registerPredict(CLI::App& app) {
    auto o = std::make_shared<PredictCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "predict", "Forward propagation of posteriors (docs/BAYESIAN_INFERENCE.md, prediction): every posterior sample through the surrogate (or "
                   "Hochmuth's law) and its own error model; predictive quantiles (5 %..95 %, 50/75/90/99 % bands) per "
                   "force / time / observable in OUT/predict_<posterior>_<experiment>.csv, the data against the 90 % band "
                   "in OUT/coverage.md and OUT/coverage.csv, provenance in OUT/predict.json; --direct N checks the "
                   "surrogate against the direct forward model. Plot with scripts/plot_predict.py OUT.");
    addPredictOptions(cmd, *o);
    cmd->callback([o]() { runPredict(*o); });
}

}  // namespace trbc::cli
