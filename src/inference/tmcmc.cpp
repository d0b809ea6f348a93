#include "inference/tmcmc.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <utility>

#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/log.hpp"

namespace trbc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Purposes of the random streams: Rng(seed, purpose, stage, index).
enum StreamPurpose : std::uint64_t { kPriorDraw = 1, kResampling = 2, kChain = 3 };

struct Population {
    Eigen::MatrixXd theta;     // n x N
    Eigen::VectorXd logLike;   // N
    Eigen::VectorXd logPrior;  // N
};

/// Everything needed to continue a run (what a checkpoint holds).
struct RunState {
    Population pop;
    double rho = 0.0;
    double logEvidence = 0.0;
    int stage = 0;  // annealing stages completed
    long long evaluations = 0;
    std::vector<TmcmcStageInfo> stages;
};

using Clock = std::chrono::steady_clock;

std::string formatVector(const Eigen::VectorXd& v) {
    std::string s = "(";
    for (Eigen::Index i = 0; i < v.size(); ++i) s += fmt::format("{}{:.17g}", i ? ", " : "", v[i]);
    return s + ")";
}

/// OpenMP loop over [0, count) that carries the first exception out of the parallel region.
/// Iterations only write their own slots, so results do not depend on the schedule.
template <class Body>
void parallelFor(int count, Body&& body) {
    std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 8)
    for (int i = 0; i < count; ++i) {
        try {
            body(i);
        } catch (...) {
#pragma omp critical(trbc_tmcmc_error)
            if (!error) error = std::current_exception();
        }
    }
    if (error) std::rethrow_exception(error);
}

// ------------------------------------------------------------------------------------------------
// Likelihood evaluation

/// out[i] = l(thetas.col(i)) for i in `which`, by the batched callback (one call) or by the
/// per-sample callback in parallel. Then checks the values in index order: NaN and +inf throw.
void evaluateLogLikelihood(const TmcmcProblem& problem, const Eigen::MatrixXd& thetas, const std::vector<int>& which,
                           Eigen::VectorXd& out, int stage) {
    const int m = static_cast<int>(which.size());
    if (m == 0) return;
    if (problem.batchLogLikelihood) {
        Eigen::MatrixXd batch(thetas.rows(), m);
        for (int i = 0; i < m; ++i) batch.col(i) = thetas.col(which[static_cast<std::size_t>(i)]);
        const Eigen::VectorXd values = problem.batchLogLikelihood(batch);
        if (values.size() != m)
            throw InputError(fmt::format("TMCMC: batchLogLikelihood returned {} values for a batch of {}", values.size(), m));
        for (int i = 0; i < m; ++i) out[which[static_cast<std::size_t>(i)]] = values[i];
    } else {
        parallelFor(m, [&](int i) {
            const int c = which[static_cast<std::size_t>(i)];
            const Eigen::VectorXd theta = thetas.col(c);
            out[c] = problem.logLikelihood(theta);
        });
    }
    for (int c : which) {
        const double v = out[c];
        if (std::isnan(v) || v == kInf)
            throw NumericalError(fmt::format(
                "TMCMC stage {}: the log-likelihood is {} at prior sample {}, theta = {} (it must be finite, or -inf "
                "for zero likelihood)", stage, std::isnan(v) ? "NaN" : "+inf", c, formatVector(thetas.col(c))));
    }
}

// ------------------------------------------------------------------------------------------------
// Stage pieces (TMCMC stage: weights, resampling, MCMC moves)

double maxFinite(const Eigen::VectorXd& v) {
    double m = -kInf;
    for (Eigen::Index k = 0; k < v.size(); ++k) m = std::max(m, v[k]);
    return m;
}

/// Proposal covariance, step 3 of a stage (Weighted) or the selection-count weighting (SelectionCounts). Serial, fixed order.
Eigen::MatrixXd proposalCovariance(const Eigen::MatrixXd& theta, const Eigen::VectorXd& wbar, const std::vector<int>& counts,
                                   const TmcmcOptions& opt) {
    const Eigen::Index n = theta.rows(), N = theta.cols();
    Eigen::VectorXd w = wbar;
    double normalisation = 1.0;
    if (opt.proposalCovariance == ProposalCovariance::SelectionCounts) {
        // w'_k = wbar_k n_k / sum(wbar n); Sigma /= (1 - sum w'^2)  (unbiased weighted covariance)
        double s = 0.0;
        for (Eigen::Index k = 0; k < N; ++k) s += (w[k] = wbar[k] * counts[static_cast<std::size_t>(k)]);
        double s2 = 0.0;
        for (Eigen::Index k = 0; k < N; ++k) {
            w[k] /= s;
            s2 += w[k] * w[k];
        }
        if (1.0 - s2 > 0.0) normalisation = 1.0 - s2;
    }
    Eigen::VectorXd mean = Eigen::VectorXd::Zero(n);
    for (Eigen::Index k = 0; k < N; ++k)
        if (w[k] > 0.0) mean += w[k] * theta.col(k);
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd d(n);
    for (Eigen::Index k = 0; k < N; ++k) {
        if (!(w[k] > 0.0)) continue;
        d = theta.col(k) - mean;
        for (Eigen::Index j = 0; j < n; ++j)
            for (Eigen::Index i = j; i < n; ++i) C(i, j) += w[k] * d[i] * d[j];
    }
    C = C.selfadjointView<Eigen::Lower>();
    return opt.covarianceScaling / normalisation * C;
}

