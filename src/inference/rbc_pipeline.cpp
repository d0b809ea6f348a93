#include "inference/rbc_pipeline.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>

#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "inference/mcmc_diagnostics.hpp"
#include "inference/rbc_hierarchical.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// How a posterior is stored: its directory and the physical-unit columns of its samples.
struct Posterior {
    std::string phase, name;          ///< phase1 / phase2 / phase3, run name
    std::vector<std::string> names;   ///< physical column names (one per sampled variable)
    Eigen::VectorXd scale;            ///< internal -> physical factor per variable
    bool deriveEtam = false;          ///< append etam_Pa_s_um = mu r (theta_new, 4.5)
    std::string label() const { return phase + "/" + name; }
};

/// Samples in physical units (plus derived quantities) and their names.
Eigen::MatrixXd physicalSamples(const Posterior& p, const Eigen::MatrixXd& s, std::vector<std::string>& names) {
    Eigen::MatrixXd out = p.scale.asDiagonal() * s;
    names = p.names;
    if (p.deriveEtam) {  // eta_m = mu r, sample by sample (Pa s um = uN/m x s)
        appendDerivedParameter(out, names, "etam_Pa_s_um", [](const Eigen::VectorXd& t) { return t[kPooledMu] * t[kPooledR]; });
    }
    return out;
}

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
        opt.populationSize = o.populationSize;
        opt.targetCoV = st.targetCoV;
        opt.covarianceScaling = st.covarianceScaling;
        opt.maxChainLength = 1;  // BASIS
        if (p.phase == "phase1" && o.phase1BurnIn > 0) opt.burnIn = {o.phase1BurnIn};
        opt.seed = rbcRunSeed(o.seed, p.label());
        opt.checkpointDirectory = (runDirectory(p) / "checkpoint").string();
        return opt;
    }
};

void writeStages(const fs::path& file, const TmcmcResult& r) {
    std::string s = csvProvenance() + "stage,exponent,cov,acceptance_rate,unique_selections,ess,max_log_likelihood,log_evidence_increment,"
                    "covariance_jitter,likelihood_evaluations,elapsed_s\n";
    for (const TmcmcStageInfo& g : r.stages)
        s += fmt::format("{},{:.10g},{:.6g},{:.6g},{},{:.8g},{:.10g},{:.10g},{:.6g},{},{:.4f}\n", g.stage, g.exponent,
                         g.coefficientOfVariation, g.acceptanceRate, g.uniqueSelections, g.effectiveSampleSize,
                         g.maxLogLikelihood, g.logEvidenceIncrement, g.covarianceJitter, g.likelihoodEvaluations,
                         g.elapsedSeconds);
    writeFileAtomically(file, s);
}

void writeSamples(const fs::path& file, const Eigen::MatrixXd& x, const std::vector<std::string>& names,
                  const Eigen::VectorXd& logLikelihood, const Eigen::VectorXd& logPrior) {
    std::vector<std::string> header = names;
    header.insert(header.end(), {"log_likelihood", "log_prior"});
    std::string s = csvProvenance() + csvRow(header);
    s.reserve(static_cast<std::size_t>(x.cols()) * 20 * static_cast<std::size_t>(x.rows() + 2));
    for (Eigen::Index k = 0; k < x.cols(); ++k) {
        for (Eigen::Index j = 0; j < x.rows(); ++j) fmt::format_to(std::back_inserter(s), "{:.10g},", x(j, k));
        fmt::format_to(std::back_inserter(s), "{:.10g},{:.10g}\n", logLikelihood[k], logPrior[k]);
    }
    writeFileAtomically(file, s);
}

/// A finished run's timing record (also reused when a finished run is only loaded).
struct RunTiming {
    double wall = 0.0, surrogate = 0.0, population = 0.0;
};

/// The timing recorded in an earlier run.json, if it has one.
std::optional<RunTiming> recordedTiming(const fs::path& runFile) {
    const std::optional<nlohmann::json> old = tryReadJson(runFile);
    if (!old || !old->is_object()) return std::nullopt;
    for (const char* key : {"wall_s", "surrogate_s", "population_s"})
        if (!old->contains(key) || !(*old)[key].is_number()) return std::nullopt;
    return RunTiming{(*old)["wall_s"].get<double>(), (*old)["surrogate_s"].get<double>(), (*old)["population_s"].get<double>()};
}

