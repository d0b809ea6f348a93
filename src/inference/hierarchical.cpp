// The population sums vectorise only if floating-point operations may be executed speculatively
// (if-conversion of the branch-free selects in population_kernels.hpp); nothing here relies on
// floating-point traps.
#pragma GCC optimize("no-trapping-math")
#include "inference/hierarchical.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <numeric>

#include "core/error.hpp"
#include "inference/population_kernels.hpp"

// The population sums in AVX-512 with 512-bit vectors where the build machine has it (after the
// includes: Eigen's packet code stays AVX2, see model.cpp): 18 % off the 50,000-sample inference.
#if defined(TRBC_AVX512_KERNELS) && defined(__GNUC__) && !defined(__clang__)
#pragma GCC target("avx512f,avx512vl,avx512dq,avx512bw,avx512cd,prefer-vector-width=512")
#endif

namespace trbc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
using Clock = std::chrono::steady_clock;

/// OpenMP loop over [0, count) with a per-thread buffer of `bufferSize` doubles; carries the first
/// exception out of the parallel region. Each iteration writes only its own slot, and every
/// candidate's sum runs serially in a fixed order, so results do not depend on the thread count.
template <class Body>
void parallelFor(Eigen::Index count, Eigen::Index bufferSize, Body&& body) {
    std::exception_ptr error;
    // Small jobs stay on the calling thread: starting a team costs far more than they do when the
    // cores are shared (single queries, tests).
    const bool parallel = count > 1 && count * std::max<Eigen::Index>(bufferSize, 1) >= 200000;
#pragma omp parallel if (parallel)
    {
        std::vector<double> buffer(static_cast<std::size_t>(std::max<Eigen::Index>(bufferSize, 1)));
#pragma omp for schedule(dynamic, 1)
        for (Eigen::Index i = 0; i < count; ++i) {
            try {
                body(i, buffer.data());
            } catch (...) {
#pragma omp critical(trbc_hierarchical_error)
                if (!error) error = std::current_exception();
            }
        }
    }
    if (error) std::rethrow_exception(error);
}

/// q(z) in the precision of the rule: Fvk = 1 double, 2 mixed (see population_kernels.hpp).
template <int Fvk>
[[gnu::always_inline]] inline double fvkTerm(double z, const detail::FvkCoefficients& c) {
    if constexpr (Fvk == 1) return detail::logFvkDensityCore(z, c);
    else return detail::logFvkDensityCoreMixed(z, c);
}

/// Phase 2 term loop: L_k = lw_k - C - sum_j ((x_jk - mean_j) invSd_j)^2 / 2 [+ log q(z_k)], then
/// log sum_k exp(L_k)   (4.3-4.4). x[j] points to coordinate j of all K samples. Fvk: 0 no q term,
/// 1 q in double, 2 q in mixed precision.
template <int G, int Fvk>
double reweightingSum(const double* const* x, const double* z, const double* lw, Eigen::Index K, const double* mean,
                      const double* invSd, double C, const detail::FvkCoefficients& fc, double* L) {
#pragma omp simd
    for (Eigen::Index k = 0; k < K; ++k) {
        double g = lw[k] - C;
        for (int j = 0; j < G; ++j) {
            const double u = (x[j][k] - mean[j]) * invSd[j];
            g -= 0.5 * u * u;
        }
        if constexpr (Fvk > 0) g += fvkTerm<Fvk>(z[k], fc);
        L[k] = g;
    }
    return detail::logSumExp(L, K);
}

/// Phase 3 term loop over the mixture components u: L_u = c_u - sum_j ((x_j - mean_ju) invSd_ju)^2 / 2
/// [+ log q(z | psi_u)], then log sum_u exp(L_u)   (4.5-4.6).
/// fa: the 7 coefficient arrays of q (muX, vx, ivx, muY, vy, ivy, logC), or null. Fvk as above.
template <int G, int Fvk>
double mixtureSum(const double* x, double z, const double* const* mean, const double* const* invSd, const double* c, Eigen::Index U,
                  const double* const* fa, double* L) {
    const double *mx = nullptr, *vx = nullptr, *ivx = nullptr, *my = nullptr, *vy = nullptr, *ivy = nullptr, *lc = nullptr;
    if constexpr (Fvk > 0) mx = fa[0], vx = fa[1], ivx = fa[2], my = fa[3], vy = fa[4], ivy = fa[5], lc = fa[6];
#pragma omp simd
    for (Eigen::Index u = 0; u < U; ++u) {
        double g = c[u];
        for (int j = 0; j < G; ++j) {
            const double w = (x[j] - mean[j][u]) * invSd[j][u];
            g -= 0.5 * w * w;
        }
        if constexpr (Fvk > 0) g += fvkTerm<Fvk>(z, {mx[u], vx[u], ivx[u], my[u], vy[u], ivy[u], lc[u]});
        L[u] = g;
    }
    return detail::logSumExp(L, U);
}

