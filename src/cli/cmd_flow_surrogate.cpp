// trbc flow train: the flow networks (surrogate/flow_surrogate.hpp, docs/FLOW_CAMPAIGN.md) from a
// shear campaign, their held-out accuracy, optional k-fold cross-validation and a learning curve
// over prefixes of the campaign.
#include <fmt/format.h>
#include <omp.h>

#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <sstream>

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

struct FlowTrainCli {
    std::vector<std::string> campaigns;
    std::string out, curve;
    FlowSurrogateTrainingOptions t;
    int folds = 0, threads = 2;
};

nlohmann::json accuracyJson(const FlowAccuracy& a) {
    auto num = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(nullptr); };
    return {{"cases", a.cases},
            {"tank_treading_cases", a.tankTreading},
            {"inclination_rmse_deg", num(a.inclinationRmseDeg)},
            {"swing_rmse_deg", num(a.swingRmseDeg)},
            {"ttf_relative_rmse", num(a.ttfRelativeRmse)},
            {"steady_cases", a.steady},
            {"inclination_rmse_steady_deg", num(a.inclinationRmseSteadyDeg)},
            {"ttf_relative_rmse_steady", num(a.ttfRelativeRmseSteady)},
            {"campaign_inclination_se_rms_deg", num(a.inclinationNoiseDeg)},
            {"campaign_ttf_relative_se_rms", num(a.ttfRelativeNoise)},
            {"brier", num(a.brier)},
            {"far_cases", a.far},
            {"far_misclassified", a.farMisclassified},
            {"near_cases", a.near},
            {"near_misclassified", a.nearMisclassified}};
}

std::string percent(long k, long n) { return n > 0 ? fmt::format("{:.1f} % ({}/{})", 100.0 * double(k) / double(n), k, n) : "-"; }

std::string accuracyRow(const std::string& label, const FlowAccuracy& a) {
    return fmt::format("| {} | {} | {:.3f} | {:.3f} | {:.2f} % | {:.3f} / {:.2f} % ({}) | {:.3f} / {:.2f} % | {} | {} | {:.4f} |", label,
                       a.cases, a.inclinationRmseDeg, a.swingRmseDeg, 100.0 * a.ttfRelativeRmse, a.inclinationRmseSteadyDeg,
                       100.0 * a.ttfRelativeRmseSteady, a.steady, a.inclinationNoiseDeg, 100.0 * a.ttfRelativeNoise,
                       percent(a.farMisclassified, a.far), percent(a.nearMisclassified, a.near), a.brier);
}

constexpr const char* kTableHead =
    "| set | cases | angle RMSE (deg) | swing RMSE (deg) | TTF RMSE | angle / TTF RMSE, steady cases (count) | campaign's own "
    "uncertainty, angle / TTF (RMS of *_se) | misclassified far from the boundary | near it | Brier |\n"
    "|---|---|---|---|---|---|---|---|---|---|";

/// Campaigns trained together must differ at most in their level and size: the same box, design,
/// seed (so that their cases pair), cytosol, start and stopping rule.
void checkCampaignsMatch(const std::vector<std::string>& campaigns) {
    std::optional<nlohmann::json> first;
    for (const std::string& c : campaigns) {
        std::filesystem::path dir = c;
        if (std::filesystem::is_regular_file(dir)) dir = dir.parent_path();
        const std::filesystem::path meta = dir / "campaign.json";
        if (campaigns.size() < 2 || !std::filesystem::exists(meta)) continue;
        nlohmann::json settings;
        try {
            std::ifstream in(meta);
            settings = nlohmann::json::parse(in).at("settings");
        } catch (const std::exception& e) {
            throw InputError(fmt::format("--campaign {}: {} is not a campaign description ({})", c, meta.string(), e.what()));
        }
        settings.erase("level");
        settings.erase("cases");
        settings.erase("inject_failures");
        if (!first) {
            first = settings;
            continue;
        }
        for (const auto& [key, value] : settings.items())
            if (!first->contains(key) || (*first)[key] != value)
                throw InputError(fmt::format("--campaign {}: its setting '{}' ({}) differs from the first campaign's ({}); campaigns trained "
                                             "together differ only in level and size", c, key, value.dump(),
                                             first->contains(key) ? (*first)[key].dump() : "absent"));
    }
}

