// The run of `trbc infer` (runRbcInference, rbc_pipeline.hpp): option checks, phase 1, phases 2-3
// by the joint MCMC or by re-weighting, the timing of each phase, and the statistics rows of a
// posterior. The files are written and read by posterior_store.hpp, the Markdown table is made by
// posterior_tables.hpp.
#include "inference/rbc_pipeline.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "core/clock.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "inference/mcmc_diagnostics.hpp"
#include "inference/posterior_store.hpp"
#include "inference/posterior_tables.hpp"
#include "inference/rbc_hierarchical.hpp"

namespace trbc {
namespace fs = std::filesystem;
using namespace detail;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

struct Context {
    const RbcInferenceOptions& o;
    RbcModel model;  // timed
    std::shared_ptr<ModelTimer> modelTimer;
    std::shared_ptr<PopulationTimer> populationTimer;
    nlohmann::json runs = nlohmann::json::object();
    nlohmann::json extrapolation = nlohmann::json::object();

    void say(const std::string& line) const {
        if (o.progress) o.progress(line);
    }
    fs::path runDirectory(const Posterior& p) const { return o.outputDirectory / p.phase / p.name; }

    TmcmcOptions runOptions(const Posterior& p, RbcSamplerSettings st) const {
        TmcmcOptions opt;
        opt.populationSize = st.populationCap > 0 ? std::min(o.populationSize, st.populationCap) : o.populationSize;
        opt.targetCoV = st.targetCoV;
        opt.covarianceScaling = st.covarianceScaling;
        opt.maxChainLength = 1;  // BASIS
        if (p.phase == "phase1" && o.phase1BurnIn > 0) opt.burnIn = {o.phase1BurnIn};
        opt.seed = rbcRunSeed(o.seed, p.label());
        opt.checkpointDirectory = (runDirectory(p) / "checkpoint").string();
        return opt;
    }
};

/// Runs (or, with resume, continues / reuses) one TMCMC run and writes samples.csv, stages.csv and run.json.
/// `mapLogPrior` (optional) gives the log prior density stored with the samples for the MAP (section
/// 7) when it is not the sampler's prior (phase 3b).
TmcmcResult runPosterior(Context& ctx, const Posterior& p, const TmcmcProblem& problem, RbcSamplerSettings st,
                         const std::function<Eigen::VectorXd(const TmcmcResult&)>& mapLogPrior = {}) {
    const fs::path dir = ctx.runDirectory(p);
    fs::create_directories(dir);
    TmcmcOptions opt = ctx.runOptions(p, st);
    opt.resume = ctx.o.resume;
    if (!ctx.o.resume) fs::remove_all(opt.checkpointDirectory);
    int stagesRun = 0;
    const std::string label = p.label();
    opt.onStage = [&](const TmcmcStageInfo& g) {
        ++stagesRun;
        ctx.say(fmt::format("infer {}: stage {:>2}  rho {:.3e}  CoV {:.2f}  accept {:.2f}  unique {:>6}  max log L {:.5g}  {:.1f} s",
                            label, g.stage, g.exponent, g.coefficientOfVariation, g.acceptanceRate, g.uniqueSelections,
                            g.maxLogLikelihood, g.elapsedSeconds));
    };
    const double s0 = ctx.modelTimer->seconds, p0 = ctx.populationTimer->seconds;
    const auto t0 = SteadyClock::now();
    TmcmcResult r = runTmcmc(problem, opt);
    RunTiming t{secondsSince(t0), ctx.modelTimer->seconds - s0, ctx.populationTimer->seconds - p0};
    if (stagesRun == 0)  // a finished run was only loaded: keep its timing
        if (const std::optional<RunTiming> recorded = recordedTiming(dir / "run.json")) t = *recorded;
    ctx.runs[label] = writeTmcmcRun(dir, p, opt, r, t, mapLogPrior ? mapLogPrior(r) : r.logPrior);
    ctx.say(fmt::format("infer {}: done, {} stages, log evidence {:.4f}, {} likelihood evaluations, {:.1f} s{}", label,
                        r.stages.size(), r.logEvidence, r.likelihoodEvaluations, t.wall, stagesRun == 0 ? " (reused)" : ""));
    return r;
}

/// Loads a finished run of an earlier invocation (phases not selected now).
TmcmcResult loadPosterior(Context& ctx, const Posterior& p, const TmcmcProblem& problem, RbcSamplerSettings st, int phase) {
    TmcmcOptions opt = ctx.runOptions(p, st);
    requireFinishedRun(opt.checkpointDirectory, ctx.o.outputDirectory, p.label(), phase);
    opt.resume = true;
    try {
        TmcmcResult r = runTmcmc(problem, opt);
        ctx.say(fmt::format("infer {}: loaded ({} samples, log evidence {:.4f})", p.label(), r.samples.cols(), r.logEvidence));
        return r;
    } catch (const InputError& e) {
        throw InputError(fmt::format("loading {} (it must have been run with the same --samples and --seed): {}", p.label(), e.what()));
    }
}

/// Problem stand-in for loading a finished run: the likelihood is never called.
TmcmcProblem loadOnlyProblem(PriorPtr prior) {
    TmcmcProblem p;
    p.prior = std::move(prior);
    p.batchLogLikelihood = [](const Eigen::MatrixXd&) -> Eigen::VectorXd {
        throw InputError("internal: a finished run was about to be continued");
    };
    return p;
}

Posterior phase1Posterior(const RbcDataSet& d, const std::string& phase) {
    // A flow set's variables are the pooled ones in their order: its eta_m = mu r is derived as theta_new's.
    return {phase, d.name, phase1OutputNames(d), phase1OutputScale(d.experiment), d.experiment == RbcExperiment::Flow};
}

double massOutside(const Eigen::VectorXd& r, double lo, double hi) {
    double n = 0.0;
    for (Eigen::Index k = 0; k < r.size(); ++k) n += (r[k] < lo || r[k] > hi) ? 1.0 : 0.0;
    return n / static_cast<double>(std::max<Eigen::Index>(r.size(), 1));
}

std::vector<PosteriorStatsRow> statsOf(const Posterior& p, const TmcmcResult& r, const Eigen::VectorXd& mapLogPrior) {
    std::vector<std::string> names;
    const Eigen::MatrixXd phys = physicalSamples(p, r.samples, names);
    return posteriorStatsRows(p.name, phys, names, r.logLikelihood, mapLogPrior);
}

/// Phase-1 prior log density of each sample (the MAP of 3b uses the phase-1 priors).
Eigen::VectorXd phase1LogPrior(const RbcDataSet& d, const Eigen::MatrixXd& samples) {
    const auto prior = phase1Prior(d);
    Eigen::VectorXd lp(samples.cols());
    for (Eigen::Index k = 0; k < samples.cols(); ++k) lp[k] = prior->logDensity(samples.col(k));
    return lp;
}

/// Removes the final statistics before phase 3 rewrites its samples: a run stopped inside phase 3
/// must not leave statistics of the earlier samples beside the new ones (the calibrated cell reads
/// posterior_stats.csv before samples.csv).
void discardFinalStatistics(const Context& ctx) {
    fs::remove(ctx.o.outputDirectory / "posterior_stats.csv");
    fs::remove(ctx.o.outputDirectory / "posterior_table.md");
}

/// DIR/posterior_stats.csv and DIR/posterior_table.md of the final posteriors (after phase 3).
void writeFinalStatistics(const Context& ctx, const std::vector<PosteriorStatsRow>& rows, const std::vector<RbcDataSet>& data,
                          const nlohmann::json& check) {
    writePosteriorStats(ctx.o.outputDirectory / "posterior_stats.csv", rows);
    writeFileAtomically(ctx.o.outputDirectory / "posterior_table.md", posteriorTableMarkdown(ctx.o, rows, data, ctx.extrapolation, check));
}

// ------------------------------------------------------------------------------------------------
// Phase timing

/// The clocks at the start of a phase.
struct PhaseStart {
    SteadyClock::time_point time;
    double surrogateSeconds;
    long long surrogateEvaluations;
    double populationSeconds;
    long long populationTerms;
};

PhaseStart phaseStart(const Context& ctx) {
    return {SteadyClock::now(), ctx.modelTimer->seconds, ctx.modelTimer->evaluations, ctx.populationTimer->seconds,
            ctx.populationTimer->terms};
}

/// Records the phase's timing in res.timing (and reports it).
void phaseEnd(const Context& ctx, RbcInferenceResult& res, int phase, const PhaseStart& begin) {
    RbcPhaseTiming& t = res.timing[phase - 1];
    t.ran = true;
    t.wallSeconds = secondsSince(begin.time);
    t.surrogateSeconds = ctx.modelTimer->seconds - begin.surrogateSeconds;
    t.surrogateEvaluations = ctx.modelTimer->evaluations - begin.surrogateEvaluations;
    t.populationSeconds = ctx.populationTimer->seconds - begin.populationSeconds;
    t.populationTerms = ctx.populationTimer->terms - begin.populationTerms;
    ctx.say(fmt::format("infer phase {}: {:.1f} s (surrogate {:.1f} s, population sums {:.1f} s, sampler and I/O {:.1f} s)",
                        phase, t.wallSeconds, t.surrogateSeconds, t.populationSeconds, t.samplerSeconds()));
}

// ------------------------------------------------------------------------------------------------
// Options and phase 1

HierarchicalMcmcOptions jointOptions(const RbcInferenceOptions& o) {
    HierarchicalMcmcOptions mo;
    mo.chains = o.chains;
    mo.warmup = o.warmup;
    mo.draws = o.draws;
    mo.thin = o.thin;
    return mo;
}


/// Phase 1: every data set's own posterior, run, or loaded when the run starts at a later phase.
void runPhase1(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res) {
    const RbcInferenceOptions& o = ctx.o;
    std::vector<PosteriorStatsRow> rows1;
    const bool run = o.firstPhase <= 1;
    const PhaseStart begin = phaseStart(ctx);
    for (const RbcDataSet& d : data) {
        const Posterior p = phase1Posterior(d, "phase1");
        const RbcSamplerSettings st = rbcSamplerSettings(RbcRun::Phase1, d.experiment);
        TmcmcResult r = run ? runPosterior(ctx, p, phase1Problem(ctx.model, d), st)
                            : loadPosterior(ctx, p, loadOnlyProblem(phase1Prior(d)), st, 1);
        if (run) {
            auto rows = statsOf(p, r, r.logPrior);
            rows1.insert(rows1.end(), rows.begin(), rows.end());
            if (d.experiment == RbcExperiment::Relaxation)
                ctx.extrapolation[p.label()] = massOutside(r.samples.row(0).transpose(), kRelaxationRLow, kRelaxationRHigh);
        }
        res.phase1.push_back(std::move(r));
    }
    if (run) {
        writePosteriorStats(o.outputDirectory / "phase1" / "posterior_stats.csv", rows1);
        phaseEnd(ctx, res, 1, begin);
    }
}

// ------------------------------------------------------------------------------------------------
// The re-weighting method (the paper's phases 2 and 3)

/// Phase 2: hyper-parameters by re-weighting the phase-1 samples. Returns those samples as the
/// re-weighting sees them, which phase 3b re-weights again.
std::vector<ReweightingSamples> runReweightingPhase2(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res) {
    const RbcInferenceOptions& o = ctx.o;
    std::vector<ReweightingSamples> sets;
    for (std::size_t i = 0; i < data.size(); ++i) {
        sets.push_back(reweightingSamples(data[i], res.phase1[i].samples));
        ctx.say(fmt::format("infer phase2: {} enters with {} distinct of {} phase-1 samples", data[i].name, sets.back().x.cols(),
                            sets.back().total));
    }
    const Posterior p{"phase2", "hyper", hyperOutputNames(), hyperOutputScale(), false};
    const RbcSamplerSettings st = rbcSamplerSettings(RbcRun::Phase2);
    const bool run = o.firstPhase <= 2;
    const PhaseStart begin = phaseStart(ctx);
    res.phase2 = run ? runPosterior(ctx, p, phase2Problem(sets, o.fvkRule, ctx.populationTimer), st)
                     : loadPosterior(ctx, p, loadOnlyProblem(hyperPrior()), st, 2);
    if (run) {
        writePosteriorStats(o.outputDirectory / "phase2" / "posterior_stats.csv", statsOf(p, res.phase2, res.phase2.logPrior));
        phaseEnd(ctx, res, 2, begin);
    }
    return sets;
}

/// Phase 3a: theta_new by TMCMC over the mixture of the phase-2 population, and the ancestral
/// cross-check (returned in `check`). Returns its statistics rows.
std::vector<PosteriorStatsRow> runReweightingPhase3a(Context& ctx, RbcInferenceResult& res, nlohmann::json& check) {
    const RbcInferenceOptions& o = ctx.o;
    const Eigen::MatrixXd& psi = res.phase2.samples;
    const Posterior pNew{"phase3", "theta_new", pooledOutputNames(), pooledOutputScale(), true};
    res.phase3a = runPosterior(ctx, pNew, phase3aProblem(psi, ctx.populationTimer), rbcSamplerSettings(RbcRun::Phase3a));
    std::vector<PosteriorStatsRow> rows = statsOf(pNew, res.phase3a, res.phase3a.logPrior);
    // Mean, SD and quantiles Rao-Blackwellised over the phase-2 population (no phase-3a sampling noise).
    for (const NewCellStatistic& st : newCellStatistics({psi}, o.population))
        for (PosteriorStatsRow& r : rows)
            if (r.parameter == st.name) {
                r.mean = st.mean.value, r.median = st.median.value, r.sd = st.sd.value, r.q05 = st.q05.value, r.q95 = st.q95.value;
                r.mcseMean = st.mean.mcse, r.mcseMedian = st.median.mcse, r.mcseSd = st.sd.mcse;
                r.mcseQ05 = st.q05.mcse, r.mcseQ95 = st.q95.mcse;
            }
    ctx.extrapolation[pNew.label()] = massOutside(res.phase3a.samples.row(kPooledR).transpose(), kRelaxationRLow, kRelaxationRHigh);
    res.ancestral = sampleNewCellAncestral(psi, o.populationSize, rbcRunSeed(o.seed, "phase3/theta_new_ancestral"));
    check = ancestralCheck(res.phase3a.samples, res.ancestral, ctx.runDirectory(pNew) / "ancestral_check.csv");
    ctx.say(fmt::format("infer phase3/theta_new: ancestral cross-check, largest mean difference {:.3f} SD",
                        check["max_mean_difference_in_sd"].get<double>()));
    return rows;
}

/// Phase 3b: each data set given all data, its phase-1 samples re-weighted by every phase-2 sample.
/// Appends the statistics rows to `rows`.
void runReweightingPhase3b(Context& ctx, const std::vector<RbcDataSet>& data, const std::vector<ReweightingSamples>& sets,
                           RbcInferenceResult& res, std::vector<PosteriorStatsRow>& rows) {
    const RbcInferenceOptions& o = ctx.o;
    const Eigen::MatrixXd& psi = res.phase2.samples;
    const DistinctColumns distinctPsi = distinctColumns(psi);
    for (std::size_t i = 0; i < data.size(); ++i) {
        const RbcDataSet& d = data[i];
        // log b_i(psi_m), once per distinct psi_m (4.6: M x N_i density terms)
        const Eigen::VectorXd logBu = logReweightingFactors(sets[i], distinctPsi.columns, o.fvkRule, ctx.populationTimer.get());
        Eigen::VectorXd logB(psi.cols());
        for (Eigen::Index m = 0; m < psi.cols(); ++m) logB[m] = logBu[distinctPsi.index[static_cast<std::size_t>(m)]];
        const Posterior p3 = phase1Posterior(d, "phase3");
        const TmcmcProblem problem = phase3bProblem(ctx.model, d, psi, logB, o.phase3b, ctx.populationTimer);
        // The MAP uses the phase-1 priors, whatever the sampler's prior.
        auto mapPrior = [&d](const TmcmcResult& r) { return phase1LogPrior(d, r.samples); };
        TmcmcResult r = runPosterior(ctx, p3, problem, rbcSamplerSettings(RbcRun::Phase3b, d.experiment), mapPrior);
        auto rr = statsOf(p3, r, mapPrior(r));
        rows.insert(rows.end(), rr.begin(), rr.end());
        if (d.experiment == RbcExperiment::Relaxation)
            ctx.extrapolation[p3.label()] = massOutside(r.samples.row(0).transpose(), kRelaxationRLow, kRelaxationRHigh);
        res.phase3b.push_back(std::move(r));
    }
}

/// Phase 3: theta_new and each data set given all data.
void runReweightingPhase3(Context& ctx, const std::vector<RbcDataSet>& data, const std::vector<ReweightingSamples>& sets,
                          RbcInferenceResult& res) {
    const PhaseStart begin3 = phaseStart(ctx);
    nlohmann::json check;
    discardFinalStatistics(ctx);
    std::vector<PosteriorStatsRow> rows = runReweightingPhase3a(ctx, res, check);
    runReweightingPhase3b(ctx, data, sets, res, rows);
    writeFinalStatistics(ctx, rows, data, check);
    res.stats = rows;
    phaseEnd(ctx, res, 3, begin3);

    nlohmann::json& ci = ctx.runs["phase3/theta_new"];
    ci["ancestral_check"] = check;
}

// ------------------------------------------------------------------------------------------------
// The joint method (phases 2 and 3 from one multi-chain MCMC run)

Eigen::MatrixXd concatenate(const std::vector<Eigen::MatrixXd>& blocks) {
    Eigen::Index cols = 0;
    for (const auto& b : blocks) cols += b.cols();
    Eigen::MatrixXd x(blocks.empty() ? 0 : blocks[0].rows(), cols);
    Eigen::Index k = 0;
    for (const auto& b : blocks) {
        x.middleCols(k, b.cols()) = b;
        k += b.cols();
    }
    return x;
}

/// Writes a posterior given by draws (inference units) and returns its statistics rows.
std::vector<PosteriorStatsRow> writeJointPosterior(Context& ctx, const Posterior& p, const Eigen::MatrixXd& samples,
                                                   const Eigen::VectorXd& ll, const Eigen::VectorXd& lp, int chains,
                                                   const nlohmann::json& info) {
    const fs::path dir = ctx.runDirectory(p);
    fs::create_directories(dir);
    fs::remove_all(dir / "checkpoint");  // a BASIS run of the other method must not be taken for this one
    std::vector<std::string> names;
    const Eigen::MatrixXd phys = physicalSamples(p, samples, names);
    ctx.runs[p.label()] = writeChainRun(dir, p, phys, names, ll, lp, chains, info);
    return posteriorStatsRows(p.name, phys, names, ll, lp, chains);
}

/// The settings the joint draws are made with: draws saved with other settings are not reused.
/// The data sets (names and content fingerprints) are part of them: draws of other groups are never
/// taken for these.
nlohmann::json jointSettings(const RbcInferenceOptions& o, const std::vector<RbcDataSet>& data, std::uint64_t seed) {
    nlohmann::json sets = nlohmann::json::array();
    for (const RbcDataSet& d : data) sets.push_back({d.name, d.contentHash});
    nlohmann::json s = {{"method", "joint MCMC"}, {"chains", o.chains}, {"warmup", o.warmup}, {"draws", o.draws}, {"thin", o.thin},
                        {"seed", seed}, {"phase1_samples", o.populationSize}, {"phase1_burn_in", o.phase1BurnIn},
                        {"hyper_sd_scale", o.population.sdUpperScale}, {"population_truncation", o.population.truncate},
                        {"data_sets", sets}};
    // The networks' content, not where they lie: a moved copy gives the same draws.
    if (o.provenance.contains("flow_model")) s["flow_model"] = o.provenance["flow_model"].value("fingerprint", nlohmann::json());
    return s;
}

/// The joint draws in res.joint: run (or, with resume, reused) when phase 2 runs now, else loaded.
void obtainJointDraws(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res, const fs::path& jointDir,
                      const nlohmann::json& settings, std::uint64_t seed, bool run) {
    const RbcInferenceOptions& o = ctx.o;
    if (run && !(o.resume && loadJointDraws(jointDir, settings, res.joint))) {
        std::vector<Eigen::MatrixXd> starts;
        for (const TmcmcResult& r : res.phase1) starts.push_back(r.samples);
        HierarchicalMcmcOptions mo = jointOptions(o);
        mo.seed = seed;
        mo.progress = [&ctx](const std::string& line) { ctx.say("infer phase2/joint: " + line); };
        res.joint = runHierarchicalMcmc(rbcHierarchicalModel(ctx.model, data, starts, rbcRunSeed(o.seed, "phase2/joint_start"), o.population), mo);
        saveJointDraws(jointDir, settings, res.joint);
    } else if (!run && !loadJointDraws(jointDir, settings, res.joint)) {
        throw InputError(fmt::format("{}: no joint-MCMC draws made with these settings ({}); run `trbc infer --phase 2` with this --out first",
                                     o.outputDirectory.string(), (jointDir / "draws.json").string()));
    }
}

/// Phase 2: the joint draws, and the hyper-parameter posterior from them (res.phase2).
void runJointPhase2(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res) {
    const RbcInferenceOptions& o = ctx.o;
    const fs::path jointDir = o.outputDirectory / "phase2" / "joint";
    const std::uint64_t seed = rbcRunSeed(o.seed, "phase2/joint");
    const nlohmann::json settings = jointSettings(o, data, seed);
    const PhaseStart begin = phaseStart(ctx);
    const bool run = o.firstPhase <= 2;
    obtainJointDraws(ctx, data, res, jointDir, settings, seed, run);
    const HierarchicalMcmcResult& J = res.joint;
    const int C = static_cast<int>(J.hyper.size());
    Eigen::VectorXd llSum = Eigen::VectorXd::Zero(C * o.draws);
    for (const auto& g : J.logLikelihood) llSum += pooledDraws(g);
    const Posterior p{"phase2", "hyper", hyperOutputNames(), hyperOutputScale(), false};
    const Eigen::MatrixXd psi = concatenate(J.hyper);
    const auto hp = hyperPrior();
    Eigen::VectorXd lp(psi.cols());
    for (Eigen::Index k = 0; k < psi.cols(); ++k) lp[k] = hp->logDensity(psi.col(k));
    nlohmann::json info = settings;
    info["acceptance"] = {{"groups", J.groupAcceptance}, {"hyper", J.hyperAcceptance}, {"shift", J.shiftAcceptance}, {"scale", J.scaleAcceptance}};
    info["likelihood_evaluations"] = J.likelihoodEvaluations;
    info["wall_s"] = J.wallSeconds;
    info["log_likelihood_column"] = "sum of the data sets' log-likelihoods at the draw";
    const auto rows = writeJointPosterior(ctx, p, psi, llSum, lp, C, info);
    writePosteriorStats(o.outputDirectory / "phase2" / "posterior_stats.csv", rows);
    res.phase2 = TmcmcResult{};
    res.phase2.samples = psi;
    res.phase2.logLikelihood = llSum;
    res.phase2.logPrior = lp;
    res.phase2.exponent = 1.0;
    res.phase2.completed = true;
    res.phase2.likelihoodEvaluations = J.likelihoodEvaluations;
    ctx.say(fmt::format("infer phase2/joint: {} chains x {} draws, {} likelihood evaluations, {:.1f} s", C, o.draws,
                        J.likelihoodEvaluations, J.wallSeconds));
    if (run) phaseEnd(ctx, res, 2, begin);
}

/// Phase 3a: theta_new with Rao-Blackwellised statistics; draws of the restricted mixture for the
/// sample file. Returns its statistics rows.
std::vector<PosteriorStatsRow> runJointPhase3a(Context& ctx, RbcInferenceResult& res, const Eigen::MatrixXd& psi) {
    const RbcInferenceOptions& o = ctx.o;
    const HierarchicalMcmcResult& J = res.joint;
    const Posterior pNew{"phase3", "theta_new", pooledOutputNames(), pooledOutputScale(), true};
    const std::vector<NewCellStatistic> nc = newCellStatistics(J.hyper, o.population);
    res.ancestral = sampleNewCellAncestral(psi, psi.cols(), rbcRunSeed(o.seed, "phase3/theta_new_ancestral"));
    // The mixture density at the draws (for the ML column) with every k-th psi draw, <= 4000 components.
    const Eigen::Index thin = std::max<Eigen::Index>(1, psi.cols() / 4000);
    Eigen::MatrixXd psiThin(psi.rows(), psi.cols() / thin);
    for (Eigen::Index k = 0; k < psiThin.cols(); ++k) psiThin.col(k) = psi.col(k * thin);
    const PopulationMixture mixture(PopulationMixture::Layout::NewCell, psiThin);
    res.phase3a = TmcmcResult{};
    res.phase3a.samples = res.ancestral;
    res.phase3a.logLikelihood = mixture.logMean(res.ancestral, ctx.populationTimer.get());
    res.phase3a.logPrior = Eigen::VectorXd(res.ancestral.cols());
    const auto box = newCellBoxPrior();
    for (Eigen::Index k = 0; k < res.ancestral.cols(); ++k) res.phase3a.logPrior[k] = box->logDensity(res.ancestral.col(k));
    res.phase3a.exponent = 1.0;
    res.phase3a.completed = true;
    nlohmann::json info = {{"method", "Rao-Blackwellised over the joint-MCMC hyper-parameter draws"},
                           {"samples", "one draw of the box-restricted population mixture per hyper-parameter draw"},
                           {"log_likelihood_column", fmt::format("log of the mixture density over every {}-th hyper-parameter draw", thin)}};
    const auto drawRows = writeJointPosterior(ctx, pNew, res.ancestral, res.phase3a.logLikelihood, res.phase3a.logPrior, 1, info);
    std::vector<PosteriorStatsRow> rows;
    for (const NewCellStatistic& s : nc) {
        PosteriorStatsRow r{"theta_new", s.name, s.mean.value, s.median.value, 0.0, 0.0, s.sd.value, s.q05.value, s.q95.value};
        for (const PosteriorStatsRow& d : drawRows)
            if (d.parameter == s.name) r.ml = d.ml, r.map = d.map;
        r.mcseMean = s.mean.mcse, r.mcseMedian = s.median.mcse, r.mcseSd = s.sd.mcse, r.mcseQ05 = s.q05.mcse, r.mcseQ95 = s.q95.mcse;
        r.rhat = s.rhat, r.essBulk = s.essBulk, r.essTail = s.essTail;
        rows.push_back(r);
    }
    ctx.extrapolation[pNew.label()] = massOutside(res.ancestral.row(kPooledR).transpose(), kRelaxationRLow, kRelaxationRHigh);
    return rows;
}

/// Phase 3b: each data set given all data, its block of the joint draws. Appends the statistics
/// rows to `rows`.
void runJointPhase3b(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res, std::vector<PosteriorStatsRow>& rows) {
    const HierarchicalMcmcResult& J = res.joint;
    const int C = static_cast<int>(J.hyper.size());
    res.phase3b.clear();
    for (std::size_t i = 0; i < data.size(); ++i) {
        const RbcDataSet& d = data[i];
        std::vector<Eigen::MatrixXd> blocks;
        for (const auto& g : J.group[i]) blocks.push_back(rbcGroupToPhase1(d.experiment, g));
        TmcmcResult r;
        r.samples = concatenate(blocks);
        r.logLikelihood = pooledDraws(J.logLikelihood[i]);
        r.logPrior = phase1LogPrior(d, r.samples);
        r.exponent = 1.0;
        r.completed = true;
        const Posterior p3 = phase1Posterior(d, "phase3");
        const auto rr = writeJointPosterior(ctx, p3, r.samples, r.logLikelihood, r.logPrior, C,
                                            {{"method", "joint MCMC (this data set's block of the joint draws)"}});
        rows.insert(rows.end(), rr.begin(), rr.end());
        if (d.experiment == RbcExperiment::Relaxation)
            ctx.extrapolation[p3.label()] = massOutside(r.samples.row(0).transpose(), kRelaxationRLow, kRelaxationRHigh);
        res.phase3b.push_back(std::move(r));
    }
}

/// Phase 3 of the joint method, with the worst chain diagnostics over all its rows in run.json of theta_new.
void runJointPhase3(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res) {
    const PhaseStart begin3 = phaseStart(ctx);
    discardFinalStatistics(ctx);
    const Eigen::MatrixXd psi = concatenate(res.joint.hyper);
    std::vector<PosteriorStatsRow> rows = runJointPhase3a(ctx, res, psi);
    runJointPhase3b(ctx, data, res, rows);
    writeFinalStatistics(ctx, rows, data, nlohmann::json());
    res.stats = rows;
    double worstRhat = 0.0, leastBulk = kInf, leastTail = kInf;
    for (const PosteriorStatsRow& r : rows) {
        if (std::isnan(r.rhat)) continue;
        worstRhat = std::max(worstRhat, r.rhat), leastBulk = std::min(leastBulk, r.essBulk), leastTail = std::min(leastTail, r.essTail);
    }
    ctx.runs["phase3/theta_new"]["diagnostics"] = {{"max_rhat", worstRhat}, {"min_ess_bulk", leastBulk}, {"min_ess_tail", leastTail}};
    ctx.say(fmt::format("infer phase3: largest R-hat {:.4f}, smallest bulk ESS {:.0f}, smallest tail ESS {:.0f} (theta_new and every data set)",
                        worstRhat, leastBulk, leastTail));
    phaseEnd(ctx, res, 3, begin3);
}

}  // namespace