/// Pooled index of each Gaussian coordinate of a data set's layout; the equilibrium FvK is extra.
std::vector<int> gaussianCoordinates(RbcExperiment e) {
    switch (e) {
        case RbcExperiment::Equilibrium: return {kPooledV};
        case RbcExperiment::Stretching: return {kPooledV, kPooledMu, kPooledKb, kPooledB2};
        case RbcExperiment::Relaxation: return {kPooledR};
        case RbcExperiment::Flow: break;  // the re-weighting route takes no flow data (validateRbcInference)
    }
    throw InputError("the re-weighting route has no population layout for flow data sets; use the joint method");
}

}  // namespace

DistinctColumns distinctColumns(const Eigen::MatrixXd& x) {
    const Eigen::Index n = x.cols(), d = x.rows();
    std::vector<Eigen::Index> order(static_cast<std::size_t>(n));
    std::iota(order.begin(), order.end(), Eigen::Index{0});
    auto less = [&](Eigen::Index a, Eigen::Index b) {
        for (Eigen::Index j = 0; j < d; ++j)
            if (x(j, a) != x(j, b)) return x(j, a) < x(j, b);
        return a < b;
    };
    std::sort(order.begin(), order.end(), less);
    // Groups of equal columns; each group is represented by its first (smallest) index.
    std::vector<Eigen::Index> rep(static_cast<std::size_t>(n));
    for (std::size_t k = 0; k < order.size(); ++k) {
        const bool same = k > 0 && (x.col(order[k]).array() == x.col(order[k - 1]).array()).all();
        rep[static_cast<std::size_t>(order[k])] = same ? rep[static_cast<std::size_t>(order[k - 1])] : order[k];
    }
    DistinctColumns r;
    r.index.resize(static_cast<std::size_t>(n));
    std::vector<Eigen::Index> slot(static_cast<std::size_t>(n), -1), firsts;
    for (Eigen::Index k = 0; k < n; ++k) {  // order of first appearance
        Eigen::Index& s = slot[static_cast<std::size_t>(rep[static_cast<std::size_t>(k)])];
        if (s < 0) {
            s = static_cast<Eigen::Index>(firsts.size());
            firsts.push_back(k);
            r.count.push_back(0);
        }
        r.index[static_cast<std::size_t>(k)] = s;
        ++r.count[static_cast<std::size_t>(s)];
    }
    r.columns.resize(d, static_cast<Eigen::Index>(firsts.size()));
    for (std::size_t u = 0; u < firsts.size(); ++u) r.columns.col(static_cast<Eigen::Index>(u)) = x.col(firsts[u]);
    return r;
}

int pooledCoordinateCount(RbcExperiment e) {
    return e == RbcExperiment::Equilibrium ? 2 : e == RbcExperiment::Stretching ? 4 : e == RbcExperiment::Flow ? 5 : 1;
}

// ------------------------------------------------------------------------------------------------
// Phase-1 samples for the re-weighting