void runFlowTrain(FlowTrainCli& o) {
    if (o.threads > 0) omp_set_num_threads(o.threads);
    const std::vector<long> sizes = o.curve.empty() ? std::vector<long>{} : parseIntegerList(o.curve, "--learning-curve", "a case count", 20);
    std::vector<ShearCampaignRow> rows;
    nlohmann::json sources = nlohmann::json::array();
    std::string from;
    checkCampaignsMatch(o.campaigns);
    for (const std::string& c : o.campaigns) {
        bool complete = true;
        std::vector<ShearCampaignRow> part = readShearCampaignRows(c, &complete);
        const int level = part.empty() ? 0 : part.front().meshLevel;
        std::cerr << fmt::format("flow train: {} cases from {}{}{}\n", part.size(), c, level > 0 ? fmt::format(" (level {})", level) : "",
                                 complete ? "" : " (campaign not complete: its finished cases)");
        sources.push_back({{"campaign", c}, {"cases", part.size()}, {"level", level}, {"complete", complete}});
        from += fmt::format("{}{} ({} cases{}{})", from.empty() ? "" : " and ", c, part.size(), level > 0 ? fmt::format(", level {}", level) : "",
                            complete ? "" : ", not complete");
        rows.insert(rows.end(), std::make_move_iterator(part.begin()), std::make_move_iterator(part.end()));
    }
    o.t.command = commandLine();
    nlohmann::json j = withBuild({{"command", o.t.command}, {"campaigns", sources}, {"restarts", o.t.restarts},
                                  {"ensemble", o.t.ensemble}, {"boundary_factor", o.t.boundaryFactor}});
    std::string md = fmt::format("Flow networks from {}; command: `{}`\n\n{}\n", from, o.t.command, kTableHead);
    const FlowSurrogateTrainingReport rep = trainFlowSurrogate(rows, o.t);
    rep.model.save(o.out);
    j["levels"] = rep.model.levels;
    j["predicts_level"] = rep.model.level;
    j["data_hash"] = rep.dataHash;
    j["rows"] = rep.rows;
    j["finished_rows"] = rep.used;
    j["training_rows"] = {{"regime", rep.regimeRows}, {"tank_treading", rep.tankTreadingRows}};
    j["test"] = accuracyJson(rep.test);
    j["wall_s"] = rep.wallSeconds;
    if (rep.model.multiLevel())
        md = fmt::format("Multi-level networks (the mesh level an input); every accuracy below is on held-out level-{} cases, "
                         "with every coarser case in training.\n\n", rep.model.level) + md;
    md += accuracyRow(fmt::format("held out ({:.0f} %)", 100.0 * o.t.testFraction), rep.test) + "\n";
    if (o.folds >= 2) {
        const FlowCrossValidation cv = crossValidateFlowSurrogate(rows, o.t, o.folds);
        j["cross_validation"] = {{"folds", cv.folds}, {"pooled", accuracyJson(cv.pooled)}};
        md += accuracyRow(fmt::format("{}-fold CV", cv.folds), cv.pooled) + "\n";
    }
    if (!sizes.empty()) {
        // The prefixes are of the finest level's cases; the coarser levels' cases all stay in.
        std::vector<ShearCampaignRow> sorted, coarser;
        for (const ShearCampaignRow& r : rows) (r.meshLevel == rep.model.level ? sorted : coarser).push_back(r);
        std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) { return a.point.caseId < b.point.caseId; });
        nlohmann::json curve = nlohmann::json::array();
        md += fmt::format("\nLearning curve ({}-fold CV on the first N cases of the design)\n\n{}\n", std::max(o.folds, 5), kTableHead);
        for (long n : sizes) {
            if (n > long(sorted.size())) {
                std::cerr << fmt::format("flow train: learning curve: {} cases asked, {} in the campaign; skipped\n", n, sorted.size());
                continue;
            }
            std::vector<ShearCampaignRow> prefix(sorted.begin(), sorted.begin() + n);
            prefix.insert(prefix.end(), coarser.begin(), coarser.end());
            const FlowCrossValidation cv = crossValidateFlowSurrogate(prefix, o.t, std::max(o.folds, 5));
            curve.push_back({{"cases", n}, {"pooled", accuracyJson(cv.pooled)}});
            md += accuracyRow(fmt::format("N = {}", n), cv.pooled) + "\n";
        }
        j["learning_curve"] = curve;
    }
    writeFileAtomically(std::filesystem::path(o.out) / "training.json", j.dump(2) + "\n");
    writeFileAtomically(std::filesystem::path(o.out) / "accuracy.md", md);
    std::cout << md;
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
        "to (v, mu, FvK, b2, eta_m) on the prior box (docs/FLOW_CAMPAIGN.md): OUT/sobol_indices.csv, OUT/sobol_table.md");
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

void registerFlowTrain(CLI::App* flow) {
    auto o = std::make_shared<FlowTrainCli>();
    CLI::App* cmd = flow->add_subcommand(
        "train",
        "Flow networks from a shear campaign (docs/FLOW_CAMPAIGN.md): the probability of tank-treading and the angle, swing and "
        "TTF of the tank-treading state. Writes OUT/flow_regime.json, OUT/flow_tank_treading.json, OUT/flow_surrogate.json, "
        "the accuracy (held-out cases, optional k-fold CV and learning curve) in OUT/training.json and OUT/accuracy.md");
    cmd->add_option("--campaign", o->campaigns,
                    "a `trbc flow campaign` directory (its finished cases) or its cases.csv; repeatable: campaigns of "
                    "several mesh levels (same box) train multi-level networks that answer at the finest level, "
                    "whose cases are the test set")
        ->required()
        ->check(CLI::ExistingPath);
    addOutOption(cmd, o->out, "model directory");
    addNumber(cmd, "--restarts", o->t.restarts, "trainings per network from consecutive seeds", NumberRange::closed(1, 64))
        ->capture_default_str();
    cmd->add_flag("!--no-ensemble", o->t.ensemble, "keep only the best restart (default: the restarts' mean)");
    addNumber(cmd, "--seed", o->t.network.seed, "seed of the first restart's initial weights", NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--test-fraction", o->t.testFraction, "share of the finished cases held out", NumberRange::rightOpen(0, 1))
        ->capture_default_str();
    addNumber(cmd, "--folds", o->folds, "k-fold cross-validation of the whole procedure (0: none)", NumberRange::closed(0, 50))
        ->capture_default_str();
    cmd->add_option("--learning-curve", o->curve,
                    "comma-separated case counts N: cross-validated accuracy on the first N cases of the design (max(folds, 5) folds)");
    addThreadsOption(cmd, o->threads, "threads (the two networks train side by side)");
    cmd->callback([o]() { runFlowTrain(*o); });
}

}  // namespace trbc::cli