/// Lower Cholesky factor of Sigma; if the factorisation fails, eps * mean(diag) is added to the
/// diagonal (eps = 1e-12, 1e-11, ...) and the amount reported in `jitter`.
Eigen::MatrixXd choleskyWithJitter(const Eigen::MatrixXd& sigma, double& jitter, int stage) {
    jitter = 0.0;
    if (!sigma.allFinite())
        throw NumericalError(fmt::format("TMCMC stage {}: the proposal covariance is not finite", stage));
    Eigen::LLT<Eigen::MatrixXd> llt(sigma);
    if (llt.info() == Eigen::Success) return llt.matrixL();
    double scale = sigma.diagonal().mean();
    if (!(scale > 0.0)) scale = 1.0;
    const Eigen::Index n = sigma.rows();
    for (double eps = 1e-12; eps <= 1.0; eps *= 10.0) {
        llt.compute(sigma + eps * scale * Eigen::MatrixXd::Identity(n, n));
        if (llt.info() == Eigen::Success) {
            jitter = eps * scale;
            return llt.matrixL();
        }
    }
    throw NumericalError(fmt::format("TMCMC stage {}: the proposal covariance is not positive definite even with "
                                     "a diagonal shift of mean(diag)", stage));
}

struct Chain {
    int parent;     // population index of the seed
    int firstSlot;  // where its first recorded state goes
    int length;     // recorded steps
};

/// step 5 of a stage: the n_k copies of sample k form chains of length <= L (L = 0: one chain of n_k).
std::vector<Chain> buildChains(const std::vector<int>& counts, int maxChainLength) {
    std::vector<Chain> chains;
    int slot = 0;
    for (std::size_t k = 0; k < counts.size(); ++k) {
        int remaining = counts[k];
        while (remaining > 0) {
            const int len = maxChainLength > 0 ? std::min(remaining, maxChainLength) : remaining;
            chains.push_back({static_cast<int>(k), slot, len});
            slot += len;
            remaining -= len;
        }
    }
    return chains;
}

struct ChainStats {
    long long proposed = 0, accepted = 0, evaluations = 0;
};

/// One proposal of a Metropolis step: theta' = theta + L xi, xi ~ N(0, I) (n normals), then the
/// log of the acceptance uniform, always in this order (the same stream use in both drivers).
void propose(Rng& rng, const Eigen::MatrixXd& L, const Eigen::Ref<const Eigen::VectorXd>& theta, Eigen::VectorXd& candidate,
             double& logU) {
    Eigen::VectorXd xi(theta.size());
    for (Eigen::Index i = 0; i < xi.size(); ++i) xi[i] = rng.normal();
    candidate = theta + L.triangularView<Eigen::Lower>() * xi;
    logU = std::log(rng.uniformOpen());
}

/// Metropolis test for pi(theta) L(theta)^rho: pi(theta') = 0 or L(theta') = 0 rejects,
/// otherwise accept when log u < rho (l' - l) + log pi' - log pi.
bool acceptMove(double rho, double llNew, double lpNew, double llCur, double lpCur, double logU) {
    if (!(lpNew > -kInf) || !(llNew > -kInf)) return false;
    return logU < rho * (llNew - llCur) + lpNew - lpCur;
}

bool badLogLikelihood(double v) { return std::isnan(v) || v == kInf; }

[[noreturn]] void throwBadLogLikelihood(int stage, int chain, int step, double value, const Eigen::VectorXd& theta) {
    throw NumericalError(fmt::format("TMCMC stage {}: the log-likelihood is {} at the candidate of chain {} step {}, "
                                     "theta = {} (it must be finite, or -inf for zero likelihood)", stage,
                                     std::isnan(value) ? "NaN" : "+inf", chain, step, formatVector(theta)));
}