namespace {

/// Bins of width <= kBinWidth over the sorted 1-D samples and their weighted moments about the bin
/// centre (see ReweightingSamples).
void buildHermiteBins(ReweightingSamples& r) {
    constexpr int P = ReweightingSamples::kHermiteTerms;
    const Eigen::Index K = r.x.cols();
    r.bins.clear();
    for (Eigen::Index k = 0; k < K;) {
        Eigen::Index e = k + 1;
        while (e < K && r.x(0, e) - r.x(0, k) <= ReweightingSamples::kBinWidth) ++e;
        ReweightingSamples::Bin b;
        b.first = k;
        b.last = e;
        b.centre = 0.5 * (r.x(0, k) + r.x(0, e - 1));
        b.logScale = r.logWeight.segment(k, e - k).maxCoeff();
        r.bins.push_back(b);
        k = e;
    }
    r.moments = Eigen::MatrixXd::Zero(P, static_cast<Eigen::Index>(r.bins.size()));
    for (std::size_t b = 0; b < r.bins.size(); ++b) {
        const ReweightingSamples::Bin& bin = r.bins[b];
        for (Eigen::Index k = bin.first; k < bin.last; ++k) {
            const double w = std::exp(r.logWeight[k] - bin.logScale), delta = r.x(0, k) - bin.centre;
            double p = w;
            for (int n = 0; n < P; ++n, p *= delta) r.moments(n, static_cast<Eigen::Index>(b)) += p;
        }
    }
}

/// log sum_k w_k exp(-((x_k - mu)/sd)^2 / 2) of one bin, directly.
double binDirect(const ReweightingSamples& r, const ReweightingSamples::Bin& bin, double mu, double invSd) {
    double mx = -kInf;
    for (Eigen::Index k = bin.first; k < bin.last; ++k) {
        const double u = (r.x(0, k) - mu) * invSd;
        mx = std::max(mx, r.logWeight[k] - 0.5 * u * u);
    }
    double sum = 0.0;
    for (Eigen::Index k = bin.first; k < bin.last; ++k) {
        const double u = (r.x(0, k) - mu) * invSd;
        sum += std::exp(r.logWeight[k] - 0.5 * u * u - mx);
    }
    return mx + std::log(sum);
}

/// log sum_k w_k exp(-((x_k - mu)/sd)^2 / 2) by the Hermite expansion per bin (1-D fast Gauss
/// transform): e^{-a^2/2} sum_n He_n(a) (-1/sd)^n / n! mu_bn, a = (c_b - mu)/sd, He_{n+1} = a He_n - n He_{n-1}.
double hermiteSum(const ReweightingSamples& r, double mu, double sd, double* L) {
    constexpr int P = ReweightingSamples::kHermiteTerms;
    const double invSd = 1.0 / sd, rho = -invSd;
    const Eigen::Index B = static_cast<Eigen::Index>(r.bins.size());
    for (Eigen::Index b = 0; b < B; ++b) {
        const ReweightingSamples::Bin& bin = r.bins[static_cast<std::size_t>(b)];
        const double a = (bin.centre - mu) * invSd;
        double S = -1.0;
        if (std::abs(a) <= 30.0) {
            const double* m = r.moments.col(b).data();
            double hPrev = 1.0, h = a, coef = 1.0;  // He_{n-1}, He_n; (-1/sd)^n / n!
            S = m[0];
            for (int n = 1; n < P; ++n) {
                coef *= rho / n;
                S += h * coef * m[n];
                const double next = a * h - n * hPrev;  // He_{n+1} = a He_n - n He_{n-1}
                hPrev = h;
                h = next;
            }
        }
        L[b] = S > 0.0 ? bin.logScale - 0.5 * a * a + std::log(S) : binDirect(r, bin, mu, invSd);
    }
    return detail::logSumExp(L, B);
}

}  // namespace

ReweightingSamples reweightingSamples(const RbcDataSet& data, const Eigen::MatrixXd& samples) {
    const int d = pooledCoordinateCount(data.experiment);
    const auto prior = phase1Prior(data);
    if (samples.rows() != prior->dimension())
        throw InputError(fmt::format("phase-1 samples of {}: {} rows, expected {}", data.name, samples.rows(), prior->dimension()));
    const Eigen::Index N = samples.cols();
    if (N < 1) throw InputError(fmt::format("phase-1 samples of {}: none", data.name));
    // Group identical pooled coordinates (lexicographic sort, ties by index: deterministic).
    std::vector<Eigen::Index> order(static_cast<std::size_t>(N));
    std::iota(order.begin(), order.end(), Eigen::Index{0});
    std::sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) {
        for (int j = 0; j < d; ++j)
            if (samples(j, a) != samples(j, b)) return samples(j, a) < samples(j, b);
        return a < b;
    });
    ReweightingSamples r;
    r.experiment = data.experiment;
    r.total = N;
    std::vector<Eigen::Index> first;
    std::vector<double> count;
    for (std::size_t k = 0; k < order.size(); ++k) {
        const bool same = k > 0 && (samples.col(order[k]).head(d).array() == samples.col(order[k - 1]).head(d).array()).all();
        if (same)
            count.back() += 1.0;
        else {
            first.push_back(order[k]);
            count.push_back(1.0);
        }
    }
    const Eigen::Index K = static_cast<Eigen::Index>(first.size());
    r.x.resize(d, K);
    r.logWeight.resize(K);
    for (Eigen::Index k = 0; k < K; ++k) {
        const Eigen::Index c = first[static_cast<std::size_t>(k)];
        double logPi = 0.0;  // phase-1 prior density of the pooled coordinates (uniform, ratio-uniform)
        for (int j = 0; j < d; ++j) logPi += prior->component(j).logDensity(samples(j, c));
        if (!(logPi > -kInf))
            throw InputError(fmt::format("phase-1 sample {} of {} lies outside the phase-1 prior support", c, data.name));
        r.x.col(k) = samples.col(c).head(d);
        r.logWeight[k] = std::log(count[static_cast<std::size_t>(k)] / static_cast<double>(N)) - logPi;
    }
    if (d == 1) buildHermiteBins(r);
    return r;
}

