// Writers and readers of the files of `trbc infer` (posterior_store.hpp), and the public
// writePosteriorStats, priorBoxJson and checkPhase1Record of rbc_pipeline.hpp.
#include "inference/posterior_store.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "inference/population.hpp"
#include "inference/statistics.hpp"

namespace trbc {
namespace fs = std::filesystem;

void writePosteriorStats(const fs::path& file, const std::vector<PosteriorStatsRow>& rows) {
    std::string s = csvProvenance() +
                    "posterior,parameter,mean,median,ml,map,sd,q05,q95,mcse_mean,mcse_median,mcse_sd,mcse_q05,mcse_q95,rhat,ess_bulk,ess_tail\n";
    for (const PosteriorStatsRow& r : rows)
        s += fmt::format("{},{},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.4g},{:.4g},{:.4g},{:.4g},{:.4g},{:.5f},{:.0f},{:.0f}\n",
                         csvField(r.posterior), csvField(r.parameter), r.mean, r.median, r.ml, r.map, r.sd, r.q05, r.q95, r.mcseMean, r.mcseMedian,
                         r.mcseSd, r.mcseQ05, r.mcseQ95, r.rhat, r.essBulk, r.essTail);
    writeFileAtomically(file, s);
}

nlohmann::json priorBoxJson(const RbcPriorBox& box) {
    nlohmann::json j = nlohmann::json::object();
    for (const std::string& name : RbcPriorBox::parameterNames()) {
        const auto [lo, hi] = box.bounds(name);
        j[name] = {lo, hi};
    }
    return j;
}

void checkPhase1Record(const std::filesystem::path& out, const nlohmann::json& record, bool reuses, bool writes) {
    const std::filesystem::path file = out / kPhase1PriorBoxFile;
    if (reuses && std::filesystem::exists(file)) {
        std::ifstream in(file);
        const nlohmann::json previous = nlohmann::json::parse(in, nullptr, false);
        if (previous != record)
            throw InputError(fmt::format("{}: the phase-1 posteriors in {} were made with the prior box (and flow networks) {}, "
                                         "not {}; give the same --prior (and --datasets, --flow-model) or use another --out",
                                         file.string(), out.string(), previous.dump(), record.dump()));
    }
    if (writes) writeFileAtomically(file, record.dump(1) + "\n");
}

namespace detail {

Eigen::MatrixXd physicalSamples(const Posterior& p, const Eigen::MatrixXd& s, std::vector<std::string>& names) {
    Eigen::MatrixXd out = p.scale.asDiagonal() * s;
    names = p.names;
    if (p.deriveEtam) {  // eta_m = mu r, sample by sample (Pa s um = uN/m x s)
        appendDerivedParameter(out, names, "etam_Pa_s_um", [](const Eigen::VectorXd& t) { return t[kPooledMu] * t[kPooledR]; });
    }
    return out;
}

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

nlohmann::json writeTmcmcRun(const fs::path& dir, const Posterior& p, const TmcmcOptions& opt, const TmcmcResult& r, const RunTiming& t,
                             const Eigen::VectorXd& logPrior) {
    std::vector<std::string> names;
    const Eigen::MatrixXd phys = physicalSamples(p, r.samples, names);
    writeSamples(dir / "samples.csv", phys, names, r.logLikelihood, logPrior);
    writeStages(dir / "stages.csv", r);
    nlohmann::json j = runJson(p, opt, r, t);
    j["samples_columns"] = names;
    writeFileAtomically(dir / "run.json", j.dump(2) + "\n");
    return j;
}

nlohmann::json writeChainRun(const fs::path& dir, const Posterior& p, const Eigen::MatrixXd& phys, const std::vector<std::string>& names,
                             const Eigen::VectorXd& logLikelihood, const Eigen::VectorXd& logPrior, int chains, const nlohmann::json& info) {
    writeSamples(dir / "samples.csv", phys, names, logLikelihood, logPrior);
    nlohmann::json j = info;
    j["posterior"] = p.name;
    j["phase"] = p.phase;
    j["parameters"] = names;
    j["samples_columns"] = names;
    j["chains"] = chains;
    j["draws_per_chain"] = phys.cols() / std::max(chains, 1);
    j["layout"] = "chain c holds the columns c * draws_per_chain ... (c + 1) * draws_per_chain - 1";
    writeFileAtomically(dir / "run.json", j.dump(2) + "\n");
    return j;
}

void requireFinishedRun(const fs::path& checkpointDirectory, const fs::path& outputDirectory, const std::string& label, int phase) {
    const fs::path header = checkpointDirectory / "tmcmc_checkpoint.json";
    if (!fs::exists(header))
        throw InputError(fmt::format("{}: no results of {} (missing {}); run `trbc infer --phase {}` with this --out first",
                                     outputDirectory.string(), label, header.string(), phase));
    double rho = 0.0;
    try {
        std::ifstream f(header);
        const nlohmann::json h = nlohmann::json::parse(f);
        rho = h.at("exponent").is_number() ? h.at("exponent").get<double>() : 0.0;
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: cannot read {}: {}", label, header.string(), e.what()));
    }
    if (!(rho >= 1.0))
        throw InputError(fmt::format("{}: the run {} is unfinished (exponent {}); finish it with `trbc infer --phase {} --resume`",
                                     outputDirectory.string(), label, rho, phase));
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

namespace {
constexpr char kDrawsMagic[8] = {'T', 'R', 'B', 'C', 'J', 'M', 'C', '1'};
}  // namespace

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

void writeInferJson(const RbcInferenceOptions& o, const std::vector<RbcDataSet>& data, const RbcInferenceResult& res,
                    const nlohmann::json& runs, const nlohmann::json& extrapolation, double surrogateSeconds, double populationSeconds) {
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
    for (const auto& [k, v] : runs.items()) info["runs"][k] = v;
    if (!info.contains("relaxation_extrapolation")) info["relaxation_extrapolation"] = nlohmann::json::object();
    for (const auto& [k, v] : extrapolation.items()) info["relaxation_extrapolation"][k] = v;
    info["last_invocation"] = {{"phases", fmt::format("{}-{}", o.firstPhase, o.lastPhase)},
                               {"wall_s", res.wallSeconds},
                               {"surrogate_s", surrogateSeconds},
                               {"population_s", populationSeconds},
                               {"sampler_s", res.wallSeconds - surrogateSeconds - populationSeconds}};
    writeFileAtomically(infoFile, info.dump(2) + "\n");
}

}  // namespace detail
}  // namespace trbc