// ------------------------------------------------------------------------------------------------

std::uint64_t rbcRunSeed(std::uint64_t seed, const std::string& runName) { return splitmix64(seed ^ fnv1a(runName)); }

std::vector<PosteriorStatsRow> posteriorStatsRows(const std::string& posterior, const Eigen::MatrixXd& samples,
                                                  const std::vector<std::string>& names, const Eigen::VectorXd& logLikelihood,
                                                  const Eigen::VectorXd& logPrior, int chains) {
    const PosteriorSummary s = posteriorStatistics(samples, logLikelihood, logPrior, names);
    std::vector<PosteriorStatsRow> rows;
    const Eigen::Index T = chains > 0 ? samples.cols() / chains : 0;
    for (std::size_t k = 0; k < s.parameters.size(); ++k) {
        const ParameterSummary& p = s.parameters[k];
        PosteriorStatsRow r{posterior, p.name, p.mean, p.median, p.ml, p.map, p.sd, p.q05, p.q95};
        if (T >= 4 && T * chains == samples.cols()) {
            Chains c;
            for (int j = 0; j < chains; ++j) c.push_back(samples.row(static_cast<Eigen::Index>(k)).segment(j * T, T).transpose());
            r.mcseMean = chainMean(c).mcse;
            r.mcseSd = chainSd(c).mcse;
            r.mcseMedian = chainQuantile(c, 0.5).mcse;
            r.mcseQ05 = chainQuantile(c, 0.05).mcse;
            r.mcseQ95 = chainQuantile(c, 0.95).mcse;
            if (chains >= 2) {
                const ChainDiagnostics d = chainDiagnostics(c);
                r.rhat = d.rhat, r.essBulk = d.essBulk, r.essTail = d.essTail;
            }
        }
        rows.push_back(r);
    }
    return rows;
}