// ------------------------------------------------------------------------------------------------
// Phase 2

Eigen::VectorXd logReweightingFactors(const ReweightingSamples& s, const Eigen::MatrixXd& psi, FvkDensityRule rule,
                                      PopulationTimer* timer) {
    if (psi.rows() != kHyperDimension)
        throw InputError(fmt::format("log b_i: psi needs {} rows, got {}", kHyperDimension, psi.rows()));
    const auto t0 = Clock::now();
    const std::vector<int> coords = gaussianCoordinates(s.experiment);
    const int G = static_cast<int>(coords.size());
    const bool fvk = s.experiment == RbcExperiment::Equilibrium;
    const Eigen::Index K = s.x.cols();
    const Eigen::MatrixXd xt = s.x.transpose();  // K x d: each coordinate contiguous
    Eigen::VectorXd out(psi.cols());
    const double* x[kPooledDimension] = {};
    for (int j = 0; j < G; ++j) x[j] = xt.col(j).data();
    const double* z = fvk ? xt.col(1).data() : nullptr;
    const double* lw = s.logWeight.data();
    parallelFor(psi.cols(), K, [&](Eigen::Index b, double* L) {
        // log b = log sum_k exp( log w_k + sum_j log N/TN(x_jk; psi) [+ log q(FvK_k | psi)] )   (4.3-4.4)
        double mean[kPooledDimension] = {}, invSd[kPooledDimension] = {}, logNorm = 0.0;
        for (int j = 0; j < G; ++j) {
            const NormalFactor f = populationFactor(coords[static_cast<std::size_t>(j)], psi.col(b));
            mean[j] = f.mean;
            invSd[j] = 1.0 / f.sd;
            logNorm += f.logNorm;  // samples lie in the phase-1 box, inside every truncation interval
        }
        if (!fvk) {
            if (G == 1 && !s.bins.empty() && 1.0 / invSd[0] >= 10.0 * ReweightingSamples::kBinWidth)
                out[b] = hermiteSum(s, mean[0], 1.0 / invSd[0], L) - logNorm;  // |d| <= 0.05
            else
                out[b] = G == 1 ? reweightingSum<1, 0>(x, z, lw, K, mean, invSd, logNorm, {}, L)
                                : reweightingSum<4, 0>(x, z, lw, K, mean, invSd, logNorm, {}, L);
            if (!std::isfinite(out[b])) out[b] = -kInf;
            return;
        }
        const RatioDensityParameters rp = fvkDensityParameters(psi.col(b));
        if (rule != FvkDensityRule::Nodes50) {
            const detail::FvkCoefficients fc = detail::fvkCoefficients(rp.muX, rp.sdX, rp.muY, rp.sdY, rp.logZy);
            out[b] = rule == FvkDensityRule::ClosedForm ? reweightingSum<1, 2>(x, z, lw, K, mean, invSd, logNorm, fc, L)
                                                        : reweightingSum<1, 1>(x, z, lw, K, mean, invSd, logNorm, fc, L);
            return;
        }
        for (Eigen::Index k = 0; k < K; ++k) {  // 50-node rule (compatibility): scalar
            const double u = (x[0][k] - mean[0]) * invSd[0];
            L[k] = lw[k] - logNorm - 0.5 * u * u + logFvkDensityNodes50(z[k], rp);
        }
        out[b] = detail::logSumExp(L, K);
    });
    if (timer) {
        timer->seconds += std::chrono::duration<double>(Clock::now() - t0).count();
        timer->terms += static_cast<long long>(K) * psi.cols();
    }
    return out;
}