/// Per-sample likelihood: every chain runs all its steps inside one parallel loop (no barrier
/// per step): B unrecorded Metropolis steps, then `length` recorded ones.
ChainStats runChainsPerSample(const TmcmcProblem& problem, const TmcmcOptions& opt, const Population& parents,
                              const std::vector<Chain>& chains, const Eigen::MatrixXd& L, double rho, int burnIn, int stage,
                              Population& out) {
    const int C = static_cast<int>(chains.size());
    struct Tally {
        long long accepted = 0, evaluations = 0;
        int badStep = -1;  // first step with a NaN/+inf log-likelihood (the chain stops there)
        double badValue = 0.0;
        Eigen::VectorXd badTheta;
    };
    std::vector<Tally> tally(static_cast<std::size_t>(C));
    parallelFor(C, [&](int c) {
        const Chain& ch = chains[static_cast<std::size_t>(c)];
        Tally& t = tally[static_cast<std::size_t>(c)];
        Rng rng(opt.seed, kChain, static_cast<std::uint64_t>(stage), static_cast<std::uint64_t>(c));
        Eigen::VectorXd theta = parents.theta.col(ch.parent), candidate;
        double ll = parents.logLike[ch.parent], lp = parents.logPrior[ch.parent], logU = 0.0;
        for (int s = 0; s < burnIn + ch.length; ++s) {
            propose(rng, L, theta, candidate, logU);
            const double lpNew = problem.prior->logDensity(candidate);
            double llNew = -kInf;
            if (lpNew > -kInf) {  // l is not evaluated outside the prior support (step 5 of a stage)
                llNew = problem.logLikelihood(candidate);
                ++t.evaluations;
                if (badLogLikelihood(llNew)) {
                    t.badStep = s, t.badValue = llNew, t.badTheta = candidate;
                    return;
                }
            }
            if (acceptMove(rho, llNew, lpNew, ll, lp, logU)) {
                theta = candidate, ll = llNew, lp = lpNew;
                ++t.accepted;
            }
            if (s >= burnIn) {
                const int slot = ch.firstSlot + (s - burnIn);
                out.theta.col(slot) = theta;
                out.logLike[slot] = ll;
                out.logPrior[slot] = lp;
            }
        }
    });
    ChainStats stats;
    for (int c = 0; c < C; ++c) {  // fixed order: the reported error does not depend on threads
        const Tally& t = tally[static_cast<std::size_t>(c)];
        if (t.badStep >= 0) throwBadLogLikelihood(stage, c, t.badStep, t.badValue, t.badTheta);
        stats.accepted += t.accepted;
        stats.evaluations += t.evaluations;
        stats.proposed += burnIn + chains[static_cast<std::size_t>(c)].length;
    }
    return stats;
}

/// Batched likelihood: all chains advance in lock-step so that each step's candidates form one
/// batch. Same random streams and the same arithmetic as runChainsPerSample, so both drivers give
/// bit-identical results.
ChainStats runChainsBatched(const TmcmcProblem& problem, const TmcmcOptions& opt, const Population& parents,
                            const std::vector<Chain>& chains, const Eigen::MatrixXd& L, double rho, int burnIn, int stage,
                            Population& out) {
    const int n = static_cast<int>(parents.theta.rows());
    const int C = static_cast<int>(chains.size());
    Eigen::MatrixXd cur(n, C), prop(n, C);
    Eigen::VectorXd curLL(C), curLP(C), propLL(C), propLP(C), logU(C);
    std::vector<Rng> rngs;
    rngs.reserve(static_cast<std::size_t>(C));
    int maxSteps = 0;
    for (int c = 0; c < C; ++c) {
        const Chain& ch = chains[static_cast<std::size_t>(c)];
        cur.col(c) = parents.theta.col(ch.parent);
        curLL[c] = parents.logLike[ch.parent];
        curLP[c] = parents.logPrior[ch.parent];
        rngs.emplace_back(opt.seed, kChain, static_cast<std::uint64_t>(stage), static_cast<std::uint64_t>(c));
        maxSteps = std::max(maxSteps, burnIn + ch.length);
    }
    std::vector<long long> accepted(static_cast<std::size_t>(C), 0);
    std::vector<int> active(static_cast<std::size_t>(C));
    for (int c = 0; c < C; ++c) active[static_cast<std::size_t>(c)] = c;
    ChainStats stats;

    for (int s = 0; s < maxSteps; ++s) {
        std::erase_if(active, [&](int c) { return burnIn + chains[static_cast<std::size_t>(c)].length <= s; });
        const int A = static_cast<int>(active.size());
        stats.proposed += A;
        parallelFor(A, [&](int a) {
            const int c = active[static_cast<std::size_t>(a)];
            Eigen::VectorXd candidate;
            propose(rngs[static_cast<std::size_t>(c)], L, cur.col(c), candidate, logU[c]);
            prop.col(c) = candidate;
            propLP[c] = problem.prior->logDensity(candidate);
        });
        std::vector<int> inSupport;  // l only where pi(theta') > 0
        for (int c : active) {
            propLL[c] = -kInf;
            if (propLP[c] > -kInf) inSupport.push_back(c);
        }
        if (!inSupport.empty()) {
            Eigen::MatrixXd batch(n, static_cast<Eigen::Index>(inSupport.size()));
            for (std::size_t i = 0; i < inSupport.size(); ++i) batch.col(static_cast<Eigen::Index>(i)) = prop.col(inSupport[i]);
            const Eigen::VectorXd values = problem.batchLogLikelihood(batch);
            if (values.size() != batch.cols())
                throw InputError(fmt::format("TMCMC: batchLogLikelihood returned {} values for a batch of {}",
                                             values.size(), batch.cols()));
            for (std::size_t i = 0; i < inSupport.size(); ++i) {
                const int c = inSupport[i];
                propLL[c] = values[static_cast<Eigen::Index>(i)];
                if (badLogLikelihood(propLL[c])) throwBadLogLikelihood(stage, c, s, propLL[c], prop.col(c));
            }
            stats.evaluations += static_cast<long long>(inSupport.size());
        }
        parallelFor(A, [&](int a) {
            const int c = active[static_cast<std::size_t>(a)];
            if (acceptMove(rho, propLL[c], propLP[c], curLL[c], curLP[c], logU[c])) {
                cur.col(c) = prop.col(c);
                curLL[c] = propLL[c];
                curLP[c] = propLP[c];
                ++accepted[static_cast<std::size_t>(c)];
            }
            if (s >= burnIn) {
                const int slot = chains[static_cast<std::size_t>(c)].firstSlot + (s - burnIn);
                out.theta.col(slot) = cur.col(c);
                out.logLike[slot] = curLL[c];
                out.logPrior[slot] = curLP[c];
            }
        });
    }
    for (long long a : accepted) stats.accepted += a;
    return stats;
}

