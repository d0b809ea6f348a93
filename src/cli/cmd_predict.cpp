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
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {
namespace {

namespace fs = std::filesystem;

}  // namespace

void registerPredict(CLI::App& app) {
    struct Opts {
        std::vector<std::string> posteriors;
        std::string inference, out, model, dataDir;
        bool single = false, quiet = false, noHierarchical = false;
        int direct = 0, directLevel = 3, maxSamples = 0, threads = 2, gridPoints = 100;
        std::uint64_t seed = 1;
        ExperimentOptions experiment;
        CacheOptions cache;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = app.add_subcommand(
        "predict", "Forward propagation of posteriors (docs/BAYESIAN_INFERENCE.md, prediction): every posterior sample through the surrogate (or "
                   "Hochmuth's law) and its own error model; predictive quantiles (5 %..95 %, 50/75/90/99 % bands) per "
                   "force / time / observable in OUT/predict_<posterior>_<experiment>.csv, the data against the 90 % band "
                   "in OUT/coverage.md and OUT/coverage.csv, provenance in OUT/predict.json; --direct N checks the "
                   "surrogate against the direct forward model. Plot with scripts/plot_predict.py OUT.");
    cmd->add_option("--posterior", o->posteriors, "posterior directory holding samples.csv (e.g. DIR/phase3/mills_2004); repeatable");
    cmd->add_option("--inference", o->inference,
                    "output directory of `trbc infer`: predict every phase-3b posterior DIR/phase3/<data set> (hierarchical)");
    cmd->add_flag("--single", o->single, "with --inference: also the phase-1 posteriors DIR/phase1/<data set> (single)");
    addOutOption(cmd, o->out);
    addSurrogateModelOption(cmd, o->model);
    addDataDirOption(cmd, o->dataDir);
    addNumber(cmd, "--max-samples", o->maxSamples, "use at most this many posterior samples (seeded choice; 0 = all)",
              NumberRange::closed(0, 1e8))
        ->capture_default_str();
    addNumber(cmd, "--grid", o->gridPoints, "forces on [0, 200] pN / times on [0, 0.5] s of the prediction curves",
              NumberRange::closed(2, 100000))
        ->capture_default_str();
    addNumber(cmd, "--direct", o->direct, "run the direct forward model on N posterior samples per posterior and compare",
              NumberRange::closed(0, 100000))
        ->capture_default_str();
    addNumber(cmd, "--direct-level", o->directLevel, "icosphere level of the direct forward model", NumberRange::closed(2, 6))
        ->capture_default_str();
    addNumber(cmd, "--seed", o->seed, "seed of the sample choices (--direct, --max-samples)", NumberRange::nonNegative())
        ->capture_default_str();
    addThreadsOption(cmd, o->threads);
    cmd->add_flag("--quiet", o->quiet, "no progress lines on stderr");
    addSolverOptions(cmd, o->experiment);
    addCacheOptions(cmd, o->cache);
    cmd->callback([o]() {
        omp_set_num_threads(o->threads);
        std::vector<fs::path> dirs;
        for (const std::string& p : o->posteriors) dirs.emplace_back(p);
        if (!o->inference.empty()) {
            const fs::path base(o->inference);
            if (!fs::is_directory(base)) throw InputError(fmt::format("--inference {}: not a directory", base.string()));
            std::vector<std::string> phases = {"phase3"};
            if (o->single) phases.insert(phases.begin(), "phase1");
            for (const std::string& ph : phases) {
                const fs::path d = base / ph;
                if (!fs::is_directory(d)) throw InputError(fmt::format("--inference {}: no {} directory (run `trbc infer --phase all` first)", base.string(), ph));
                std::vector<fs::path> found;
                for (const auto& e : fs::directory_iterator(d))
                    if (e.is_directory() && e.path().filename() != "theta_new" && fs::exists(e.path() / "samples.csv")) found.push_back(e.path());
                std::sort(found.begin(), found.end());
                if (found.empty()) throw InputError(fmt::format("--inference {}: no posterior samples in {}", base.string(), d.string()));
                dirs.insert(dirs.end(), found.begin(), found.end());
            }
        }
        if (dirs.empty()) throw InputError("predict: give --posterior DIR (repeatable) or --inference DIR");
        ensureWritableDirectory(o->out);
        const fs::path outDir(o->out);
        auto say = [o](const std::string& line) {
            if (!o->quiet) std::cerr << line << '\n';
        };

        // Read everything first so that bad input fails before any work.
        std::vector<PosteriorSamples> posts;
        for (const fs::path& d : dirs) posts.push_back(readPosteriorSamples(d));
        const fs::path dataDir = experimentDirectory(o->dataDir);
        const std::vector<RbcDataSet> data = loadRbcDataSets(dataDir);
        const fs::path modelDir = surrogateModelDirectory(o->model);
        auto surrogate = std::make_shared<Surrogate>(Surrogate::load(modelDir));
        const RbcModel model = surrogateRbcModel(surrogate);

        PredictionOptions popt;
        popt.gridPoints = o->gridPoints;
        std::vector<PosteriorPrediction> predictions;
        std::vector<DirectComparison> direct;
        std::vector<fs::path> files;
        nlohmann::json postJson = nlohmann::json::array();
        ExperimentOptions eopt = o->experiment;
        eopt.level = o->directLevel;
        eopt.cacheDir = cacheDirectory(o->cache);
        for (const PosteriorSamples& full : posts) {
            const RbcDataSet* ds = nullptr;
            for (const RbcDataSet& d : data)
                if (d.name == full.name) ds = &d;
            if (!ds) say(fmt::format("predict {}: no data set named {} in {}: no coverage", full.label, full.name, dataDir.string()));
            const std::uint64_t seed = o->seed ^ fnv1a(full.label);
            const PosteriorSamples s =
                o->maxSamples > 0 ? selectSamples(full, subsampleIndices(full.values.cols(), o->maxSamples, seed)) : full;
            say(fmt::format("predict {}: {} {} samples from {}", s.label, s.values.cols(), experimentName(s.experiment), s.file.string()));
            predictions.push_back(predictPosterior(s, model, ds, popt));
            for (const fs::path& f : writePredictionCsv(outDir, predictions.back())) files.push_back(f);
            nlohmann::json pj = {{"label", s.label},
                                 {"samples", fs::absolute(s.file).lexically_normal().string()},
                                 {"experiment", experimentName(s.experiment)},
                                 {"samples_total", full.values.cols()},
                                 {"samples_used", s.values.cols()},
                                 {"data_set", ds ? ds->name : ""},
                                 {"data_file", ds ? ds->file.string() : ""},
                                 {"data_hash", ds ? ds->contentHash : ""}};
            if (o->direct > 0) {
                const std::vector<Eigen::Index> idx = subsampleIndices(s.values.cols(), o->direct, seed ^ 0x5EEDULL);
                std::vector<long long> idxOut(idx.begin(), idx.end());
                pj["direct_sample_indices"] = idxOut;
                say(fmt::format("predict {}: direct forward model (level {}) on {} samples", s.label, eopt.level, idx.size()));
                auto rows = compareWithDirectModel(s, model, ds, idx, eopt, say);
                direct.insert(direct.end(), rows.begin(), rows.end());
            }
            postJson.push_back(pj);
        }

        writeCoverageCsv(outDir / "coverage.csv", predictions);
        std::string md = "# Posterior predictions against the data\n\n";
        md += fmt::format("Made by `{}` (trbc {}), surrogate `{}`, seed {}.\n\n", commandLine(), kVersion,
                          fs::absolute(modelDir).lexically_normal().string(), o->seed);
        md += coverageMarkdown(predictions);
        if (!direct.empty()) md += "\n" + directComparisonMarkdown(direct, eopt.level);
        writeFileAtomically(outDir / "coverage.md", md);

        nlohmann::json networks = nlohmann::json::object();
        const std::pair<const char*, const TrainedNetwork*> nets[3] = {
            {"equilibrium", &surrogate->equilibrium}, {"stretching", &surrogate->stretching}, {"relaxation", &surrogate->relaxation}};
        for (const auto& [name, net] : nets) networks[name] = {{"data_hash", net->dataHash}, {"command", net->command}};
        nlohmann::json directJson = nlohmann::json::array();
        for (const DirectComparison& d : direct)
            directJson.push_back({{"posterior", d.label}, {"observable", d.observable}, {"n", d.surrogate.size()}, {"failures", d.failures},
                                  {"rmse", d.surrogate.empty() ? nlohmann::json(nullptr) : nlohmann::json(d.rmse())}});
        std::vector<std::string> fileNames;
        for (const fs::path& f : files) fileNames.push_back(f.filename().string());
        const nlohmann::json prov = {{"command", commandLine()},
                                     {"version", kVersion},
                                     {"seed", o->seed},
                                     {"max_samples", o->maxSamples},
                                     {"grid_points", o->gridPoints},
                                     {"levels", predictiveLevels()},
                                     {"model", {{"dir", fs::absolute(modelDir).lexically_normal().string()}, {"networks", networks}}},
                                     {"data_dir", fs::absolute(dataDir).lexically_normal().string()},
                                     {"inference", o->inference},
                                     {"posteriors", postJson},
                                     {"direct", {{"samples", o->direct}, {"level", eopt.level}, {"comparison", directJson}}},
                                     {"files", fileNames}};
        writeFileAtomically(outDir / "predict.json", prov.dump(2) + "\n");

        int total = 0, inside = 0;
        for (const PosteriorPrediction& p : predictions)
            for (const CoveragePoint& c : p.coverage) total += 1, inside += c.inside() ? 1 : 0;
        std::cout << fmt::format("trbc predict: {} posterior(s); {} of {} data points inside their 90 % band\n", predictions.size(), inside, total);
        std::cout << fmt::format("coverage: {}\nprovenance: {}\n", (outDir / "coverage.md").string(), (outDir / "predict.json").string());
    });
}

}  // namespace trbc::cli
