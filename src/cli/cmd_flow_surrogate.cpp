// trbc flow train: the flow networks (surrogate/flow_surrogate.hpp, docs/FLOW_NETWORKS.md) from a
// shear campaign, their held-out accuracy, optional k-fold cross-validation and a learning curve
// over prefixes of the campaign.
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <omp.h>

#include <algorithm>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "analysis/flow_sobol.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "surrogate/flow_surrogate.hpp"
#include "surrogate/sobol.hpp"
#include "surrogate/sobol_io.hpp"

namespace trbc::cli {
namespace {

std::vector<int> hiddenLayerWidths(const std::string& text) {
    std::vector<int> widths;
    for (long w : parseIntegerList(text, "--hidden", "a layer width", 1, 4096)) widths.push_back(int(w));
    return widths;
}

struct FlowTrainCli {
    std::vector<std::string> campaigns;
    std::string out, curve, hidden;
    FlowSurrogateTrainingOptions t;
    int folds = 0, threads = 2;
};

void runFlowTrain(FlowTrainCli& o) {
    if (o.threads > 0) omp_set_num_threads(o.threads);
    const std::vector<long> sizes = o.curve.empty() ? std::vector<long>{} : parseIntegerList(o.curve, "--learning-curve", "a case count", 20);
    if (!o.hidden.empty()) o.t.network.hiddenLayers = hiddenLayerWidths(o.hidden);
    std::vector<ShearCampaignRow> rows;
    FlowTrainingSummary s;
    checkShearCampaignsMatch(std::vector<std::filesystem::path>(o.campaigns.begin(), o.campaigns.end()));
    for (const std::string& c : o.campaigns) {
        bool complete = true;
        std::vector<ShearCampaignRow> part = readShearCampaignRows(c, &complete);
        const int level = part.empty() ? 0 : part.front().meshLevel;
        std::cerr << fmt::format("flow train: {} cases from {}{}{}\n", part.size(), c, level > 0 ? fmt::format(" (level {})", level) : "",
                                 complete ? "" : " (campaign not complete: its finished cases)");
        s.sources.push_back({c, long(part.size()), level, complete});
        rows.insert(rows.end(), std::make_move_iterator(part.begin()), std::make_move_iterator(part.end()));
    }
    o.t.command = commandLine();
    s.options = o.t;
    s.training = trainFlowSurrogate(rows, o.t);
    s.training.model.save(o.out);
    if (o.folds >= 2) s.crossValidation = crossValidateFlowSurrogate(rows, o.t, o.folds);
    if (!sizes.empty()) {
        s.learningCurveFolds = std::max(o.folds, 5);
        const FlowLearningCurve curve = flowLearningCurve(rows, s.training.model.level, sizes, o.t, s.learningCurveFolds);
        for (long n : curve.skipped)
            std::cerr << fmt::format("flow train: learning curve: {} cases asked, {} in the campaign; skipped\n", n, curve.available);
        s.learningCurve = curve.points;
    }
    std::cout << writeFlowTrainingReport(o.out, s);
}

struct FlowDistillCli {
    std::string model, out, hidden;
    FlowDistillationOptions d;
    int threads = 2;
};

void runFlowDistill(FlowDistillCli& o) {
    if (o.threads > 0) omp_set_num_threads(o.threads);
    if (!o.hidden.empty()) o.d.hiddenLayers = hiddenLayerWidths(o.hidden);
    std::error_code ec;
    if (std::filesystem::exists(o.out, ec) && std::filesystem::equivalent(o.out, o.model, ec))
        throw InputError(fmt::format("--out {} is the --model directory; the student would overwrite its ensemble", o.out));
    const FlowSurrogate teacher = FlowSurrogate::load(o.model);
    const std::filesystem::path trainingFile = std::filesystem::path(o.model) / "training.json";
    if (!std::filesystem::is_regular_file(trainingFile, ec))
        throw InputError(fmt::format("{}: missing (--model must be a `trbc flow train` directory)", trainingFile.string()));
    nlohmann::json training;
    try {
        training = nlohmann::json::parse(readFileBytes(trainingFile));
    } catch (const nlohmann::json::exception& e) {
        throw InputError(fmt::format("{}: not JSON ({})", trainingFile.string(), e.what()));
    }
    o.d.command = commandLine();
    const FlowDistillation d = distillFlowSurrogate(teacher, o.d);
    d.model.save(o.out);
    writeFileAtomically(std::filesystem::path(o.out) / "training.json",
                        flowDistillationJson(training, o.d, d, o.model, o.d.command).dump(2) + "\n");
    const FlowDistillationCheck& c = d.check;
    std::cout << fmt::format(
        "flow distill: {} samples, hidden {}, {:.1f} s; against the ensemble at {} other points ({} tank-treading): probability "
        "RMS {:.4f}, regime disagreement {:.2f} %, angle RMS {:.3f} deg, swing RMS {:.3f} deg, TTF RMS {:.2f} %\n",
        o.d.samples, fmt::join(o.d.hiddenLayers, ","), d.wallSeconds, c.points, c.tankTreading, c.probabilityRmse,
        100.0 * c.regimeDisagreement, c.inclinationRmseDeg, c.swingRmseDeg, 100.0 * c.ttfRelativeRmse);
}

struct FlowSobolCli {
    std::string surrogate, config, out;
    long samples = 4096;
    std::uint64_t seed = 1;
    int resamples = 100, threads = 2;
};

void runFlowSobol(const FlowSobolCli& o) {
    const FlowSurrogate model = FlowSurrogate::load(o.surrogate);
    const ValidationConfig cfg = readValidationConfig(o.config, defaultExperimentDirectory());
    const std::vector<FlowSobolOutput> outputs = flowSobolOutputs(cfg);
    if (outputs.empty()) throw InputError(fmt::format("--config {}: no angle, TTF or threshold sweep", o.config));
    omp_set_num_threads(o.threads);
    setProvenanceSeed(o.seed);
    Eigen::VectorXd lo(5), hi(5);
    for (int k = 0; k < 5; ++k) lo(k) = kCellBox[k].lo, hi(k) = kCellBox[k].hi;
    SobolOptions so;
    so.nBase = o.samples;
    so.seed = o.seed;
    so.resamples = o.resamples;
    std::vector<std::string> names;
    for (const FlowSobolOutput& f : outputs) names.push_back(f.name);
    const auto t0 = SteadyClock::now();
    const SobolResult r = sobolAnalysis([&](const Eigen::MatrixXd& X) { return flowSobolModel(model, outputs, cfg.etaIn, X); }, lo, hi,
                                        so, {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um"}, names);
    const double wall = secondsSince(t0);
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec) throw InputError(fmt::format("--out: cannot create {}: {}", o.out, ec.message()));
    const std::filesystem::path dir = o.out;
    writeSobolCsv(dir / "sobol_indices.csv", r);
    std::string md = fmt::format("First-order / total Sobol' indices (± 95 % bootstrap half-width) of the flow networks' outputs, cell "
                                 "parameters uniform on the prior box; N = {} base rows, {} evaluations; command: `{}`\n\n"
                                 "| output | v | mu | FvK | b2 | eta_m |\n|---|---|---|---|---|---|\n",
                                 r.nBase, r.evaluations, commandLine());
    for (Eigen::Index k = 0; k < Eigen::Index(names.size()); ++k) {
        md += "| " + names[std::size_t(k)];
        for (Eigen::Index i = 0; i < 5; ++i)
            md += fmt::format(" | {:.2f} ± {:.2f} / {:.2f} ± {:.2f}", r.S1(k, i), r.S1_ci(k, i), r.ST(k, i), r.ST_ci(k, i));
        md += " |\n";
    }
    writeFileAtomically(dir / "sobol_table.md", md);
    const nlohmann::json j = withBuild({{"command", commandLine()}, {"surrogate", o.surrogate}, {"config", o.config},
                                        {"seed", o.seed}, {"n_base", r.nBase}, {"evaluations", r.evaluations}, {"resamples", r.resamples},
                                        {"wall_s", wall}});
    writeFileAtomically(dir / "sobol.json", j.dump(2) + "\n");
    std::cout << md;
}

}  // namespace

void registerFlowSobol(CLI::App* flow) {
    auto o = std::make_shared<FlowSobolCli>();
    CLI::App* cmd = flow->add_subcommand(
        "sobol",
        "Sobol' indices of the flow networks' angle, TTF and critical stress at every validation viscosity of --config with respect "
        "to (v, mu, FvK, b2, eta_m) on the prior box (docs/FLOW_NETWORKS.md): OUT/sobol_indices.csv, OUT/sobol_table.md");
    cmd->add_option("--surrogate", o->surrogate, "flow networks (a `trbc flow train` directory)")->required()->check(CLI::ExistingDirectory);
    cmd->add_option("--config", o->config, "validation configuration whose sweeps name the outputs")->required()->check(CLI::ExistingFile);
    addNumber(cmd, "--samples", o->samples, "N, base rows of the Saltelli design", NumberRange::closed(2, double(1L << 22)))
        ->capture_default_str();
    addNumber(cmd, "--seed", o->seed, "seed of the bootstrap", NumberRange::nonNegative())->capture_default_str();
    addNumber(cmd, "--resamples", o->resamples, "bootstrap resamples", NumberRange::closed(2, 100000))->capture_default_str();
    addOutOption(cmd, o->out);
    addThreadsOption(cmd, o->threads);
    cmd->callback([o]() { runFlowSobol(*o); });
}

void registerFlowDistill(CLI::App* flow) {
    auto o = std::make_shared<FlowDistillCli>();
    CLI::App* cmd = flow->add_subcommand(
        "distill",
        "One network in place of each ensemble of flow networks (docs/CALIBRATION_WITH_FLOWS.md, the distilled networks), trained on the "
        "ensemble's mean at points of the campaign's box: one pass per evaluation instead of one per member, for the flow "
        "likelihood of `trbc infer`. Writes the networks to OUT and OUT/training.json: the ensemble's cross-validated "
        "accuracy and the student's error against the ensemble at points it did not see, which the likelihood adds");
    cmd->add_option("--model", o->model, "the ensemble (a `trbc flow train` directory with its training.json)")
        ->required()
        ->check(CLI::ExistingDirectory);
    addOutOption(cmd, o->out, "model directory");
    addNumber(cmd, "--samples", o->d.samples, "training points (a Sobol' design over the campaign's box)",
              NumberRange::closed(1000, 1e7))
        ->capture_default_str();
    addNumber(cmd, "--check-samples", o->d.checkSamples, "comparison points (a uniform design of seed + 1)", NumberRange::closed(100, 1e7))
        ->capture_default_str();
    addNumber(cmd, "--seed", o->d.seed, "seed of the training design", NumberRange::nonNegative())->capture_default_str();
    addNumber(cmd, "--training-seed", o->d.trainingSeed, "seed of the initial weights and mini-batch order", NumberRange::nonNegative())
        ->capture_default_str();
    cmd->add_option("--hidden", o->hidden, "comma-separated widths of the student's hidden layers (tanh)")
        ->default_str(fmt::format("{}", fmt::join(FlowDistillationOptions{}.hiddenLayers, ",")));
    addThreadsOption(cmd, o->threads, "threads (the two networks train side by side)");
    cmd->callback([o]() { runFlowDistill(*o); });
}

void registerFlowTrain(CLI::App* flow) {
    auto o = std::make_shared<FlowTrainCli>();
    CLI::App* cmd = flow->add_subcommand(
        "train",
        "Flow networks from a shear campaign (docs/FLOW_NETWORKS.md): the probability of tank-treading and the angle, swing and "
        "TTF of the tank-treading state. Writes OUT/flow_regime.json, OUT/flow_tank_treading.json, OUT/flow_surrogate.json, "
        "the accuracy (held-out cases, optional k-fold CV and learning curve) in OUT/training.json and OUT/accuracy.md, and with "
        "--folds every held-out row's predictions in OUT/cv_predictions.csv");
    cmd->add_option("--campaign", o->campaigns,
                    "a `trbc flow campaign` directory (its finished cases) or its cases.csv; repeatable: campaigns of "
                    "several mesh levels (same box) train multi-level networks that answer at the finest level, "
                    "whose cases are the test set; campaigns of the same design from random and in-plane starts "
                    "train the regime on the random ones and the angle, swing and TTF on the in-plane ones")
        ->required()
        ->check(CLI::ExistingPath);
    addOutOption(cmd, o->out, "model directory");
    cmd->add_option("--hidden", o->hidden, "comma-separated widths of the hidden layers of both networks (tanh)")
        ->default_str(fmt::format("{}", fmt::join(flowNetworkDefaults().hiddenLayers, ",")));
    addNumber(cmd, "--restarts", o->t.restarts, "trainings per network from consecutive seeds", NumberRange::closed(1, 64))
        ->capture_default_str();
    cmd->add_flag("!--no-ensemble", o->t.ensemble, "keep only the best restart (default: the restarts' mean)");
    addNumber(cmd, "--seed", o->t.network.seed, "seed of the first restart's initial weights", NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--test-fraction", o->t.testFraction, "share of the cases (case ids) held out", NumberRange::rightOpen(0, 1))
        ->capture_default_str();
    addNumber(cmd, "--folds", o->folds, "k-fold cross-validation of the whole procedure (0: none)", NumberRange::closed(0, 50))
        ->capture_default_str();
    cmd->add_option("--learning-curve", o->curve,
                    "comma-separated case counts N: cross-validated accuracy on the first N cases of the design (max(folds, 5) folds)");
    addThreadsOption(cmd, o->threads, "threads (the two networks train side by side)");
    cmd->callback([o]() { runFlowTrain(*o); });
}

}  // namespace trbc::cli