nlohmann::json runJson(const Posterior& p, const TmcmcOptions& opt, const TmcmcResult& r, const RunTiming& t) {
    return {{"posterior", p.name},
            {"phase", p.phase},
            {"seed", opt.seed},
            {"population_size", opt.populationSize},
            {"target_cov", opt.targetCoV},
            {"covariance_scaling", opt.covarianceScaling},
            {"max_chain_length", opt.maxChainLength},
            {"burn_in", opt.burnIn.empty() ? 0 : opt.burnIn.front()},
            {"completed", r.completed},
            {"log_evidence", r.logEvidence},
            {"stages", r.stages.size()},
            {"likelihood_evaluations", r.likelihoodEvaluations},
            {"parameters", p.names},
            {"wall_s", t.wall},
            {"surrogate_s", t.surrogate},
            {"population_s", t.population},
            {"sampler_s", t.wall - t.surrogate - t.population}};
}

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
    const fs::path runFile = dir / "run.json";
    if (stagesRun == 0)  // a finished run was only loaded: keep its timing
        if (const std::optional<RunTiming> recorded = recordedTiming(runFile)) t = *recorded;
    std::vector<std::string> names;
    const Eigen::MatrixXd phys = physicalSamples(p, r.samples, names);
    writeSamples(dir / "samples.csv", phys, names, r.logLikelihood, mapLogPrior ? mapLogPrior(r) : r.logPrior);
    writeStages(dir / "stages.csv", r);
    nlohmann::json j = runJson(p, opt, r, t);
    j["samples_columns"] = names;
    writeFileAtomically(runFile, j.dump(2) + "\n");
    ctx.runs[label] = j;
    ctx.say(fmt::format("infer {}: done, {} stages, log evidence {:.4f}, {} likelihood evaluations, {:.1f} s{}", label,
                        r.stages.size(), r.logEvidence, r.likelihoodEvaluations, t.wall, stagesRun == 0 ? " (reused)" : ""));
    return r;
}

/// Loads a finished run of an earlier invocation (phases not selected now).
TmcmcResult loadPosterior(Context& ctx, const Posterior& p, const TmcmcProblem& problem, RbcSamplerSettings st, int phase) {
    TmcmcOptions opt = ctx.runOptions(p, st);
    const fs::path header = fs::path(opt.checkpointDirectory) / "tmcmc_checkpoint.json";
    if (!fs::exists(header))
        throw InputError(fmt::format("{}: no results of {} (missing {}); run `trbc infer --phase {}` with this --out first",
                                     ctx.o.outputDirectory.string(), p.label(), header.string(), phase));
    double rho = 0.0;
    try {
        std::ifstream f(header);
        const nlohmann::json h = nlohmann::json::parse(f);
        rho = h.at("exponent").is_number() ? h.at("exponent").get<double>() : 0.0;
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: cannot read {}: {}", p.label(), header.string(), e.what()));
    }
    if (!(rho >= 1.0))
        throw InputError(fmt::format("{}: the run {} is unfinished (exponent {}); finish it with `trbc infer --phase {} --resume`",
                                     ctx.o.outputDirectory.string(), p.label(), rho, phase));
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
    return {phase, d.name, phase1OutputNames(d.experiment), phase1OutputScale(d.experiment), false};
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

// ------------------------------------------------------------------------------------------------
// Markdown table (paper's Table 1 layout)

struct TableRow {
    std::string label;  // e.g. "$\\mu$ (µN/m)"
    std::string parameter;
    double factor;      // physical -> table unit
};

std::string formatNumber(double x) {
    if (x == 0.0) return "0";
    const double a = std::abs(x);
    if (a >= 0.01 && a < 1e4) return fmt::format("{:.3g}", x);
    return fmt::format("{:.3e}", x);
}

std::string markdownTable(const std::vector<PosteriorStatsRow>& rows, const std::string& posterior, const std::vector<TableRow>& layout,
                          bool twoDecimals) {
    std::string s = "| | mean | median | ML | MAP | standard deviation | 5 % | 95 % |\n|---|---|---|---|---|---|---|---|\n";
    for (const TableRow& t : layout)
        for (const PosteriorStatsRow& r : rows)
            if (r.posterior == posterior && r.parameter == t.parameter) {
                auto f = [&](double x) { return twoDecimals ? fmt::format("{:.2f}", x * t.factor) : formatNumber(x * t.factor); };
                s += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} |\n", t.label, f(r.mean), f(r.median), f(r.ml), f(r.map),
                                 f(r.sd), f(r.q05), f(r.q95));
            }
    return s;
}