int burnInForStage(const TmcmcOptions& opt, int stage) {
    if (opt.burnIn.empty()) return 0;
    const std::size_t i = std::min(static_cast<std::size_t>(stage - 1), opt.burnIn.size() - 1);
    return opt.burnIn[i];
}

/// One annealing stage (exponent, weights, covariance, resampling, chains): updates rho, log Z and the population.
TmcmcStageInfo annealingStage(const TmcmcProblem& problem, const TmcmcOptions& opt, RunState& st) {
    const int N = opt.populationSize;
    const int stage = st.stage + 1;
    const Eigen::VectorXd& ll = st.pop.logLike;
    TmcmcStageInfo info;
    info.stage = stage;
    info.maxLogLikelihood = maxFinite(ll);
    if (!(info.maxLogLikelihood > -kInf))
        throw NumericalError(fmt::format("TMCMC stage {}: all {} samples have zero likelihood (log-likelihood -inf); "
                                         "the likelihood and the prior support do not overlap", stage, N));

    // Step 1: next exponent.
    double delta = nextTemperingIncrement(ll, st.rho, opt.targetCoV, opt.bisectionTolerance);
    double rhoNext = st.rho + std::max(delta, opt.minIncrement);
    if (delta >= 1.0 - st.rho || rhoNext >= 1.0) rhoNext = 1.0;
    delta = rhoNext - st.rho;
    info.exponent = rhoNext;
    info.coefficientOfVariation = weightCoefficientOfVariation(ll, delta);

    // Step 2: weights and evidence. a_k = Delta l_k, W = sum exp(a_k - a*).
    const double aMax = delta * info.maxLogLikelihood;
    Eigen::VectorXd wbar(N);
    double W = 0.0;
    for (int k = 0; k < N; ++k) W += (wbar[k] = ll[k] > -kInf ? std::exp(delta * ll[k] - aMax) : 0.0);
    info.logEvidenceIncrement = std::log(W / N) + aMax;
    wbar /= W;
    double sumSq = 0.0;
    for (int k = 0; k < N; ++k) sumSq += wbar[k] * wbar[k];
    info.effectiveSampleSize = 1.0 / sumSq;

    // Step 4: multinomial resampling (own stream per stage).
    Rng resampler(opt.seed, kResampling, static_cast<std::uint64_t>(stage), 0);
    const std::vector<int> counts = multinomialCounts(wbar, N, resampler);
    info.uniqueSelections = static_cast<int>(std::count_if(counts.begin(), counts.end(), [](int c) { return c > 0; }));

    // Step 3: proposal covariance and its Cholesky factor.
    const Eigen::MatrixXd sigma = proposalCovariance(st.pop.theta, wbar, counts, opt);
    const Eigen::MatrixXd L = choleskyWithJitter(sigma, info.covarianceJitter, stage);

    // Step 5: chains.
    Population next{Eigen::MatrixXd(st.pop.theta.rows(), N), Eigen::VectorXd(N), Eigen::VectorXd(N)};
    const std::vector<Chain> chains = buildChains(counts, opt.maxChainLength);
    const int burnIn = burnInForStage(opt, stage);
    const ChainStats cs = problem.batchLogLikelihood
                              ? runChainsBatched(problem, opt, st.pop, chains, L, rhoNext, burnIn, stage, next)
                              : runChainsPerSample(problem, opt, st.pop, chains, L, rhoNext, burnIn, stage, next);
    info.acceptanceRate = cs.proposed > 0 ? static_cast<double>(cs.accepted) / static_cast<double>(cs.proposed) : 0.0;
    info.likelihoodEvaluations = cs.evaluations;

    st.pop = std::move(next);
    st.rho = rhoNext;
    st.logEvidence += info.logEvidenceIncrement;
    st.stage = stage;
    st.evaluations += cs.evaluations;
    return info;
}

