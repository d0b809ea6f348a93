// trbc surrogate train | eval: the three networks of docs/CAMPAIGN_AND_SURROGATE.md, trained from a campaign
// and evaluated in batches on a CSV of inputs.
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <chrono>
#include <fstream>
#include <iostream>
#include <memory>
#include <set>

#include "cli/common.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "sampling/campaign.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {
namespace {

nlohmann::json accuracyJson(const std::vector<OutputAccuracy>& acc) {
    nlohmann::json j = nlohmann::json::array();
    for (const OutputAccuracy& a : acc)
        j.push_back({{"output", a.name}, {"n", a.n}, {"rmse", a.rmse}, {"relative_rmse", a.relativeRmse}, {"mae", a.mae},
                     {"max_abs", a.maxAbs}, {"mean_relative", a.meanRelative}, {"r2", a.r2}});
    return j;
}

std::string accuracyMarkdown(const std::vector<OutputAccuracy>& acc) {
    std::string s = "| output | n | RMSE | relative RMSE | MAE | max abs | R^2 |\n|---|---|---|---|---|---|---|\n";
    for (const OutputAccuracy& a : acc)
        s += fmt::format("| {} | {} | {:.4g} | {:.3f} % | {:.4g} | {:.4g} | {:.5f} |\n", a.name, a.n, a.rmse,
                         100 * a.relativeRmse, a.mae, a.maxAbs, a.r2);
    return s;
}

/// Held-out rows with truth and prediction: inputs, outputs, outputs_pred.
void writePredictionsCsv(const std::filesystem::path& p, const Eigen::MatrixXd& inputs, const Eigen::MatrixXd& truth,
                         const Eigen::MatrixXd& predicted) {
    std::string text = csvProvenance() +
        "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN,D_um,hmin_um,hmax_um,D0_um,D1_um,tc_s,"
        "D_um_pred,hmin_um_pred,hmax_um_pred,D0_um_pred,D1_um_pred,tc_s_pred\n";
    for (Eigen::Index c = 0; c < inputs.cols(); ++c) {
        std::string line;
        for (const Eigen::MatrixXd* m : {&inputs, &truth, &predicted})
            for (Eigen::Index r = 0; r < 6; ++r) line += fmt::format("{}{:.10g}", line.empty() ? "" : ",", (*m)(r, c));
        text += line + '\n';
    }
    writeFileAtomically(p, text);
}

/// cv.md: pooled out-of-fold accuracy and the relative RMSE of every output per fold.
std::string crossValidationMarkdown(const CrossValidationReport& cv, const std::string& dataHash, std::uint64_t testSeed) {
    std::string md = fmt::format("# Surrogate cross-validation\n\nMade by `{}` (trbc {}), data hash {}: {} folds of whole cells "
                                 "(seeded permutation, test seed {}); every cell is predicted once, by the networks "
                                 "trained without it. {:.0f} s.\n\n## Pooled out-of-fold predictions\n\n",
                                 commandLine(), kVersion, dataHash, cv.folds, testSeed, cv.wallSeconds);
    md += accuracyMarkdown(cv.pooled) + "\n## Relative RMSE per fold (%)\n\n| fold |";
    for (const auto& a : cv.pooled) md += " " + a.name + " |";
    md += "\n|---|---|---|---|---|---|---|\n";
    for (std::size_t f = 0; f < cv.perFold.size(); ++f) {
        md += fmt::format("| {} |", f);
        for (const auto& a : cv.perFold[f]) md += fmt::format(" {:.3f} |", 100 * a.relativeRmse);
        md += "\n";
    }
    return md;
}

/// The accuracy where the equilibrium branch switches (SwitchAccuracy), as JSON and as a section.
nlohmann::json switchJson(const SwitchAccuracy& a) {
    if (!std::isfinite(a.vSwitch)) return nullptr;
    return {{"v_switch", a.vSwitch},           {"band_v", a.band},
            {"cells_near_switch", a.cells},    {"kicked_cells", a.kickedCells},
            {"misclassified_cells", a.misclassified < 0 ? nlohmann::json(nullptr) : nlohmann::json(a.misclassified)},
            {"near_switch", accuracyJson(a.nearSwitch)}, {"kicked", accuracyJson(a.kicked)},
            {"right_branch_cells", a.misclassified < 0 ? nlohmann::json(nullptr) : nlohmann::json(a.rightBranchCells)},
            {"right_branch", a.misclassified < 0 ? nlohmann::json(nullptr) : accuracyJson(a.rightBranch)}};
}

std::string switchMarkdown(const SwitchAccuracy& a) {
    if (!std::isfinite(a.vSwitch)) return "";
    std::string md = fmt::format(
        "\n## Near the switch of the equilibrium branch\n\nCells with v >= {:.4f} ({} below the smallest v of a cell "
        "whose lowest-energy state is not the symmetric disc, so every cell within {} in v of the switch line): {} "
        "cells, {} of them kicked. ",
        a.vSwitch - a.band, a.band, a.band, a.cells, a.kickedCells);
    md += a.misclassified < 0 ? std::string("The surrogate has no branch classifier.\n\n")
                              : fmt::format("Branch misclassified by the surrogate: {} of these cells.\n\n", a.misclassified);
    md += accuracyMarkdown(a.nearSwitch) + "\nThe kicked cells alone:\n\n" + accuracyMarkdown(a.kicked);
    if (a.misclassified >= 0)
        md += fmt::format("\nThe {} near cells whose branch the classifier got right (the regressors' own error; each "
                          "misclassified cell adds the whole jump, so one alone among {} cells makes hmin's RMSE at "
                          "least jump / sqrt({})):\n\n",
                          a.rightBranchCells, a.cells, a.cells) +
              accuracyMarkdown(a.rightBranch);
    return md;
}

bool listed(const std::vector<std::string>& list, const std::string& name) {
    return std::find(list.begin(), list.end(), name) != list.end();
}

// Values of the network-list options (--ensemble, --distill).
std::vector<std::string> networkNamesOrNone() {
    std::vector<std::string> allowed = surrogateNetworkNames();
    allowed.insert(allowed.begin(), "none");
    return allowed;
}

struct TrainCommandOptions {
    std::string data, out;
    SurrogateTrainingOptions t;
    int threads = 2;
    int cvFolds = 0;
    std::string relaxationVariables = "log";
    std::string stretchingVariables = "sqrt-b2";
    std::vector<std::string> ensemble{"relaxation"};
    std::vector<std::string> distill{"relaxation"};
    std::string branch = "auto";
    std::map<long, int> kicked;  ///< the campaign's equilibrium branches (for the accuracy near the switch)
};

void addTrainOptions(CLI::App* cmd, TrainCommandOptions& o) {
    cmd->add_option("--data", o.data, "campaign directory (samples.csv, or the finished cells of a running one) or a table CSV")
        ->required();
    addOutOption(cmd, o.out, "model directory");
    addNumber(cmd, "--seed", o.t.network.seed, "seed of the initial weights and mini-batch order", NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--split-seed", o.t.network.splitSeed, "seed of the training/validation split", NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--test-fraction", o.t.testFraction, "share of the cells held out as the test set", NumberRange::rightOpen(0.0, 0.5))
        ->capture_default_str();
    addNumber(cmd, "--test-seed", o.t.testSeed, "seed of the choice of test cells", NumberRange::nonNegative())->capture_default_str();
    addNumber(cmd, "--restarts", o.t.restarts,
                    "trainings per network from seeds seed, seed+1, ...; the lowest validation loss is kept, or all of "
                    "them for the networks of --ensemble",
              NumberRange::closed(1, 100))
        ->capture_default_str();
    addNumber(cmd, "--max-epochs", o.t.network.maxEpochs, "epoch cap of each network", NumberRange::closed(1, 1e7))
        ->capture_default_str();
    addThreadsOption(cmd, o.threads, "networks trained concurrently (results do not depend on it)", 1, 3);
    cmd->add_option("--relaxation-variables", o.relaxationVariables,
                    "log: the relaxation network maps (v, log mu, log FvK, b2, log etam) to log(tc mu/etam); linear: the raw "
                    "variables")
        ->check(CLI::IsMember({"log", "linear"}))->capture_default_str();
    cmd->add_option("--stretching-variables", o.stretchingVariables,
                    "sqrt-b2: the stretching network sees sqrt(b2) (the hardening sets in at stretches ~ 1/sqrt(b2)); "
                    "linear: b2")
        ->check(CLI::IsMember({"sqrt-b2", "linear"}))->capture_default_str();
    cmd->add_option("--ensemble", o.ensemble,
                    "networks that keep all their restarts and predict with the members' mean (geometric mean for log "
                    "outputs): any of equilibrium, stretching, relaxation, or none")
        ->check(CLI::IsMember(networkNamesOrNone()))->delimiter(',')->capture_default_str();
    cmd->add_option("--distill", o.distill,
                    "ensemble networks replaced by one network trained on the ensemble's predictions at "
                    "--distill-samples uniform points of the prior box (one network pass per evaluation instead of one "
                    "per member; the default): any of the --ensemble networks, or none; "
                    "when not given, the default's networks that are not in --ensemble are left out")
        ->check(CLI::IsMember(networkNamesOrNone()))->delimiter(',')->capture_default_str();
    // 1e7 points x (5 inputs + the teachers' outputs) doubles: about 1 GB at most.
    addNumber(cmd, "--distill-samples", o.t.distillSamples, "box points of each distillation (at most 1e7: memory)",
              NumberRange::closed(1000, 1e7))
        ->capture_default_str();
    addNumber(cmd, "--cup-hmin-um", o.t.cupHminUm,
              "with --branch auto, a kicked cell counts as the cup (the branch the classifier separates) when its hmin "
              "is at least this; the other kicked states stay close to the disc",
              NumberRange::closed(0.0, 10.0, "um"))
        ->capture_default_str();
    cmd->add_option("--branch", o.branch,
                    "auto: where the campaign's equilibria.csv holds cups (near v = 1), also train a branch classifier "
                    "on (v, FvK) and give the three networks the branch as one more input (branch.json); none: the three "
                    "networks alone, which smear the jump to the cup over both sides of the switch "
                    "(docs/CAMPAIGN_AND_SURROGATE.md)")
        ->check(CLI::IsMember({"auto", "none"}))->capture_default_str();
    addNumber(cmd, "--cv-folds", o.cvFolds,
                    "also estimate the held-out error by K-fold cross-validation over whole cells (K more trainings; "
                    "writes cv.md, cv.json, cv_predictions.csv); 0: off",
              NumberRange::closed(0, 100))
        ->capture_default_str();
}

/// --cv-folds, --ensemble and --distill checked against each other; a --distill that was not given
/// keeps only the default's networks that are in --ensemble.
void reconcileNetworkLists(TrainCommandOptions& o, bool distillGiven) {
    if (o.cvFolds == 1) throw InputError("surrogate train: --cv-folds must be 0 (off) or at least 2, got 1");
    if (!distillGiven) {
        std::erase_if(o.distill, [&](const std::string& name) { return !listed(o.ensemble, name); });
        if (o.distill.empty()) o.distill = {"none"};
    }
    if (listed(o.ensemble, "none") && o.ensemble.size() > 1)
        throw InputError("surrogate train: --ensemble none cannot be combined with network names");
    if (listed(o.distill, "none") && o.distill.size() > 1)
        throw InputError("surrogate train: --distill none cannot be combined with network names");
    for (const std::string& name : surrogateNetworkNames())
        if (listed(o.distill, name) && !listed(o.ensemble, name))
            throw InputError(fmt::format("surrogate train: --distill {} needs {} in --ensemble (the network it is "
                                         "distilled from)", name, name));
}

SurrogateTrainingOptions trainingOptions(const TrainCommandOptions& o) {
    SurrogateTrainingOptions t = o.t;
    t.command = commandLine();
    setProvenanceSeed(t.network.seed);
    if (o.branch == "auto") t.cellBranch = o.kicked;
    t.logRelaxation = o.relaxationVariables == "log";
    t.sqrtB2Stretching = o.stretchingVariables == "sqrt-b2";
    const auto& names = surrogateNetworkNames();
    for (int k = 0; k < 3; ++k) {
        t.ensemble[k] = listed(o.ensemble, names[std::size_t(k)]);
        t.distill[k] = listed(o.distill, names[std::size_t(k)]);
    }
    if (t.restarts < 2 && (t.ensemble[0] || t.ensemble[1] || t.ensemble[2]))
        std::cerr << "surrogate train: --restarts 1 leaves one network per ensemble (nothing to average)\n";
    t.progress = [](const std::string& net, const EpochRecord& e) {
        if (e.reduced || e.last || e.epoch % 100 == 0)
            std::cerr << fmt::format("  {:<11} epoch {:>4}  train {}  validation {:.3e}  best {:.3e}  rate {:.0e}{}\n",
                                     net, e.epoch,
                                     std::isnan(e.trainLoss) ? std::string("(none)") : fmt::format("{:.3e}", e.trainLoss),
                                     e.validationLoss, e.bestValidationLoss, e.learningRate,
                                     e.last ? "  (done)" : e.reduced ? "  (restored best, rate / 10)" : "");
    };
    return t;
}

SwitchAccuracy testSwitchAccuracy(const SurrogateTrainingReport& rep, const std::map<long, int>& kicked) {
    return switchAccuracy(rep.testCellIds, rep.testInputs, rep.testTruth, rep.testPredicted, kicked,
                          rep.model.branched ? &rep.testBranch : nullptr, &rep.cellLabel);
}

/// MODEL_DIR/accuracy.json: settings, data, per-network training records, held-out accuracy.
nlohmann::json trainingJson(const TrainCommandOptions& o, const SurrogateTrainingOptions& t, const SurrogateTrainingReport& rep,
                            bool complete, double wall) {
    nlohmann::json j = withBuild({{"command", commandLine()},
                                  {"data", o.data},
                                  {"data_complete", complete},
                                  {"data_hash", rep.dataHash},
                                  {"rows", rep.rows},
                                  {"cells", rep.cells},
                                  {"test_cells", rep.testCells},
                                  {"test_seed", t.testSeed},
                                  {"seed", t.network.seed},
                                  {"restarts", t.restarts},
                                  {"relaxation_variables", o.relaxationVariables},
                                  {"stretching_variables", o.stretchingVariables},
                                  {"ensemble", o.ensemble},
                                  {"distill", o.distill},
                                  {"distill_samples", t.distillSamples},
                                  {"split_seed", t.network.splitSeed},
                                  {"wall_s", wall},
                                  {"networks", nlohmann::json::object()},
                                  {"dropped_where", rep.droppedWhere},
                                  {"branch", o.branch},
                                  {"branched", rep.model.branched},
                                  {"cup_hmin_um", t.cupHminUm},
                                  {"test", accuracyJson(rep.test)},
                                  {"test_near_switch", switchJson(testSwitchAccuracy(rep, o.kicked))},
                                  {"validation", accuracyJson(rep.validation)}});
    const auto& names = surrogateNetworkNames();
    const TrainedNetwork* nets[3] = {&rep.model.equilibrium, &rep.model.stretching, &rep.model.relaxation};
    for (int k = 0; k < 3; ++k)
        j["networks"][names[k]] = {{"samples_used", rep.used[k]},
                                   {"samples_dropped", rep.dropped[k]},
                                   {"wall_s", rep.wallSeconds[k]},
                                   {"epochs", nets[k]->history.passes()},
                                   {"seed", nets[k]->options.seed},
                                   {"ensemble_members", 1 + nets[k]->ensemble.size()},
                                   {"distilled_from_members", nets[k]->distillation.members},
                                   {"best_epoch", nets[k]->history.bestEpoch},
                                   {"best_validation_loss", nets[k]->history.bestValidationLoss},
                                   {"hit_epoch_cap", nets[k]->history.hitEpochCap}};
    if (rep.model.branched)
        j["networks"]["branch"] = {{"samples_used", rep.branchUsed},
                                   {"wall_s", rep.branchWallSeconds},
                                   {"epochs", rep.model.branch.history.passes()},
                                   {"seed", rep.model.branch.options.seed},
                                   {"best_epoch", rep.model.branch.history.bestEpoch},
                                   {"best_validation_loss", rep.model.branch.history.bestValidationLoss},
                                   {"hit_epoch_cap", rep.model.branch.history.hitEpochCap}};
    return j;
}

/// MODEL_DIR/accuracy.md: test and validation accuracy, the training of each network.
std::string trainingMarkdown(const SurrogateTrainingReport& rep, const std::map<long, int>& kicked, bool complete) {
    std::string md = fmt::format("# Surrogate accuracy\n\nMade by `{}` (trbc {}), data hash {}: {} rows in {} cells{}; "
                                 "{} cells held out as the test set.\n\n## Test set (cells never seen in training or early stopping)\n\n",
                                 commandLine(), kVersion, rep.dataHash, rep.rows, rep.cells,
                                 complete ? "" : " (finished part of an unfinished campaign)", rep.testCells);
    md += accuracyMarkdown(rep.test) + "\n## Validation split (used for early stopping)\n\n" + accuracyMarkdown(rep.validation);
    md += "\n## Training\n\n| network | samples | dropped | epochs | members | wall s |\n|---|---|---|---|---|---|\n";
    const auto& names = surrogateNetworkNames();
    const TrainedNetwork* nets[3] = {&rep.model.equilibrium, &rep.model.stretching, &rep.model.relaxation};
    for (int k = 0; k < 3; ++k)
        md += fmt::format("| {} | {} | {} | {} | {} | {:.1f} |\n", names[k], rep.used[k], rep.dropped[k], nets[k]->history.passes(),
                          1 + nets[k]->ensemble.size(), rep.wallSeconds[k]);
    if (rep.model.branched)
        md += fmt::format("| branch | {} | 0 | {} | 1 | {:.1f} |\n", rep.branchUsed, rep.model.branch.history.passes(),
                          rep.branchWallSeconds);
    md += switchMarkdown(testSwitchAccuracy(rep, kicked));
    if (!rep.droppedWhere.empty()) md += "\nFailed samples by input:\n\n- " + fmt::format("{}", fmt::join(rep.droppedWhere, "\n- ")) + "\n";
    return md;
}

/// K-fold cross-validation over whole cells: cv.json, cv.md and cv_predictions.csv in `dir`.
void crossValidate(const std::vector<CampaignRow>& rows, const SurrogateTrainingOptions& t, const std::map<long, int>& kicked,
                   int folds, const std::string& dataHash, const std::filesystem::path& dir) {
    std::cerr << fmt::format("surrogate train: {}-fold cross-validation ({} more trainings)\n", folds, folds);
    SurrogateTrainingOptions c = t;
    c.progress = nullptr;
    const CrossValidationReport cv = crossValidateSurrogate(rows, c, folds);
    nlohmann::json cj = withBuild({{"command", commandLine()}, {"data_hash", dataHash},
                                   {"folds", cv.folds},       {"test_seed", t.testSeed}, {"wall_s", cv.wallSeconds},
                                   {"pooled", accuracyJson(cv.pooled)}, {"per_fold", nlohmann::json::array()}});
    const auto labels = cupLabels(rows, t.cellBranch, t.cupHminUm);
    const SwitchAccuracy near = switchAccuracy(cv.cellIds, cv.inputs, cv.truth, cv.predicted, kicked,
                                               cv.branched ? &cv.branch : nullptr, &labels);
    cj["near_switch"] = switchJson(near);
    for (const auto& f : cv.perFold) cj["per_fold"].push_back(accuracyJson(f));
    writeFileAtomically(dir / "cv.json", cj.dump(2) + "\n");
    const std::string cvMd = crossValidationMarkdown(cv, dataHash, t.testSeed) + switchMarkdown(near);
    writeFileAtomically(dir / "cv.md", cvMd);
    writePredictionsCsv(dir / "cv_predictions.csv", cv.inputs, cv.truth, cv.predicted);
    std::cout << "\n" << cvMd;
}

void runTrain(TrainCommandOptions& o, bool distillGiven) {
    reconcileNetworkLists(o, distillGiven);
    ensureWritableDirectory(o.out);
    bool complete = true;
    const auto rows = readCampaignRows(o.data, &complete);
    if (!complete)
        std::cerr << fmt::format("surrogate train: {} is an unfinished campaign; training on its {} finished rows\n", o.data, rows.size());
    o.kicked = readCampaignBranches(o.data);
    const SurrogateTrainingOptions t = trainingOptions(o);
    omp_set_num_threads(o.threads);
    const auto t0 = SteadyClock::now();
    const SurrogateTrainingReport rep = trainSurrogate(rows, t);
    const double wall = secondsSince(t0);
    rep.model.save(o.out);
    const std::filesystem::path dir = o.out;
    writeFileAtomically(dir / "accuracy.json", trainingJson(o, t, rep, complete, wall).dump(2) + "\n");
    const std::string md = trainingMarkdown(rep, o.kicked, complete);
    writeFileAtomically(dir / "accuracy.md", md);
    writePredictionsCsv(dir / "test_predictions.csv", rep.testInputs, rep.testTruth, rep.testPredicted);
    std::cout << md;
    if (o.cvFolds >= 2) crossValidate(rows, t, o.kicked, o.cvFolds, rep.dataHash, dir);
    std::cout << fmt::format("\nmodel: {}\n", dir.string());
}

void registerTrain(CLI::App* parent) {
    auto o = std::make_shared<TrainCommandOptions>();
    CLI::App* cmd = parent->add_subcommand(
        "train", "Train the equilibrium, stretching and relaxation networks (3 x 32 tanh, Adam, early stopping; "
                 "docs/CAMPAIGN_AND_SURROGATE.md, surrogate training) on a campaign table; writes MODEL_DIR/{equilibrium,stretching,relaxation}.json and "
                 "the held-out accuracy (accuracy.md, accuracy.json, test_predictions.csv)");
    addTrainOptions(cmd, *o);
    cmd->callback([o, cmd]() { runTrain(*o, cmd->count("--distill") > 0); });
}

void registerEval(CLI::App* parent) {
    struct Opts {
        std::string model, in, out;
        bool single = false;
        int threads = 1;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = parent->add_subcommand(
        "eval", "Evaluate the surrogates on a CSV with columns v, mu_uN_per_m, FvK (or kb_J), b2, etam_Pa_s_um, Fext_pN "
                "(other columns ignored); writes those inputs, D_um, hmin_um, hmax_um, D0_um, D1_um, tc_s and "
                "outside_training_box (1 = extrapolation)");
    addSurrogateModelOption(cmd, o->model);
    cmd->add_option("--in", o->in, "input CSV")->required();
    addOutOption(cmd, o->out, "output CSV");
    cmd->add_flag("--single-precision", o->single, "evaluate in float (about 3x faster, ~1e-6 relative difference)");
    addThreadsOption(cmd, o->threads);
    cmd->callback([o]() {
        const std::filesystem::path modelDir = surrogateModelDirectory(o->model);
        Surrogate s = Surrogate::load(modelDir);
        s.precision = o->single ? Precision::Single : Precision::Double;
        ensureWritableFile(o->out);
        const NumericTable t = readNumericTable(o->in, {"v", "mu_uN_per_m", "FvK", "kb_J", "b2", "etam_Pa_s_um", "Fext_pN"});
        Eigen::MatrixXd x(6, t.values.rows());
        x.row(0) = t.column("v").transpose();
        x.row(1) = t.column("mu_uN_per_m", "shear modulus, uN/m").transpose();
        if (t.find("FvK") >= 0)
            x.row(2) = t.column("FvK").transpose();
        else {
            const Eigen::VectorXd kb = t.column("kb_J", "or FvK; bending modulus in J");
            for (Eigen::Index i = 0; i < kb.size(); ++i) x(2, i) = CellParameters::fvkFromKb(x(1, i), kb(i));
        }
        x.row(3) = t.column("b2").transpose();
        x.row(4) = t.column("etam_Pa_s_um", "membrane viscosity, Pa s um").transpose();
        x.row(5) = t.column("Fext_pN", "bead force, pN").transpose();
        // Physically impossible rows (v outside (0, 1], non-positive moduli, negative b2 or force)
        // are errors; rows inside the physical domain but outside the training box are evaluated
        // and flagged as extrapolations.
        for (Eigen::Index i = 0; i < x.cols(); ++i) {
            try {
                validateCellParameters(CellParameters{x(0, i), x(1, i), x(2, i), x(3, i), x(4, i)}, true);
                validateForce(x(5, i), true);
            } catch (const InputError& e) {
                throw InputError(fmt::format("{}:{}: {}", o->in, t.lines[static_cast<std::size_t>(i)], e.what()));
            }
        }
        omp_set_num_threads(o->threads);
        const Eigen::MatrixXd y = s.evaluate(x);
        const auto outside = outsideTrainingBox(x);
        std::string text =
            csvProvenance() + "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN,D_um,hmin_um,hmax_um,D0_um,D1_um,tc_s,outside_training_box\n";
        long nOutside = 0;
        for (Eigen::Index i = 0; i < x.cols(); ++i) {
            for (int r = 0; r < 6; ++r)
                if (!std::isfinite(y(r, i)))
                    throw NumericalError(fmt::format("{}:{}: the surrogate gives a non-finite output for this row; nothing written",
                                                     o->in, t.lines[static_cast<std::size_t>(i)]));
            for (int r = 0; r < 6; ++r) text += fmt::format("{:.10g},", x(r, i));
            for (int r = 0; r < 6; ++r) text += fmt::format("{:.10g},", y(r, i));
            text += outside[i] ? "1\n" : "0\n";
            nOutside += outside[i];
        }
        writeFileAtomically(o->out, text);
        std::cerr << fmt::format("surrogate eval: {} rows -> {}{}\n", x.cols(), o->out,
                                 nOutside ? fmt::format(" ({} outside the training box: extrapolated, flagged)", nOutside) : "");
    });
}

void registerTest(CLI::App* parent) {
    struct Opts {
        std::string model, data, out;
        int threads = 1;
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = parent->add_subcommand(
        "test", "Accuracy of the surrogates against simulated rows they were not trained on (another campaign, or "
                "trbc simulate results in the campaign's columns): the table of accuracy.md (equilibrium outputs and "
                "tc once per cell, D0 and D1 per row); with --out also test.md, test.json and test_predictions.csv");
    addSurrogateModelOption(cmd, o->model);
    cmd->add_option("--data", o->data, "campaign directory (samples.csv, or the finished cells of a running one) or a table CSV")
        ->required();
    addOutOption(cmd, o->out, "directory for test.md, test.json and test_predictions.csv", false);
    addThreadsOption(cmd, o->threads);
    cmd->callback([o]() {
        const std::filesystem::path modelDir = surrogateModelDirectory(o->model);
        const Surrogate s = Surrogate::load(modelDir);
        if (!o->out.empty()) ensureWritableDirectory(o->out);
        bool complete = true;
        const auto rows = readCampaignRows(o->data, &complete);
        if (rows.empty()) throw InputError(fmt::format("--data {}: no finished rows", o->data));
        const std::string hash = campaignDataHash(rows);
        std::vector<const CampaignRow*> ptrs;
        for (const CampaignRow& r : rows) ptrs.push_back(&r);
        omp_set_num_threads(o->threads);
        const SurrogateTest t = testSurrogate(s, ptrs);
        long outside = 0;
        for (const bool b : outsideTrainingBox(t.inputs)) outside += b;
        const bool trainedOnIt = hash == s.relaxation.dataHash;  // the three networks carry the same training hash
        std::string md = fmt::format("# Surrogate test\n\nMade by `{}` (trbc {}): model {}, data {} ({} rows in {} cells{}, "
                                     "data hash {}; the model was trained on {}).\n\n",
                                     commandLine(), kVersion, modelDir.string(), o->data, rows.size(),
                                     std::set<long>(t.cellIds.begin(), t.cellIds.end()).size(),
                                     complete ? "" : ", finished part of an unfinished campaign", hash, s.relaxation.dataHash);
        if (trainedOnIt)
            md += "**These are the model's own training data: this is not a test.** Its held-out accuracy is in the model's "
                  "accuracy.md.\n\n";
        if (outside) md += fmt::format("{} rows lie outside the training box (extrapolated).\n\n", outside);
        md += accuracyMarkdown(t.accuracy);
        if (trainedOnIt) std::cerr << "surrogate test: the model was trained on these rows; the numbers are not a test\n";
        if (!o->out.empty()) {
            const std::filesystem::path dir = o->out;
            const nlohmann::json j = withBuild({{"command", commandLine()}, {"model", modelDir.string()},
                                                {"data", o->data},         {"data_complete", complete}, {"data_hash", hash},
                                                {"model_data_hash", s.relaxation.dataHash}, {"trained_on_these_data", trainedOnIt},
                                                {"rows", rows.size()},     {"outside_training_box", outside},
                                                {"test", accuracyJson(t.accuracy)}});
            writeFileAtomically(dir / "test.json", j.dump(2) + "\n");
            writeFileAtomically(dir / "test.md", md);
            writePredictionsCsv(dir / "test_predictions.csv", t.inputs, t.truth, t.predicted);
        }
        std::cout << md;
    });
}

}  // namespace

void registerSurrogate(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand("surrogate", "Neural-network surrogates of the three experiments (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training)");
    cmd->require_subcommand(1);
    registerTrain(cmd);
    registerEval(cmd);
    registerTest(cmd);
}

}  // namespace trbc::cli