std::vector<TableRow> tableLayout(const std::vector<PosteriorStatsRow>& rows, const std::string& posterior) {
    static const std::vector<TableRow> known = {
        {"$v$", "v", 1.0},
        {"$\\mu$ (µN/m)", "mu_uN_per_m", 1.0},
        {"$\\kappa_b$ ($10^{-19}$ J)", "kb_J", 1e19},
        {"$b_2$", "b2", 1.0},
        {"$\\eta_m$ (Pa s µm)", "etam_Pa_s_um", 1.0},
        {"$\\eta_m/\\mu$ (s)", "etam_over_mu_s", 1.0},
        {"FvK", "FvK", 1.0},
    };
    std::vector<TableRow> out;
    for (const TableRow& t : known)
        for (const PosteriorStatsRow& r : rows)
            if (r.posterior == posterior && r.parameter == t.parameter) out.push_back(t);
    for (const PosteriorStatsRow& r : rows) {  // the remaining (error-model) parameters as they are
        if (r.posterior != posterior) continue;
        bool have = false;
        for (const TableRow& t : out) have = have || t.parameter == r.parameter;
        if (!have) out.push_back({"`" + r.parameter + "`", r.parameter, 1.0});
    }
    return out;
}

std::string tableMarkdown(const RbcInferenceOptions& o, const std::vector<PosteriorStatsRow>& rows, const std::vector<RbcDataSet>& data,
                          const nlohmann::json& extrapolation, const nlohmann::json& check) {
    std::string s = "# Posterior statistics of the t-RBC parameters\n\n";
    s += fmt::format("Made by `{}` (trbc {}), seed {}, {} samples per TMCMC/BASIS run (docs/BAYESIAN_INFERENCE.md).\n",
                     o.provenance.value("command", std::string("trbc infer")), kVersion, o.seed, o.populationSize);
    if (o.provenance.contains("model")) s += fmt::format("Model: `{}`.\n", o.provenance["model"].value("dir", std::string("?")));
    s += "\n## $\\theta^{\\rm new}$: a new cell given all data (phase 3a) — the layout of the paper's Table 1\n\n";
    s += "$\\mu$ in µN/m, $\\kappa_b$ in $10^{-19}$ J, $\\eta_m$ in Pa·s·µm. MAP = ML here (uniform box prior, docs/BAYESIAN_INFERENCE.md).\n\n";
    const std::vector<TableRow> table1 = {{"$v$", "v", 1.0},
                                          {"$\\mu$", "mu_uN_per_m", 1.0},
                                          {"$\\kappa_b$", "kb_J", 1e19},
                                          {"$b_2$", "b2", 1.0},
                                          {"$\\eta_m$", "etam_Pa_s_um", 1.0}};
    s += "| | mean | median | ML | MAP | standard deviation | MCSE of mean | MCSE of median | MCSE of SD |\n"
         "|---|---|---|---|---|---|---|---|---|\n";
    for (const TableRow& t : table1)
        for (const PosteriorStatsRow& r : rows)
            if (r.posterior == "theta_new" && r.parameter == t.parameter)
                s += fmt::format("| {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2g} | {:.2g} | {:.2g} |\n", t.label, r.mean * t.factor,
                                 r.median * t.factor, r.ml * t.factor, r.map * t.factor, r.sd * t.factor, r.mcseMean * t.factor,
                                 r.mcseMedian * t.factor, r.mcseSd * t.factor);
    s += "\nMCSE: Monte Carlo standard error of the estimate (for the joint method from the multi-chain effective sample "
         "size; for a BASIS population a lower bound that ignores its ancestry).\n";
    s += "\nWith the 90 % central credible intervals and $\\eta_m/\\mu$:\n\n";
    s += markdownTable(rows, "theta_new", tableLayout(rows, "theta_new"), false);
    if (!check.is_null() && check.contains("max_mean_difference_in_sd"))
        s += fmt::format("\nCross-check (docs/BAYESIAN_INFERENCE.md): ancestral sampling of the same mixture gives means within {:.3f} "
                         "posterior SD of the TMCMC samples (largest difference over the parameters).\n",
                         check["max_mean_difference_in_sd"].get<double>());
    s += "\n## Each data set given all data (phase 3b)\n";
    for (const RbcDataSet& d : data) {
        s += fmt::format("\n### {} ({}, `{}`)\n\n", d.name, experimentName(d.experiment), d.file.filename().string());
        s += markdownTable(rows, d.name, tableLayout(rows, d.name), false);
    }
    if (!extrapolation.empty()) {
        s += "\n## Relaxation network outside its training range\n\nShare of the samples with $r=\\eta_m/\\mu$ outside "
             "[0.025, 0.25] s, where the network input $\\eta_m=4r$ leaves [0.1, 1] (docs/BAYESIAN_INFERENCE.md):\n\n| posterior | share |\n|---|---|\n";
        for (const auto& [k, v] : extrapolation.items()) s += fmt::format("| {} | {:.3f} |\n", k, v.get<double>());
    }
    return s;
}