TmcmcProblem phase2Problem(std::vector<ReweightingSamples> sets, FvkDensityRule rule, std::shared_ptr<PopulationTimer> timer) {
    if (sets.empty()) throw InputError("phase 2 needs the phase-1 samples of at least one data set");
    TmcmcProblem p;
    p.prior = hyperPrior();
    auto shared = std::make_shared<const std::vector<ReweightingSamples>>(std::move(sets));
    p.batchLogLikelihood = [shared, rule, timer](const Eigen::MatrixXd& psi) {
        Eigen::VectorXd ll = Eigen::VectorXd::Zero(psi.cols());
        for (const ReweightingSamples& s : *shared) ll += logReweightingFactors(s, psi, rule, timer.get());  // prod_i b_i
        for (Eigen::Index i = 0; i < ll.size(); ++i)
            if (!std::isfinite(ll[i])) ll[i] = -kInf;
        return ll;
    };
    return p;
}

// ------------------------------------------------------------------------------------------------
// Mixtures (phase 3)

PopulationMixture::PopulationMixture(Layout layout, const Eigen::MatrixXd& psiAll, const Eigen::VectorXd& logOffset,
                                     FvkDensityRule rule, Eigen::Index fvkFrom)
    : rule_(rule), M_(psiAll.cols()) {
    if (psiAll.rows() != kHyperDimension)
        throw InputError(fmt::format("population mixture: psi needs {} rows, got {}", kHyperDimension, psiAll.rows()));
    if (M_ < 1) throw InputError("population mixture: no phase-2 samples");
    if (logOffset.size() != 0 && logOffset.size() != M_)
        throw InputError(fmt::format("population mixture: {} offsets for {} components", logOffset.size(), M_));
    // Merge identical (psi_m, c_m): (1/M) sum_m = (1/M) sum_u n_u (same terms, other order).
    Eigen::MatrixXd stacked(kHyperDimension + 1, M_);
    stacked.topRows(kHyperDimension) = psiAll;
    stacked.row(kHyperDimension) = logOffset.size() ? Eigen::RowVectorXd(logOffset.transpose()) : Eigen::RowVectorXd::Zero(M_);
    const DistinctColumns distinct = distinctColumns(stacked);
    const Eigen::MatrixXd psi = distinct.columns.topRows(kHyperDimension);
    const Eigen::Index U = psi.cols();
    switch (layout) {
        case Layout::NewCell: pooled_ = {kPooledV, kPooledMu, kPooledKb, kPooledB2, kPooledR}; break;
        case Layout::Equilibrium: pooled_ = gaussianCoordinates(RbcExperiment::Equilibrium); fvk_ = true; break;
        case Layout::Stretching: pooled_ = gaussianCoordinates(RbcExperiment::Stretching); break;
        case Layout::Relaxation: pooled_ = gaussianCoordinates(RbcExperiment::Relaxation); break;
    }
    const int G = static_cast<int>(pooled_.size());
    mean_.resize(U, G);
    invSd_.resize(U, G);
    c_.resize(U);
    for (Eigen::Index m = 0; m < U; ++m)
        c_[m] = distinct.columns(kHyperDimension, m) + std::log(static_cast<double>(distinct.count[static_cast<std::size_t>(m)]));
    for (Eigen::Index m = 0; m < U; ++m)
        for (int j = 0; j < G; ++j) {
            const NormalFactor f = populationFactor(pooled_[static_cast<std::size_t>(j)], psi.col(m));
            mean_(m, j) = f.mean;
            invSd_(m, j) = 1.0 / f.sd;
            c_[m] -= f.logNorm;
            if (m == 0) lo_.push_back(f.lo), hi_.push_back(f.hi);
        }
    if (!fvk_) return;
    if (fvkFrom >= 0) {
        if (fvkFrom >= M_) throw InputError(fmt::format("population mixture: no phase-2 sample {}", fvkFrom));
        fvkSingle_ = true;
        fvkSingleParameters_ = fvkDensityParameters(psiAll.col(fvkFrom));
        return;
    }
    fvkParameters_.resize(static_cast<std::size_t>(U));
    FvkArrays& a = fvkArrays_;
    for (Eigen::ArrayXd* v : {&a.muX, &a.vx, &a.ivx, &a.muY, &a.vy, &a.ivy, &a.logC}) v->resize(U);
    for (Eigen::Index m = 0; m < U; ++m) {
        const RatioDensityParameters p = fvkDensityParameters(psi.col(m));
        fvkParameters_[static_cast<std::size_t>(m)] = p;
        const detail::FvkCoefficients c = detail::fvkCoefficients(p.muX, p.sdX, p.muY, p.sdY, p.logZy);
        a.muX[m] = c.muX, a.vx[m] = c.vx, a.ivx[m] = c.ivx, a.muY[m] = c.muY, a.vy[m] = c.vy, a.ivy[m] = c.ivy, a.logC[m] = c.logC;
    }
}