/// Stage 0: N prior draws (stream per sample) and their log-likelihoods.
void priorStage(const TmcmcProblem& problem, const TmcmcOptions& opt, int n, RunState& st) {
    const int N = opt.populationSize;
    st.pop = Population{Eigen::MatrixXd(n, N), Eigen::VectorXd(N), Eigen::VectorXd(N)};
    parallelFor(N, [&](int k) {
        Rng rng(opt.seed, kPriorDraw, 0, static_cast<std::uint64_t>(k));
        const Eigen::VectorXd theta = problem.prior->sample(rng);
        if (theta.size() != n)
            throw InputError(fmt::format("TMCMC: the prior sampler returned {} coordinates, expected {}", theta.size(), n));
        st.pop.theta.col(k) = theta;
        st.pop.logPrior[k] = problem.prior->logDensity(theta);
    });
    std::vector<int> all(static_cast<std::size_t>(N));
    for (int k = 0; k < N; ++k) all[static_cast<std::size_t>(k)] = k;
    evaluateLogLikelihood(problem, st.pop.theta, all, st.pop.logLike, 0);
    st.evaluations = N;
}

// ------------------------------------------------------------------------------------------------
// Checkpoints: <dir>/tmcmc_checkpoint.json (options, counters, stage infos) + a binary file with
// the population, rho and log Z as raw native doubles (exact, and -inf survives). Both are
// written to temporary names and renamed, the header last, so a crash leaves the previous pair.

namespace fs = std::filesystem;
constexpr char kMagic[8] = {'T', 'R', 'B', 'C', 'T', 'M', 'C', '1'};
constexpr const char* kHeaderName = "tmcmc_checkpoint.json";

std::string binaryName(int stage) { return fmt::format("tmcmc_state_{:04d}.bin", stage); }

nlohmann::json numberToJson(double x) {
    if (std::isfinite(x)) return x;
    return std::isnan(x) ? "nan" : (x > 0 ? "inf" : "-inf");
}

double numberFromJson(const nlohmann::json& j) {
    if (j.is_number()) return j.get<double>();
    const std::string s = j.get<std::string>();
    return s == "inf" ? kInf : s == "-inf" ? -kInf : std::numeric_limits<double>::quiet_NaN();
}

nlohmann::json optionsToJson(const TmcmcOptions& o, int n) {
    return {{"dimension", n},
            {"populationSize", o.populationSize},
            {"targetCoV", o.targetCoV},
            {"covarianceScaling", o.covarianceScaling},
            {"maxChainLength", o.maxChainLength},
            {"burnIn", o.burnIn},
            {"minIncrement", o.minIncrement},
            {"bisectionTolerance", o.bisectionTolerance},
            {"proposalCovariance", o.proposalCovariance == ProposalCovariance::Weighted ? "Weighted" : "SelectionCounts"},
            {"seed", o.seed}};
}

nlohmann::json stageToJson(const TmcmcStageInfo& s) {
    return {{"stage", s.stage},
            {"exponent", numberToJson(s.exponent)},
            {"coefficientOfVariation", numberToJson(s.coefficientOfVariation)},
            {"acceptanceRate", numberToJson(s.acceptanceRate)},
            {"uniqueSelections", s.uniqueSelections},
            {"effectiveSampleSize", numberToJson(s.effectiveSampleSize)},
            {"maxLogLikelihood", numberToJson(s.maxLogLikelihood)},
            {"logEvidenceIncrement", numberToJson(s.logEvidenceIncrement)},
            {"covarianceJitter", numberToJson(s.covarianceJitter)},
            {"likelihoodEvaluations", s.likelihoodEvaluations},
            {"elapsedSeconds", numberToJson(s.elapsedSeconds)}};
}