nlohmann::json readJsonOrEmpty(const fs::path& p) {
    const std::optional<nlohmann::json> j = tryReadJson(p);
    return j && j->is_object() ? *j : nlohmann::json::object();
}

nlohmann::json timingJson(const RbcPhaseTiming& t) {
    return {{"wall_s", t.wallSeconds},          {"surrogate_s", t.surrogateSeconds}, {"population_s", t.populationSeconds},
            {"sampler_s", t.samplerSeconds()},  {"surrogate_evaluations", t.surrogateEvaluations},
            {"population_terms", t.populationTerms}};
}

/// Mean and SD of each parameter of theta_new from TMCMC and from ancestral sampling.
nlohmann::json ancestralCheck(const Eigen::MatrixXd& tmcmc, const Eigen::MatrixXd& ancestral, const fs::path& file) {
    const auto& names = pooledOutputNames();
    const Eigen::VectorXd scale = pooledOutputScale();
    std::string csv = csvProvenance() + "parameter,tmcmc_mean,ancestral_mean,tmcmc_sd,ancestral_sd,tmcmc_q05,ancestral_q05,tmcmc_q95,ancestral_q95,mean_difference_in_sd\n";
    nlohmann::json j = nlohmann::json::object();
    double worst = 0.0;
    for (int p = 0; p < kPooledDimension; ++p) {
        const Eigen::VectorXd a = tmcmc.row(p).transpose() * scale[p], b = ancestral.row(p).transpose() * scale[p];
        const double ma = mean(a), mb = mean(b), sa = populationSd(a), sb = populationSd(b);
        const double diff = (ma - mb) / std::max(sb, 1e-300);
        worst = std::max(worst, std::abs(diff));
        csv += fmt::format("{},{:.8g},{:.8g},{:.8g},{:.8g},{:.8g},{:.8g},{:.8g},{:.8g},{:.4f}\n", csvField(names[static_cast<std::size_t>(p)]), ma, mb,
                           sa, sb, quantile(a, 0.05), quantile(b, 0.05), quantile(a, 0.95), quantile(b, 0.95), diff);
        j[names[static_cast<std::size_t>(p)]] = {{"tmcmc_mean", ma}, {"ancestral_mean", mb}, {"tmcmc_sd", sa}, {"ancestral_sd", sb},
                                                 {"mean_difference_in_sd", diff}};
    }
    writeFileAtomically(file, csv);
    j["max_mean_difference_in_sd"] = worst;
    return j;
}

// ------------------------------------------------------------------------------------------------
// The joint method (phases 2 and 3 from one multi-chain MCMC run)

constexpr char kDrawsMagic[8] = {'T', 'R', 'B', 'C', 'J', 'M', 'C', '1'};

