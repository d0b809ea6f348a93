// trbc infer: the hierarchical Bayesian inference on the surrogates. Parses options and calls
// runRbcInference (src/inference/rbc_pipeline.hpp).
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <memory>

#include "cli/common.hpp"
#include "core/output_dir.hpp"
#include "core/error.hpp"
#include "core/version.hpp"
#include "analysis/flow_data_sets.hpp"
#include "inference/rbc_pipeline.hpp"
#include "surrogate/flow_surrogate.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc::cli {

namespace {
/// --prior NAME=LO:HI, each validated by RbcPriorBox::set (the error names the parameter and its range).
RbcPriorBox parsePriorBox(const std::vector<std::string>& specs) {
    RbcPriorBox box;
    for (const std::string& s : specs) {
        const auto eq = s.find('='), colon = s.find(':', eq == std::string::npos ? 0 : eq);
        double lo = 0.0, hi = 0.0;
        bool ok = eq != std::string::npos && colon != std::string::npos;
        if (ok) {
            try {
                std::size_t n1 = 0, n2 = 0;
                const std::string a = s.substr(eq + 1, colon - eq - 1), b = s.substr(colon + 1);
                lo = std::stod(a, &n1);
                hi = std::stod(b, &n2);
                ok = n1 == a.size() && n2 == b.size();
            } catch (const std::exception&) {
                ok = false;
            }
        }
        if (!ok) throw InputError(fmt::format("--prior '{}': expected NAME=LO:HI, e.g. v=0.8:1", s));
        box.set(s.substr(0, eq), lo, hi);
    }
    return box;
}
struct InferCommandOptions {
    std::string datasets = "paper", flowModel;
    std::string phase = "all", out, model, dataDir, fvk = "closed", prior3b = "support", fvk3b = "all", method = "joint";
    int chains = 16, warmup = 1000, draws = 2500, thin = 4;
    double hyperSdScale = 1.0;
    int burnIn = 0;
    std::string truncation = "on", box = "on";
    std::vector<std::string> priors;
    int samples = 50000, threads = 2;
    std::uint64_t seed = 0xC0FFEE;
    bool resume = false, single = false, quiet = false;
};

/// --phase, the phases 2-3 method and its sampler and population options.
void addMethodOptions(CLI::App* cmd, InferCommandOptions& o) {
    cmd->add_option("--phase", o.phase, "phase to run: 1, 2, 3 or all (2 and 3 read the earlier phases from --out)")
        ->check(CLI::IsMember({"1", "2", "3", "all"}))
        ->capture_default_str();
    cmd->add_option("--method", o.method,
                    "phases 2-3: joint (one multi-chain MCMC over hyper-parameters and every data set's parameters, theta_new "
                    "Rao-Blackwellised over its draws; R-hat, ESS and MCSE for every statistic) or reweighting (the paper's "
                    "route: phase-1 samples re-weighted, mixtures sampled with TMCMC/BASIS); docs/BAYESIAN_INFERENCE.md")
        ->check(CLI::IsMember({"joint", "reweighting"}))
        ->capture_default_str();
    addNumber(cmd, "--chains", o.chains, "joint method: number of chains", NumberRange::closed(2, 1024))->capture_default_str();
    addNumber(cmd, "--warmup", o.warmup, "joint method: warm-up sweeps per chain (adaptation, discarded)", NumberRange::closed(50, 1e7))
        ->capture_default_str();
    addNumber(cmd, "--draws", o.draws, "joint method: kept draws per chain", NumberRange::closed(8, 1e7))->capture_default_str();
    addNumber(cmd, "--thin", o.thin, "joint method: sweeps per kept draw", NumberRange::closed(1, 1e4))->capture_default_str();
    addNumber(cmd, "--phase1-burn-in", o.burnIn,
              "unrecorded Metropolis steps per BASIS stage of the phase-1 runs (0: the paper's BASIS; more steps spread the "
              "population along correlated posteriors at proportional cost)",
              NumberRange::closed(0, 100))
        ->capture_default_str();
    addNumber(cmd, "--hyper-sd-scale", o.hyperSdScale,
              "joint method, for sensitivity studies: multiply the upper bound of every population-SD hyper-prior by this",
              NumberRange::closed(0.05, 20.0))
        ->capture_default_str();
    cmd->add_option("--population-truncation", o.truncation,
                    "joint method, for sensitivity studies: on (v truncated to [0, 1] and kb to its prior box in the population) or off")
        ->check(CLI::IsMember({"on", "off"}))
        ->capture_default_str();
    cmd->add_option("--theta-new-box", o.box,
                    "on: theta_new restricted to v >= 0.65, mu <= 20 uN/m, b2 <= 10, etam/mu <= 2 s (the paper's box); off: only "
                    "to v <= 1, the kb box and mu, b2, etam/mu >= 0")
        ->check(CLI::IsMember({"on", "off"}))
        ->capture_default_str();
}

/// Population size, seed, inputs and outputs, the FvK density and the phase-3b and prior choices.
void addRunOptions(CLI::App* cmd, InferCommandOptions& o) {
    // Below 100 samples the TMCMC stages cannot resample the population (the same floor as [inference] samples).
    // N x 5 parameters, with its likelihoods and a handful of copies per stage: 1e6 keeps a run
    // within a few hundred MB.
    addNumber(cmd, "--samples", o.samples, "population size N of every TMCMC/BASIS run (phase 1; phases 2-3 of --method reweighting; "
                                           "at most 1e6, the memory of N x 5 parameters and their copies)",
              NumberRange::closed(100, 1e6))
        ->capture_default_str();
    addNumber(cmd, "--seed", o.seed, "run seed (each run derives its own from it and its name)", NumberRange::nonNegative())
        ->capture_default_str();
    addOutOption(cmd, o.out, "output directory DIR (required unless --datasets list)", false);
    addSurrogateModelOption(cmd, o.model);
    addDataDirOption(cmd, o.dataDir);
    addThreadsOption(cmd, o.threads, "OpenMP threads (results do not depend on it)");
    cmd->add_flag("--resume", o.resume, "continue unfinished runs from their per-stage checkpoints and reuse finished ones");
    cmd->add_flag("--single-precision", o.single, "evaluate the surrogate in float (about 3x faster)");
    cmd->add_option("--fvk-density", o.fvk, "density of FvK under the population (docs/BAYESIAN_INFERENCE.md): closed (closed form, "
                                             "mixed precision, |d log q| < 1e-5), closed-double (closed form in double "
                                             "precision, about 2x slower) or nodes50 (the reference's 50-node rule)")
        ->check(CLI::IsMember({"closed", "closed-double", "nodes50"}))
        ->capture_default_str();
    cmd->add_option("--phase3b-prior", o.prior3b, "reweighting method: prior of phase 3b: support (indicator of the phase-1 support, "
                                                  "the derivation) or reference (phase-1 priors, equilibrium sigma >= 1e-4)")
        ->check(CLI::IsMember({"support", "reference"}))
        ->capture_default_str();
    cmd->add_option("--phase3b-equilibrium-fvk", o.fvk3b, "reweighting method, phase 3b equilibrium: q(FvK | psi) at every phase-2 sample "
                                                          "(all, the derivation) or at the last one only (last, the reference's defect)")
        ->check(CLI::IsMember({"all", "last"}))
        ->capture_default_str();
    cmd->add_option("--prior", o.priors,
                    "narrow the phase-1 prior box of one parameter, NAME=LO:HI in physical units (repeatable; NAME one of v, "
                    "mu_uN_per_m, kb_J, b2, etam_Pa_s_um; default and widest: the surrogates' training box v [0.65, 1], "
                    "mu [1, 10] uN/m, kb [1.074e-19, 1.074e-18] J, b2 [0, 4], etam [0.1, 1] Pa s um). Give the same "
                    "--prior to every phase");
    cmd->add_option("--datasets", o.datasets,
                    "data sets to calibrate on: paper (the single-cell sets), all (those and the shear-flow sets of "
                    "DATA_DIR/validation, seen through the flow networks; --method joint), list (print them and exit) or "
                    "comma-separated names")
        ->capture_default_str();
    cmd->add_option("--flow-model", o.flowModel,
                    "flow-network directory for the flow data sets (default: the shipped data/surrogates/flow_distilled, "
                    "one network distilled from each ensemble of data/surrogates/flow, four to six times faster); its "
                    "training.json's cross-validation (and distillation check) gives the networks' error in the likelihood");
    cmd->add_flag("--quiet", o.quiet, "no progress lines on stderr");
}

RbcInferenceOptions inferenceOptions(const InferCommandOptions& o) {
    RbcInferenceOptions opt;
    opt.outputDirectory = o.out;
    if (o.phase == "all")
        opt.firstPhase = 1, opt.lastPhase = 3;
    else
        opt.firstPhase = opt.lastPhase = std::stoi(o.phase);
    opt.populationSize = o.samples;
    opt.method = o.method == "joint" ? HierarchicalMethod::Joint : HierarchicalMethod::Reweighting;
    opt.chains = o.chains;
    opt.warmup = o.warmup;
    opt.draws = o.draws;
    opt.thin = o.thin;
    opt.phase1BurnIn = o.burnIn;
    opt.population.sdUpperScale = o.hyperSdScale;
    opt.population.truncate = o.truncation == "on";
    opt.population.newCellBox = o.box == "on";
    opt.seed = o.seed;
    setProvenanceSeed(o.seed);
    opt.resume = o.resume;
    opt.fvkRule = o.fvk == "closed"          ? FvkDensityRule::ClosedForm
                  : o.fvk == "closed-double" ? FvkDensityRule::ClosedFormDouble
                                             : FvkDensityRule::Nodes50;
    opt.phase3b.rule = opt.fvkRule;
    opt.phase3b.referencePrior = o.prior3b == "reference";
    opt.phase3b.referenceEquilibriumDefect = o.fvk3b == "last";
    return opt;
}

void printInferSummary(const InferCommandOptions& o, const RbcInferenceResult& r) {
    std::cout << fmt::format("trbc infer: phases {} in {:.1f} s with {} thread(s)\n", o.phase, r.wallSeconds, o.threads);
    for (int ph = 0; ph < 3; ++ph) {
        const RbcPhaseTiming& t = r.timing[ph];
        if (t.ran)
            std::cout << fmt::format("  phase {}: {:7.1f} s  (surrogate {:.1f} s, population sums {:.1f} s, sampler and I/O {:.1f} s)\n",
                                     ph + 1, t.wallSeconds, t.surrogateSeconds, t.populationSeconds, t.samplerSeconds());
    }
    const std::filesystem::path out(o.out);
    if (!r.stats.empty()) {
        std::cout << "theta_new: mean +- MCSE, median +- MCSE, SD +- MCSE, 5 % and 95 % quantiles:\n";
        for (const PosteriorStatsRow& s : r.stats)
            if (s.posterior == "theta_new")
                std::cout << fmt::format("  {:<16} {:.4g} +- {:.2g}  {:.4g} +- {:.2g}  {:.4g} +- {:.2g}  [{:.4g}, {:.4g}]\n", s.parameter,
                                         s.mean, s.mcseMean, s.median, s.mcseMedian, s.sd, s.mcseSd, s.q05, s.q95);
        std::cout << fmt::format("statistics: {}\ntable: {}\n", (out / "posterior_stats.csv").string(), (out / "posterior_table.md").string());
    }
    std::cout << fmt::format("provenance: {}\n", (out / "infer.json").string());
}

void runInfer(const InferCommandOptions& o) {
    RbcInferenceOptions opt = inferenceOptions(o);
    const RbcPriorBox box = parsePriorBox(o.priors);
    const DataSetChoice choice = DataSetChoice::parse(o.datasets);
    // Every input is read and checked before anything is written to --out.
    const std::filesystem::path modelDir = surrogateModelDirectory(o.model);
    auto surrogate = std::make_shared<Surrogate>(Surrogate::load(modelDir));
    surrogate->precision = o.single ? Precision::Single : Precision::Double;
    const std::filesystem::path dataDir = experimentDirectory(o.dataDir);
    const std::vector<RbcDataSet> singleCell = loadRbcDataSets(dataDir);
    const std::filesystem::path flowDir = o.flowModel.empty() ? defaultSurrogateDirectory() / "flow_distilled" : std::filesystem::path(o.flowModel);
    std::vector<RbcDataSet> flow;
    if (choice.mayChooseFlow(singleCell)) {
        try {
            for (FlowDataSet& f : flowDataSets(dataDir / "validation", flowNetworkErrors(flowDir))) flow.push_back(flowRbcDataSet(std::move(f)));
        } catch (const InputError& e) {
            throw InputError(fmt::format("--datasets {}: the flow data sets need DATA_DIR/validation (--data-dir) and the flow "
                                         "networks (--flow-model): {}", o.datasets, e.what()));
        }
    }
    const bool listOnly = choice.kind == DataSetChoice::Kind::List;
    if (!listOnly && o.out.empty()) throw InputError("infer: --out is required");
    if (listOnly) {
        for (const RbcDataSet& d : singleCell) std::cout << dataSetSummary(d) << '\n';
        for (const RbcDataSet& d : flow) std::cout << dataSetSummary(d) << '\n';
        return;
    }
    std::vector<RbcDataSet> data = selectDataSets(choice, singleCell, flow);
    for (RbcDataSet& d : data) d.prior = box;
    const bool anyFlow = std::any_of(data.begin(), data.end(), [](const RbcDataSet& d) { return d.experiment == RbcExperiment::Flow; });
    std::shared_ptr<const FlowSurrogate> flowNetworks;
    if (anyFlow) flowNetworks = std::make_shared<const FlowSurrogate>(FlowSurrogate::load(flowDir));
    RbcModel model = surrogateRbcModel(surrogate);
    if (flowNetworks) model.flow = surrogateFlowModel(flowNetworks);
    validateRbcInference(model, data, opt);
    const OutputDirectory outDir(o.out, "infer", "--out", {"infer.json", kPhase1PriorBoxFile});
    ensureWritableDirectory(o.out);
    const nlohmann::json boxJson = priorBoxJson(box);
    nlohmann::json phase1Record = boxJson;
    if (anyFlow) phase1Record["flow_model"] = FlowSurrogate::fingerprint(flowDir);
    checkPhase1Record(o.out, phase1Record, o.resume || opt.firstPhase > 1, opt.firstPhase == 1);
    opt.provenance = {{"command", commandLine()},
                      {"model", {{"dir", std::filesystem::absolute(modelDir).lexically_normal().string()},
                                 {"precision", o.single ? "single" : "double"},
                                 {"networks", surrogateNetworksJson(*surrogate)}}},
                      {"data_dir", std::filesystem::absolute(dataDir).lexically_normal().string()},
                      {"phase1_prior_box", boxJson},
                      {"datasets", o.datasets}};
    if (anyFlow)
        opt.provenance["flow_model"] = {{"dir", std::filesystem::absolute(flowDir).lexically_normal().string()},
                                        {"fingerprint", phase1Record["flow_model"]}};
    if (!o.quiet) opt.progress = [](const std::string& line) { std::cerr << line << '\n'; };
    omp_set_num_threads(o.threads);
    printInferSummary(o, runRbcInference(model, data, opt));
}

}  // namespace

void registerInfer(CLI::App& app) {
    auto o = std::make_shared<InferCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "infer", "Hierarchical Bayesian inference of (v, mu, kb, b2, etam) from the paper's seven data sets (and, with --datasets, the "
                 "shear-flow sets) on the surrogates "
                 "(docs/BAYESIAN_INFERENCE.md): phase 1 each data set's posterior (TMCMC/BASIS), phases 2-3 the population "
                 "hyper-parameters, each data set given all data and theta_new (a new cell), by default from one joint "
                 "multi-chain MCMC; writes DIR/posterior_stats.csv (with MCSE, R-hat and ESS), DIR/posterior_table.md, "
                 "DIR/infer.json and the samples of every posterior");
    addMethodOptions(cmd, *o);
    addRunOptions(cmd, *o);
    cmd->callback([o]() { runInfer(*o); });
}

}  // namespace trbc::cli