TmcmcStageInfo stageFromJson(const nlohmann::json& j) {
    TmcmcStageInfo s;
    s.stage = j.at("stage").get<int>();
    s.exponent = numberFromJson(j.at("exponent"));
    s.coefficientOfVariation = numberFromJson(j.at("coefficientOfVariation"));
    s.acceptanceRate = numberFromJson(j.at("acceptanceRate"));
    s.uniqueSelections = j.at("uniqueSelections").get<int>();
    s.effectiveSampleSize = numberFromJson(j.at("effectiveSampleSize"));
    s.maxLogLikelihood = numberFromJson(j.at("maxLogLikelihood"));
    s.logEvidenceIncrement = numberFromJson(j.at("logEvidenceIncrement"));
    s.covarianceJitter = numberFromJson(j.at("covarianceJitter"));
    s.likelihoodEvaluations = j.at("likelihoodEvaluations").get<long long>();
    s.elapsedSeconds = numberFromJson(j.at("elapsedSeconds"));
    return s;
}

template <class T>
void appendRaw(std::string& bytes, const T* data, std::size_t count) {
    bytes.append(reinterpret_cast<const char*>(data), sizeof(T) * count);
}

/// Reads `count` values at `offset` of `bytes`; false when the bytes end first.
template <class T>
bool takeRaw(const std::string& bytes, std::size_t& offset, T* data, std::size_t count) {
    const std::size_t size = sizeof(T) * count;
    if (bytes.size() < offset || bytes.size() - offset < size) return false;
    std::memcpy(data, bytes.data() + offset, size);
    offset += size;
    return true;
}

/// The header's own checksum: FNV-1a of its JSON text without the "checksum" key.
std::string headerChecksum(nlohmann::json h) {
    h.erase("checksum");
    return fmt::format("{:016x}", fnv1a(h.dump()));
}

// Both files carry an FNV-1a checksum (core/hash.hpp): the binary's in the header
// ("dataChecksum"), the header's in itself ("checksum"), so that one flipped bit in either is
// seen and the run starts afresh instead of resuming from a wrong population.
void writeCheckpoint(const TmcmcOptions& opt, const RunState& st) {
    const fs::path dir(opt.checkpointDirectory);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw IoError(fmt::format("TMCMC checkpoint: cannot create directory '{}': {}", dir.string(), ec.message()));
    const int n = static_cast<int>(st.pop.theta.rows()), N = static_cast<int>(st.pop.theta.cols());

    const fs::path bin = dir / binaryName(st.stage);
    std::string bytes(kMagic, sizeof kMagic);
    const std::int64_t header[3] = {n, N, st.stage};
    const double scalars[2] = {st.rho, st.logEvidence};
    appendRaw(bytes, header, 3);
    appendRaw(bytes, scalars, 2);
    appendRaw(bytes, st.pop.theta.data(), static_cast<std::size_t>(n) * static_cast<std::size_t>(N));
    appendRaw(bytes, st.pop.logLike.data(), static_cast<std::size_t>(N));
    appendRaw(bytes, st.pop.logPrior.data(), static_cast<std::size_t>(N));
    writeFileAtomically(bin, bytes);

    nlohmann::json h;
    h["format"] = "trbc-tmcmc-checkpoint";
    h["version"] = 2;
    h["options"] = optionsToJson(opt, n);
    h["stage"] = st.stage;
    h["exponent"] = numberToJson(st.rho);               // informative; the exact values are in the binary file
    h["logEvidence"] = numberToJson(st.logEvidence);
    h["likelihoodEvaluations"] = st.evaluations;
    h["dataFile"] = bin.filename().string();
    h["dataChecksum"] = fmt::format("{:016x}", fnv1a(bytes));
    h["stages"] = nlohmann::json::array();
    for (const auto& s : st.stages) h["stages"].push_back(stageToJson(s));
    h["checksum"] = headerChecksum(h);
    writeFileAtomically(dir / kHeaderName, h.dump(1) + "\n");
    if (st.stage > 0) fs::remove(dir / binaryName(st.stage - 1), ec);  // superseded
}