/// Draws of the joint sampler as raw doubles (exact), with a JSON header of the settings they were
/// made with; written to temporary names and renamed.
void saveJointDraws(const fs::path& dir, const nlohmann::json& settings, const HierarchicalMcmcResult& r) {
    fs::create_directories(dir);
    const fs::path bin = dir / "draws.bin", tmp = dir / "draws.bin.tmp";
    {
        std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
        auto put = [&f](const double* p, Eigen::Index n) { f.write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(sizeof(double) * n)); };
        f.write(kDrawsMagic, 8);
        for (const auto& h : r.hyper) put(h.data(), h.size());
        for (std::size_t g = 0; g < r.group.size(); ++g)
            for (std::size_t c = 0; c < r.group[g].size(); ++c) {
                put(r.group[g][c].data(), r.group[g][c].size());
                put(r.logLikelihood[g][c].data(), r.logLikelihood[g][c].size());
            }
        if (!f) throw InputError(fmt::format("cannot write {} (disk full?)", tmp.string()));
    }
    fs::rename(tmp, bin);
    nlohmann::json h = settings;
    h["group_dimensions"] = nlohmann::json::array();
    for (const auto& g : r.group) h["group_dimensions"].push_back(g.empty() ? 0 : g[0].rows());
    h["hyper_rows"] = r.hyper.empty() ? 0 : r.hyper[0].rows();
    h["acceptance"] = {{"groups", r.groupAcceptance}, {"hyper", r.hyperAcceptance}, {"shift", r.shiftAcceptance}, {"scale", r.scaleAcceptance}};
    h["likelihood_evaluations"] = r.likelihoodEvaluations;
    h["wall_s"] = r.wallSeconds;
    writeFileAtomically(dir / "draws.json", h.dump(1) + "\n");
}

/// Loads draws saved with the same settings; false when there are none or they were made otherwise.
bool loadJointDraws(const fs::path& dir, const nlohmann::json& settings, HierarchicalMcmcResult& r) {
    const nlohmann::json h = readJsonOrEmpty(dir / "draws.json");
    if (h.empty() || !fs::exists(dir / "draws.bin")) return false;
    for (const auto& [k, v] : settings.items())
        if (!h.contains(k) || h[k] != v) return false;
    const int C = settings.at("chains").get<int>(), T = settings.at("draws").get<int>();
    const auto dims = h.at("group_dimensions").get<std::vector<Eigen::Index>>();
    const Eigen::Index rows = h.at("hyper_rows").get<Eigen::Index>();
    std::ifstream f(dir / "draws.bin", std::ios::binary);
    char magic[8];
    f.read(magic, 8);
    if (!f || !std::equal(magic, magic + 8, kDrawsMagic)) return false;
    auto get = [&f](double* p, Eigen::Index n) { f.read(reinterpret_cast<char*>(p), static_cast<std::streamsize>(sizeof(double) * n)); };
    r = HierarchicalMcmcResult{};
    r.hyper.assign(static_cast<std::size_t>(C), Eigen::MatrixXd(rows, T));
    for (auto& x : r.hyper) get(x.data(), x.size());
    r.group.assign(dims.size(), {});
    r.logLikelihood.assign(dims.size(), {});
    for (std::size_t g = 0; g < dims.size(); ++g)
        for (int c = 0; c < C; ++c) {
            r.group[g].push_back(Eigen::MatrixXd(dims[g], T));
            r.logLikelihood[g].push_back(Eigen::VectorXd(T));
            get(r.group[g].back().data(), r.group[g].back().size());
            get(r.logLikelihood[g].back().data(), T);
        }
    if (!f) return false;
    r.groupAcceptance = h["acceptance"].value("groups", std::vector<double>{});
    r.hyperAcceptance = h["acceptance"].value("hyper", std::vector<double>{});
    r.shiftAcceptance = h["acceptance"].value("shift", 0.0);
    r.scaleAcceptance = h["acceptance"].value("scale", 0.0);
    r.likelihoodEvaluations = h.value("likelihood_evaluations", 0LL);
    r.wallSeconds = h.value("wall_s", 0.0);
    return true;
}

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
    writeSamples(dir / "samples.csv", phys, names, ll, lp);
    nlohmann::json j = info;
    j["posterior"] = p.name;
    j["phase"] = p.phase;
    j["parameters"] = names;
    j["samples_columns"] = names;
    j["chains"] = chains;
    j["draws_per_chain"] = samples.cols() / std::max(chains, 1);
    j["layout"] = "chain c holds the columns c * draws_per_chain ... (c + 1) * draws_per_chain - 1";
    writeFileAtomically(dir / "run.json", j.dump(2) + "\n");
    ctx.runs[p.label()] = j;
    return posteriorStatsRows(p.name, phys, names, ll, lp, chains);
}