void validateRbcInference(const RbcModel& model, const std::vector<RbcDataSet>& data, const RbcInferenceOptions& o) {
    if (o.firstPhase < 1 || o.lastPhase > 3 || o.firstPhase > o.lastPhase)
        throw InputError(fmt::format("infer: phases {}..{} are invalid: the phases are 1, 2, 3", o.firstPhase, o.lastPhase));
    if (o.method == HierarchicalMethod::Reweighting && (o.population.sdUpperScale != 1.0 || !o.population.truncate))
        throw InputError("infer: --hyper-sd-scale and --population-truncation off need --method joint (the re-weighting route's population is fixed)");
    if (o.method == HierarchicalMethod::Joint) validateHierarchicalMcmcOptions(jointOptions(o));  // before phase 1 runs
    if (o.populationSize < 2) throw InputError(fmt::format("infer: --samples = {} is invalid: must be >= 2", o.populationSize));
    if (data.empty()) throw InputError("infer: no data sets");
    if (o.method == HierarchicalMethod::Reweighting)
        for (const RbcDataSet& d : data)
            if (d.experiment == RbcExperiment::Flow)
                throw InputError(fmt::format("infer: data set {} is a flow data set, which only --method joint takes", d.name));
    if (o.outputDirectory.empty()) throw InputError("infer: no output directory");
    for (const RbcDataSet& d : data)
        if (d.experiment == RbcExperiment::Flow && (!d.flow || !model.flow.tankTreading || !model.flow.criticalStressPa))
            throw InputError(fmt::format("infer: flow data set {} needs {}", d.name, d.flow ? "the flow networks in the model" : "its observations"));
}

RbcInferenceResult runRbcInference(const RbcModel& model, const std::vector<RbcDataSet>& data, const RbcInferenceOptions& o) {
    validateRbcInference(model, data, o);
    fs::create_directories(o.outputDirectory);

    const auto tStart = SteadyClock::now();
    Context ctx{o, {}, std::make_shared<ModelTimer>(), std::make_shared<PopulationTimer>()};
    ctx.model = timedModel(model, ctx.modelTimer);
    RbcInferenceResult res;
    runPhase1(ctx, data, res);
    if (o.lastPhase >= 2 && o.method == HierarchicalMethod::Joint) {
        runJointPhase2(ctx, data, res);
        if (o.lastPhase >= 3) runJointPhase3(ctx, data, res);
    } else if (o.lastPhase >= 2) {
        const std::vector<ReweightingSamples> sets = runReweightingPhase2(ctx, data, res);
        if (o.lastPhase >= 3) runReweightingPhase3(ctx, data, sets, res);
    }
    res.wallSeconds = secondsSince(tStart);
    writeInferJson(o, data, res, ctx.runs, ctx.extrapolation, ctx.modelTimer->seconds, ctx.populationTimer->seconds);
    return res;
}

}  // namespace trbc