/// Loads the checkpoint if there is one (false if none, or if it is damaged: reported, and the
/// run starts afresh); throws InputError when it was written by a run with different options.
bool readCheckpoint(const TmcmcOptions& opt, int n, RunState& st) {
    const fs::path dir(opt.checkpointDirectory), hdr = dir / kHeaderName;
    if (!fs::exists(hdr)) return false;
    const auto damaged = [&](const std::string& why) {
        logMessage(LogLevel::Warning, fmt::format("TMCMC resume: the checkpoint in '{}' is damaged ({}); starting afresh", dir.string(), why));
        return false;
    };
    const nlohmann::json h = nlohmann::json::parse(readFileBytes(hdr), nullptr, false);
    if (h.is_discarded() || !h.is_object()) return damaged(hdr.filename().string() + " is not valid JSON");
    if (h.value("format", "") != "trbc-tmcmc-checkpoint" || h.value("version", 0) != 2 || !h.contains("checksum") ||
        !h["checksum"].is_string() || h["checksum"].get<std::string>() != headerChecksum(h))
        return damaged(hdr.filename().string() + ": checksum mismatch or an older format");
    const nlohmann::json expected = optionsToJson(opt, n), stored = h.at("options");
    for (const auto& [key, value] : expected.items())
        if (!stored.contains(key) || stored.at(key) != value)
            throw InputError(fmt::format("TMCMC resume: the checkpoint in '{}' was written with {} = {}, the options "
                                         "give {}; resume needs identical settings", dir.string(), key,
                                         stored.contains(key) ? stored.at(key).dump() : "(missing)", value.dump()));
    const int N = opt.populationSize;
    const std::string dataFile = h.at("dataFile").get<std::string>();
    if (dataFile.find('/') != std::string::npos) return damaged("dataFile names another directory");
    const fs::path bin = dir / dataFile;
    const std::string bytes = fs::is_regular_file(bin) ? readFileBytes(bin) : std::string();
    if (h.value("dataChecksum", "") != fmt::format("{:016x}", fnv1a(bytes)))
        return damaged(bin.filename().string() + ": missing or checksum mismatch");
    char magic[8];
    std::int64_t header[3];
    double scalars[2];
    std::size_t offset = 0;
    if (!takeRaw(bytes, offset, magic, 8) || !takeRaw(bytes, offset, header, 3) || !takeRaw(bytes, offset, scalars, 2) ||
        !std::equal(magic, magic + 8, kMagic) || header[0] != n || header[1] != N || header[2] != h.at("stage").get<int>())
        return damaged(bin.filename().string() + " does not match its header");
    RunState loaded;
    loaded.pop = Population{Eigen::MatrixXd(n, N), Eigen::VectorXd(N), Eigen::VectorXd(N)};
    if (!takeRaw(bytes, offset, loaded.pop.theta.data(), static_cast<std::size_t>(n) * static_cast<std::size_t>(N)) ||
        !takeRaw(bytes, offset, loaded.pop.logLike.data(), static_cast<std::size_t>(N)) ||
        !takeRaw(bytes, offset, loaded.pop.logPrior.data(), static_cast<std::size_t>(N)) || offset != bytes.size())
        return damaged(bin.filename().string() + " is truncated");
    loaded.rho = scalars[0];
    loaded.logEvidence = scalars[1];
    loaded.stage = static_cast<int>(header[2]);
    loaded.evaluations = h.at("likelihoodEvaluations").get<long long>();
    for (const auto& s : h.at("stages")) loaded.stages.push_back(stageFromJson(s));
    st = std::move(loaded);
    return true;
}