HierarchicalMcmcOptions jointOptions(const RbcInferenceOptions& o) {
    HierarchicalMcmcOptions mo;
    mo.chains = o.chains;
    mo.warmup = o.warmup;
    mo.draws = o.draws;
    mo.thin = o.thin;
    return mo;
}

template <class Begin, class End>
void runJointPhases(Context& ctx, const std::vector<RbcDataSet>& data, RbcInferenceResult& res,
                    const Begin& phaseBegin, const End& phaseEnd) {
    const RbcInferenceOptions& o = ctx.o;
    const fs::path jointDir = o.outputDirectory / "phase2" / "joint";
    const std::uint64_t seed = rbcRunSeed(o.seed, "phase2/joint");
    const nlohmann::json settings = {{"method", "joint MCMC"}, {"chains", o.chains}, {"warmup", o.warmup}, {"draws", o.draws}, {"thin", o.thin},
                                     {"seed", seed}, {"phase1_samples", o.populationSize}, {"phase1_burn_in", o.phase1BurnIn},
                                     {"hyper_sd_scale", o.population.sdUpperScale}, {"population_truncation", o.population.truncate}};
    {
        const auto begin = phaseBegin(2);
        const bool run = o.firstPhase <= 2;
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
        if (run) phaseEnd(2, begin);
    }
    if (o.lastPhase < 3) return;
    const auto begin3 = phaseBegin(3);
    const HierarchicalMcmcResult& J = res.joint;
    const int C = static_cast<int>(J.hyper.size());
    const Eigen::MatrixXd psi = concatenate(J.hyper);

    // theta_new: Rao-Blackwellised statistics; draws of the restricted mixture for the sample file.
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

    // Each data set given all data: the group draws.
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
    writePosteriorStats(o.outputDirectory / "posterior_stats.csv", rows);
    writeFileAtomically(o.outputDirectory / "posterior_table.md", tableMarkdown(o, rows, data, ctx.extrapolation, nlohmann::json()));
    res.stats = rows;
    double worstRhat = 0.0, leastBulk = kInf, leastTail = kInf;
    for (const PosteriorStatsRow& r : rows) {
        if (std::isnan(r.rhat)) continue;
        worstRhat = std::max(worstRhat, r.rhat), leastBulk = std::min(leastBulk, r.essBulk), leastTail = std::min(leastTail, r.essTail);
    }
    ctx.runs["phase3/theta_new"]["diagnostics"] = {{"max_rhat", worstRhat}, {"min_ess_bulk", leastBulk}, {"min_ess_tail", leastTail}};
    ctx.say(fmt::format("infer phase3: largest R-hat {:.4f}, smallest bulk ESS {:.0f}, smallest tail ESS {:.0f} (theta_new and every data set)",
                        worstRhat, leastBulk, leastTail));
    phaseEnd(3, begin3);
}

}  // namespace

// ------------------------------------------------------------------------------------------------

nlohmann::json priorBoxJson(const RbcPriorBox& box) {
    nlohmann::json j = nlohmann::json::object();
    for (const std::string& name : RbcPriorBox::parameterNames()) {
        const auto [lo, hi] = box.bounds(name);
        j[name] = {lo, hi};
    }
    return j;
}

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

void writePosteriorStats(const fs::path& file, const std::vector<PosteriorStatsRow>& rows) {
    std::string s = csvProvenance() +
                    "posterior,parameter,mean,median,ml,map,sd,q05,q95,mcse_mean,mcse_median,mcse_sd,mcse_q05,mcse_q95,rhat,ess_bulk,ess_tail\n";
    for (const PosteriorStatsRow& r : rows)
        s += fmt::format("{},{},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.4g},{:.4g},{:.4g},{:.4g},{:.4g},{:.5f},{:.0f},{:.0f}\n",
                         csvField(r.posterior), csvField(r.parameter), r.mean, r.median, r.ml, r.map, r.sd, r.q05, r.q95, r.mcseMean, r.mcseMedian,
                         r.mcseSd, r.mcseQ05, r.mcseQ95, r.rhat, r.essBulk, r.essTail);
    writeFileAtomically(file, s);
}