double PopulationMixture::logMeanAt(const Eigen::Ref<const Eigen::VectorXd>& x) const {
    if (x.size() < dimension())
        throw InputError(fmt::format("population mixture: a query needs {} entries, got {}", dimension(), x.size()));
    const Eigen::MatrixXd one = x.head(dimension());  // the batched code path, one column
    return logMean(one)[0];
}

double PopulationMixture::exactLogMean(const double* q, double z, double* L) const {
    // log (1/M) sum_m exp(c_m - sum_j ((x_j - mean_jm) / sd_jm)^2 / 2 [+ log q(FvK | psi_m)])   (4.5, 4.6)
    const int G = static_cast<int>(pooled_.size());
    for (int j = 0; j < G; ++j)
        if (!(q[j] >= lo_[static_cast<std::size_t>(j)] && q[j] <= hi_[static_cast<std::size_t>(j)]))
            return -kInf;  // outside a truncation interval: zero density for every m
    if (fvk_ && !(z > 0.0)) return -kInf;
    const Eigen::Index U = c_.size();
    const double* mean[kPooledDimension] = {};
    const double* invSd[kPooledDimension] = {};
    for (int j = 0; j < G; ++j) mean[j] = mean_.col(j).data(), invSd[j] = invSd_.col(j).data();
    double r = -kInf;
    if (!fvk_ || fvkSingle_) {
        r = G == 1   ? mixtureSum<1, 0>(q, z, mean, invSd, c_.data(), U, nullptr, L)
            : G == 4 ? mixtureSum<4, 0>(q, z, mean, invSd, c_.data(), U, nullptr, L)
                     : mixtureSum<5, 0>(q, z, mean, invSd, c_.data(), U, nullptr, L);
        if (fvkSingle_) r += logFvkDensity(z, fvkSingleParameters_, rule_);  // the same factor for every m
    } else if (rule_ != FvkDensityRule::Nodes50) {
        const FvkArrays& a = fvkArrays_;
        const double* fa[7] = {a.muX.data(), a.vx.data(), a.ivx.data(), a.muY.data(), a.vy.data(), a.ivy.data(), a.logC.data()};
        r = rule_ == FvkDensityRule::ClosedForm ? mixtureSum<1, 2>(q, z, mean, invSd, c_.data(), U, fa, L)
                                                : mixtureSum<1, 1>(q, z, mean, invSd, c_.data(), U, fa, L);
    } else {
        for (Eigen::Index u = 0; u < U; ++u) {  // 50-node rule (compatibility): scalar
            const double w = (q[0] - mean[0][u]) * invSd[0][u];
            L[u] = c_[u] - 0.5 * w * w + logFvkDensityNodes50(z, fvkParameters_[static_cast<std::size_t>(u)]);
        }
        r = detail::logSumExp(L, U);
    }
    r -= std::log(static_cast<double>(M_));
    return std::isfinite(r) ? r : -kInf;
}