void validateProblem(const TmcmcProblem& problem) {
    if (!problem.prior) throw InputError("TMCMC problem: prior is null");
    if (problem.prior->dimension() < 1)
        throw InputError(fmt::format("TMCMC problem: prior dimension = {} is invalid: must be >= 1", problem.prior->dimension()));
    if (!problem.logLikelihood && !problem.batchLogLikelihood)
        throw InputError("TMCMC problem: no likelihood: set logLikelihood or batchLogLikelihood");
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Public building blocks

double weightCoefficientOfVariation(const Eigen::VectorXd& logLikelihood, double delta) {
    const Eigen::Index N = logLikelihood.size();
    const double lMax = maxFinite(logLikelihood);
    Eigen::VectorXd w(N);
    double sum = 0.0;
    for (Eigen::Index k = 0; k < N; ++k)
        sum += (w[k] = logLikelihood[k] > -kInf ? std::exp(delta * (logLikelihood[k] - lMax)) : 0.0);
    const double mean = sum / static_cast<double>(N);
    double ss = 0.0;
    for (Eigen::Index k = 0; k < N; ++k) ss += (w[k] - mean) * (w[k] - mean);
    return std::sqrt(ss / static_cast<double>(N - 1)) / mean;
}

double nextTemperingIncrement(const Eigen::VectorXd& logLikelihood, double rho, double targetCoV, double tolerance) {
    const double full = 1.0 - rho;
    if (weightCoefficientOfVariation(logLikelihood, full) <= targetCoV) return full;
    // CoV is increasing in Delta: bisection on [0, 1 - rho] to relative width `tolerance`. The
    // iteration cap only matters when the root tends to 0 (e.g. zero-likelihood samples make
    // CoV(0+) > target); Delta_min then takes over.
    double lo = 0.0, hi = full;
    for (int it = 0; it < 200 && hi - lo > tolerance * hi; ++it) {
        const double mid = 0.5 * (lo + hi);
        (weightCoefficientOfVariation(logLikelihood, mid) > targetCoV ? hi : lo) = mid;
    }
    return 0.5 * (lo + hi);
}

std::vector<int> multinomialCounts(const Eigen::VectorXd& weights, int n, Rng& rng) {
    const Eigen::Index K = weights.size();
    std::vector<int> counts(static_cast<std::size_t>(K), 0);
    double total = 0.0;
    Eigen::Index lastPositive = -1;
    for (Eigen::Index k = 0; k < K; ++k) {
        if (!(weights[k] >= 0.0) || !std::isfinite(weights[k]))
            throw NumericalError(fmt::format("multinomial resampling: weight {} = {} is not finite and >= 0", k, weights[k]));
        total += weights[k];
        if (weights[k] > 0.0) lastPositive = k;
    }
    if (lastPositive < 0) throw NumericalError("multinomial resampling: all weights are zero");
    // n sorted uniforms u_(i) = S_i / S_{n+1}, S_i = sum of i standard exponentials.
    std::vector<double> u(static_cast<std::size_t>(n));
    double S = 0.0;
    for (int i = 0; i < n; ++i) u[static_cast<std::size_t>(i)] = (S += -std::log(rng.uniformOpen()));
    S += -std::log(rng.uniformOpen());
    Eigen::Index k = 0;
    double cumulative = weights[0] / total;
    for (int i = 0; i < n; ++i) {
        const double ui = u[static_cast<std::size_t>(i)] / S;
        // Advance while u >= c_k; zero-weight k have c_k = c_{k-1} <= u and are skipped.
        while (k < lastPositive && ui >= cumulative) cumulative += weights[++k] / total;
        ++counts[static_cast<std::size_t>(k)];
    }
    return counts;
}

void validateTmcmcOptions(const TmcmcOptions& o) {
    auto bad = [](const char* name, auto value, const char* range) {
        throw InputError(fmt::format("TMCMC option {} = {} is invalid: {}", name, value, range));
    };
    if (o.populationSize < 2) bad("populationSize", o.populationSize, "must be an integer >= 2");
    if (!(o.targetCoV > 0.0 && std::isfinite(o.targetCoV))) bad("targetCoV", o.targetCoV, "must be > 0 and finite");
    if (!(o.covarianceScaling > 0.0 && std::isfinite(o.covarianceScaling)))
        bad("covarianceScaling", o.covarianceScaling, "must be > 0 and finite (beta^2)");
    if (o.maxChainLength < 0) bad("maxChainLength", o.maxChainLength, "must be >= 0 (1 = BASIS, 0 = unlimited)");
    for (int b : o.burnIn)
        if (b < 0) bad("burnIn", b, "every entry must be >= 0");
    if (!(o.minIncrement > 0.0 && o.minIncrement <= 1.0)) bad("minIncrement", o.minIncrement, "must be in (0, 1]");
    if (!(o.bisectionTolerance > 0.0 && o.bisectionTolerance < 1.0))
        bad("bisectionTolerance", o.bisectionTolerance, "must be in (0, 1)");
    if (o.maxStages < 0) bad("maxStages", o.maxStages, "must be >= 0 (0 = no limit)");
    if (o.resume && o.checkpointDirectory.empty())
        throw InputError("TMCMC option resume = true is invalid: it needs a checkpointDirectory");
}

// ------------------------------------------------------------------------------------------------
// Driver

TmcmcResult runTmcmc(const TmcmcProblem& problem, const TmcmcOptions& opt) {
    validateTmcmcOptions(opt);
    validateProblem(problem);
    const auto start = Clock::now();
    const int n = problem.prior->dimension();
    const bool checkpoints = !opt.checkpointDirectory.empty();

    RunState st;
    if (!(opt.resume && readCheckpoint(opt, n, st))) {
        priorStage(problem, opt, n, st);
        if (checkpoints) writeCheckpoint(opt, st);
    }
    while (st.rho < 1.0 && (opt.maxStages == 0 || st.stage < opt.maxStages)) {
        TmcmcStageInfo info = annealingStage(problem, opt, st);
        info.elapsedSeconds = std::chrono::duration<double>(Clock::now() - start).count();
        st.stages.push_back(info);
        if (checkpoints) writeCheckpoint(opt, st);
        if (opt.onStage) opt.onStage(info);
    }

    TmcmcResult r;
    r.samples = std::move(st.pop.theta);
    r.logLikelihood = std::move(st.pop.logLike);
    r.logPrior = std::move(st.pop.logPrior);
    r.logEvidence = st.logEvidence;
    r.exponent = st.rho;
    r.completed = st.rho >= 1.0;
    r.likelihoodEvaluations = st.evaluations;
    r.stages = std::move(st.stages);
    return r;
}

Tmcmc::Tmcmc(TmcmcOptions options) : options_(std::move(options)) { validateTmcmcOptions(options_); }

}  // namespace trbc