RbcInferenceResult runRbcInference(const RbcModel& model, const std::vector<RbcDataSet>& data, const RbcInferenceOptions& o) {
    if (o.firstPhase < 1 || o.lastPhase > 3 || o.firstPhase > o.lastPhase)
        throw InputError(fmt::format("infer: phases {}..{} are invalid: the phases are 1, 2, 3", o.firstPhase, o.lastPhase));
    if (o.method == HierarchicalMethod::Reweighting && (o.population.sdUpperScale != 1.0 || !o.population.truncate))
        throw InputError("infer: --hyper-sd-scale and --population-truncation off need --method joint (the re-weighting route's population is fixed)");
    if (o.method == HierarchicalMethod::Joint) validateHierarchicalMcmcOptions(jointOptions(o));  // before phase 1 runs
    if (o.populationSize < 2) throw InputError(fmt::format("infer: --samples = {} is invalid: must be >= 2", o.populationSize));
    if (data.empty()) throw InputError("infer: no data sets");
    if (o.outputDirectory.empty()) throw InputError("infer: no output directory");
    fs::create_directories(o.outputDirectory);

    const auto tStart = SteadyClock::now();
    Context ctx{o, {}, std::make_shared<ModelTimer>(), std::make_shared<PopulationTimer>()};
    ctx.model = timedModel(model, ctx.modelTimer);
    RbcInferenceResult res;
    const auto phaseBegin = [&](int) { return std::tuple{SteadyClock::now(), ctx.modelTimer->seconds, ctx.modelTimer->evaluations,
                                                         ctx.populationTimer->seconds, ctx.populationTimer->terms}; };
    auto phaseEnd = [&](int phase, const auto& begin) {
        const auto& [t0, s0, e0, p0, n0] = begin;
        RbcPhaseTiming& t = res.timing[phase - 1];
        t.ran = true;
        t.wallSeconds = secondsSince(t0);
        t.surrogateSeconds = ctx.modelTimer->seconds - s0;
        t.surrogateEvaluations = ctx.modelTimer->evaluations - e0;
        t.populationSeconds = ctx.populationTimer->seconds - p0;
        t.populationTerms = ctx.populationTimer->terms - n0;
        ctx.say(fmt::format("infer phase {}: {:.1f} s (surrogate {:.1f} s, population sums {:.1f} s, sampler and I/O {:.1f} s)",
                            phase, t.wallSeconds, t.surrogateSeconds, t.populationSeconds, t.samplerSeconds()));
    };

    // ---- Phase 1: seven independent posteriors
    std::vector<PosteriorStatsRow> rows1;
    {
        const bool run = o.firstPhase <= 1;
        const auto begin = phaseBegin(1);
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
            phaseEnd(1, begin);
        }
    }
    if (o.lastPhase >= 2 && o.method == HierarchicalMethod::Joint) {
        runJointPhases(ctx, data, res, phaseBegin, phaseEnd);
    } else if (o.lastPhase >= 2) {
        // ---- Phase 2: hyper-parameters by re-weighting the phase-1 samples
        std::vector<ReweightingSamples> sets;
        for (std::size_t i = 0; i < data.size(); ++i) {
            sets.push_back(reweightingSamples(data[i], res.phase1[i].samples));
            ctx.say(fmt::format("infer phase2: {} enters with {} distinct of {} phase-1 samples", data[i].name, sets.back().x.cols(),
                                sets.back().total));
        }
        const Posterior p{"phase2", "hyper", hyperOutputNames(), hyperOutputScale(), false};
        const RbcSamplerSettings st = rbcSamplerSettings(RbcRun::Phase2);
        const bool run = o.firstPhase <= 2;
        const auto begin = phaseBegin(2);
        res.phase2 = run ? runPosterior(ctx, p, phase2Problem(sets, o.fvkRule, ctx.populationTimer), st)
                         : loadPosterior(ctx, p, loadOnlyProblem(hyperPrior()), st, 2);
        if (run) {
            writePosteriorStats(o.outputDirectory / "phase2" / "posterior_stats.csv", statsOf(p, res.phase2, res.phase2.logPrior));
            phaseEnd(2, begin);
        }

        // ---- Phase 3: theta_new and each data set given all data
        if (o.lastPhase >= 3) {
            const auto begin3 = phaseBegin(3);
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
            const nlohmann::json check = ancestralCheck(res.phase3a.samples, res.ancestral,
                                                        ctx.runDirectory(pNew) / "ancestral_check.csv");
            ctx.say(fmt::format("infer phase3/theta_new: ancestral cross-check, largest mean difference {:.3f} SD",
                                check["max_mean_difference_in_sd"].get<double>()));

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
            writePosteriorStats(o.outputDirectory / "posterior_stats.csv", rows);
            writeFileAtomically(o.outputDirectory / "posterior_table.md", tableMarkdown(o, rows, data, ctx.extrapolation, check));
            res.stats = rows;
            phaseEnd(3, begin3);

            nlohmann::json& ci = ctx.runs["phase3/theta_new"];
            ci["ancestral_check"] = check;
        }
    }
    res.wallSeconds = secondsSince(tStart);

    // ---- Provenance (merged with what earlier invocations wrote)
    const fs::path infoFile = o.outputDirectory / "infer.json";
    nlohmann::json info = readJsonOrEmpty(infoFile);
    for (const auto& [k, v] : o.provenance.items()) info[k] = v;
    info = withBuild(std::move(info));
    info["seed"] = o.seed;
    info["samples"] = o.populationSize;
    info["threads"] = omp_get_max_threads();
    info["fvk_density"] = o.fvkRule == FvkDensityRule::ClosedForm         ? "closed form, mixed precision"
                          : o.fvkRule == FvkDensityRule::ClosedFormDouble ? "closed form, double precision"
                                                                          : "50-node rule";
    info["method"] = o.method == HierarchicalMethod::Joint ? "joint" : "reweighting";
    if (o.method == HierarchicalMethod::Joint) info["joint"] = {{"chains", o.chains}, {"warmup", o.warmup}, {"draws", o.draws}, {"thin", o.thin}};
    info["population"] = {{"hyper_sd_scale", o.population.sdUpperScale}, {"truncation", o.population.truncate},
                          {"theta_new_box", o.population.newCellBox}};
    info["phase3b_prior"] = o.phase3b.referencePrior ? "reference (phase-1 prior)" : "support indicator";
    info["phase3b_equilibrium_fvk"] = o.phase3b.referenceEquilibriumDefect ? "last phase-2 sample (reference)" : "every phase-2 sample";
    nlohmann::json files = nlohmann::json::array();
    for (const RbcDataSet& d : data)
        files.push_back({{"name", d.name}, {"experiment", experimentName(d.experiment)}, {"file", d.file.string()}, {"fnv1a", d.contentHash}});
    info["data_sets"] = files;
    if (!info.contains("phases")) info["phases"] = nlohmann::json::object();
    if (!info.contains("runs")) info["runs"] = nlohmann::json::object();
    for (int ph = 1; ph <= 3; ++ph)
        if (res.timing[ph - 1].ran) {
            nlohmann::json t = timingJson(res.timing[ph - 1]);
            t["command"] = o.provenance.value("command", std::string());
            info["phases"][std::to_string(ph)] = t;
        }
    double total = 0.0, totalSurrogate = 0.0, totalPopulation = 0.0;
    for (const auto& [k, v] : info["phases"].items()) {
        total += v.value("wall_s", 0.0);
        totalSurrogate += v.value("surrogate_s", 0.0);
        totalPopulation += v.value("population_s", 0.0);
    }
    info["total"] = {{"wall_s", total}, {"surrogate_s", totalSurrogate}, {"population_s", totalPopulation},
                     {"sampler_s", total - totalSurrogate - totalPopulation},
                     {"note", "sum over the phases recorded in this directory; sampler_s = wall - surrogate - population "
                              "(TMCMC, statistics, I/O)"}};
    for (const auto& [k, v] : ctx.runs.items()) info["runs"][k] = v;
    if (!info.contains("relaxation_extrapolation")) info["relaxation_extrapolation"] = nlohmann::json::object();
    for (const auto& [k, v] : ctx.extrapolation.items()) info["relaxation_extrapolation"][k] = v;
    info["last_invocation"] = {{"phases", fmt::format("{}-{}", o.firstPhase, o.lastPhase)},
                               {"wall_s", res.wallSeconds},
                               {"surrogate_s", ctx.modelTimer->seconds},
                               {"population_s", ctx.populationTimer->seconds},
                               {"sampler_s", res.wallSeconds - ctx.modelTimer->seconds - ctx.populationTimer->seconds}};
    writeFileAtomically(infoFile, info.dump(2) + "\n");
    return res;
}

}  // namespace trbc