namespace {

/// 4-point Lagrange interpolation in a uniform table (nodes lo + i h); NaN if a node is not finite.
double interpolateTable(const Eigen::VectorXd& t, double lo, double h, double x) {
    const Eigen::Index G = t.size();
    const double f = (x - lo) / h;
    const Eigen::Index i = std::clamp<Eigen::Index>(static_cast<Eigen::Index>(std::floor(f)) - 1, 0, G - 4);
    const double u = f - static_cast<double>(i);  // position among the nodes i..i+3 (in [1, 2] inside)
    const double w0 = -(u - 1) * (u - 2) * (u - 3) / 6, w1 = u * (u - 2) * (u - 3) / 2, w2 = -u * (u - 1) * (u - 3) / 2,
                 w3 = u * (u - 1) * (u - 2) / 6;
    const double v = w0 * t[i] + w1 * t[i + 1] + w2 * t[i + 2] + w3 * t[i + 3];
    return std::isfinite(v) ? v : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

double PopulationMixture::tabulate(double lo, double hi, double h, double tolerance, PopulationTimer* timer) {
    if (dimension() != 1) throw InputError("population mixture: only one-dimensional layouts can be tabulated");
    if (!(hi > lo) || !(h > 0.0)) throw InputError(fmt::format("population mixture: bad table range [{}, {}] / step {}", lo, hi, h));
    const auto t0 = Clock::now();
    long long terms = 0;
    double error = kInf;
    table_.resize(0);
    for (int attempt = 0; attempt < 6; ++attempt, h *= 0.5) {
        const Eigen::Index G = std::max<Eigen::Index>(4, static_cast<Eigen::Index>(std::ceil((hi - lo) / h)) + 1);
        const double step = (hi - lo) / static_cast<double>(G - 1);
        Eigen::VectorXd t(G);
        parallelFor(G, c_.size(), [&](Eigen::Index g, double* L) {
            const double q = lo + static_cast<double>(g) * step;
            t[g] = exactLogMean(&q, 0.0, L);
        });
        // Check at the mid-points of 1000 cells spread over the range.
        const Eigen::Index checks = std::min<Eigen::Index>(1000, G - 1);
        Eigen::VectorXd exact(checks), approx(checks);
        parallelFor(checks, c_.size(), [&](Eigen::Index j, double* L) {
            const Eigen::Index cell = j * (G - 1) / checks;
            const double q = lo + (static_cast<double>(cell) + 0.5) * step;
            exact[j] = exactLogMean(&q, 0.0, L);
            approx[j] = interpolateTable(t, lo, step, q);
        });
        terms += static_cast<long long>(G + checks) * c_.size();
        const double top = t.maxCoeff();
        error = 0.0;
        for (Eigen::Index j = 0; j < checks; ++j)
            if (exact[j] > top - 40.0) error = std::max(error, std::isnan(approx[j]) ? kInf : std::abs(approx[j] - exact[j]));
        if (error <= tolerance) {
            table_ = std::move(t);
            tableLo_ = lo;
            tableH_ = step;
            break;
        }
    }
    if (timer) {
        timer->seconds += std::chrono::duration<double>(Clock::now() - t0).count();
        timer->terms += terms;
    }
    return error;
}

Eigen::VectorXd PopulationMixture::logMean(const Eigen::MatrixXd& x, PopulationTimer* timer) const {
    if (x.rows() < dimension())
        throw InputError(fmt::format("population mixture: queries need {} rows, got {}", dimension(), x.rows()));
    const auto t0 = Clock::now();
    const int G = static_cast<int>(pooled_.size());
    Eigen::VectorXd out(x.cols());
    std::atomic<long long> exactQueries{0};
    const double tableHi = tableLo_ + tableH_ * static_cast<double>(table_.size() - 1);
    parallelFor(x.cols(), c_.size(), [&](Eigen::Index i, double* L) {
        double q[kPooledDimension + 1] = {};
        for (int j = 0; j < G; ++j) q[j] = x(j, i);
        const double z = fvk_ ? x(G, i) : 0.0;
        if (tabulated() && q[0] >= tableLo_ && q[0] <= tableHi && q[0] >= lo_[0] && q[0] <= hi_[0]) {
            const double v = interpolateTable(table_, tableLo_, tableH_, q[0]);
            if (!std::isnan(v)) {
                out[i] = v;
                return;
            }
        }
        ++exactQueries;
        out[i] = exactLogMean(q, z, L);
    });
    if (timer) {
        timer->seconds += std::chrono::duration<double>(Clock::now() - t0).count();
        timer->terms += exactQueries.load() * c_.size();
    }
    return out;
}

TmcmcProblem phase3aProblem(const Eigen::MatrixXd& psi, std::shared_ptr<PopulationTimer> timer) {
    TmcmcProblem p;
    p.prior = newCellBoxPrior();
    auto mixture = std::make_shared<const PopulationMixture>(PopulationMixture::Layout::NewCell, psi);
    p.batchLogLikelihood = [mixture, timer](const Eigen::MatrixXd& theta) { return mixture->logMean(theta, timer.get()); };
    return p;
}

Eigen::MatrixXd sampleNewCellAncestral(const Eigen::MatrixXd& psi, Eigen::Index n, std::uint64_t seed) {
    if (psi.rows() != kHyperDimension || psi.cols() < 1)
        throw InputError(fmt::format("ancestral sampling: psi must be {} x M with M >= 1", kHyperDimension));
    const auto box = newCellBoxPrior();
    Rng rng(seed, 0x3a3a3a3a, 0, 0);
    Eigen::MatrixXd out(kPooledDimension, n);
    Eigen::VectorXd theta(kPooledDimension);
    const long long maxTries = 1000 * std::max<Eigen::Index>(n, 1);
    long long tries = 0;
    for (Eigen::Index k = 0; k < n;) {
        if (++tries > maxTries)
            throw NumericalError("ancestral sampling of theta_new: fewer than 1 in 1000 draws fall inside the box of 4.5");
        const Eigen::Index m = std::min<Eigen::Index>(static_cast<Eigen::Index>(rng.uniform() * static_cast<double>(psi.cols())),
                                                      psi.cols() - 1);
        for (int j = 0; j < kPooledDimension; ++j) {
            const NormalFactor f = populationFactor(j, psi.col(m));
            theta[j] = std::isfinite(f.lo) ? f.mean + f.sd * truncatedStandardNormal((f.lo - f.mean) / f.sd, (f.hi - f.mean) / f.sd, rng)
                                           : f.mean + f.sd * rng.normal();
        }
        if (box->logDensity(theta) > -kInf) out.col(k++) = theta;
    }
    return out;
}

// ------------------------------------------------------------------------------------------------
// Phase 3b

std::shared_ptr<const ProductPrior> phase3bPrior(const RbcDataSet& data, const Phase3bOptions& o) {
    const auto p1 = phase1Prior(data);
    std::vector<ScalarPriorPtr> c;
    for (int j = 0; j < p1->dimension(); ++j) {
        const ScalarPrior& s = p1->component(j);
        double lo = s.lower();
        if (o.referencePrior && data.experiment == RbcExperiment::Equilibrium && j == 2) lo = 1e-4;  // sigma ~ U[1e-4, 0.5]
        if (o.referencePrior && !(data.experiment == RbcExperiment::Equilibrium && j == 2))
            c.push_back(std::shared_ptr<const ScalarPrior>(p1, &s));  // the phase-1 prior itself
        else
            c.push_back(uniformPrior(lo, s.upper()));  // indicator of the support
    }
    return std::make_shared<ProductPrior>(std::move(c));
}

TmcmcProblem phase3bProblem(const RbcModel& model, const RbcDataSet& data, const Eigen::MatrixXd& psi, const Eigen::VectorXd& logB,
                            const Phase3bOptions& o, std::shared_ptr<PopulationTimer> timer) {
    if (logB.size() != psi.cols())
        throw InputError(fmt::format("phase 3b ({}): {} values of log b_i for {} phase-2 samples", data.name, logB.size(), psi.cols()));
    if (!(o.bFloor > 0.0)) throw InputError(fmt::format("phase 3b: the floor of b_i = {} must be > 0", o.bFloor));
    // c_m = -log max(b_i(psi_m), floor)
    const double logFloor = std::log(o.bFloor);
    Eigen::VectorXd offset(logB.size());
    for (Eigen::Index m = 0; m < logB.size(); ++m) offset[m] = -std::max(logB[m], logFloor);
    const auto layout = data.experiment == RbcExperiment::Equilibrium  ? PopulationMixture::Layout::Equilibrium
                        : data.experiment == RbcExperiment::Stretching ? PopulationMixture::Layout::Stretching
                                                                         : PopulationMixture::Layout::Relaxation;
    const Eigen::Index fvkFrom = o.referenceEquilibriumDefect && data.experiment == RbcExperiment::Equilibrium ? psi.cols() - 1 : -1;
    auto built = std::make_shared<PopulationMixture>(layout, psi, offset, o.rule, fvkFrom);
    if (layout == PopulationMixture::Layout::Relaxation) {
        // r lives in the phase-1 support [0.01, 1]: tabulate the 1-D mixture there (checked to 1e-9).
        const ScalarPrior& r = phase1Prior(data)->component(0);
        built->tabulate(r.lower(), r.upper(), 1e-4, 1e-9, timer.get());
    }
    std::shared_ptr<const PopulationMixture> mixture = built;
    TmcmcProblem p;
    p.prior = phase3bPrior(data, o);
    p.batchLogLikelihood = [model, data, mixture, timer](const Eigen::MatrixXd& theta) {
        Eigen::VectorXd ll = rbcLogLikelihood(model, data, theta);
        // The mixture only where the data likelihood is non-zero.
        std::vector<Eigen::Index> live;
        for (Eigen::Index i = 0; i < ll.size(); ++i)
            if (ll[i] > -kInf) live.push_back(i);
        Eigen::MatrixXd x(mixture->dimension(), static_cast<Eigen::Index>(live.size()));
        for (std::size_t k = 0; k < live.size(); ++k) x.col(static_cast<Eigen::Index>(k)) = theta.col(live[k]).head(mixture->dimension());
        const Eigen::VectorXd lm = mixture->logMean(x, timer.get());
        for (std::size_t k = 0; k < live.size(); ++k) ll[live[k]] += lm[static_cast<Eigen::Index>(k)];
        return ll;
    };
    return p;
}

}  // namespace trbc
