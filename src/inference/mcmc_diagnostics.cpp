#include "inference/mcmc_diagnostics.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/error.hpp"
#include "inference/priors.hpp"
#include "inference/statistics.hpp"

namespace trbc {

namespace {

void checkChains(const Chains& chains) {
    if (chains.empty()) throw InputError("MCMC diagnostics: no chains");
    const Eigen::Index n = chains[0].size();
    for (const Eigen::VectorXd& c : chains)
        if (c.size() != n) throw InputError("MCMC diagnostics: the chains differ in length");
    if (n < 4) throw InputError(fmt::format("MCMC diagnostics: {} draws per chain are too few (>= 4)", n));
}

/// Each chain cut into its first and second half (the middle draw of an odd length is dropped).
Chains splitChains(const Chains& chains) {
    Chains out;
    for (const Eigen::VectorXd& c : chains) {
        const Eigen::Index h = c.size() / 2;
        out.push_back(c.head(h));
        out.push_back(c.tail(h));
    }
    return out;
}

/// Within-chain variance W (divisor n - 1, averaged) and var+ = (n-1)/n W + B/n.
void varianceComponents(const Chains& c, double& W, double& varPlus) {
    const double n = static_cast<double>(c[0].size()), m = static_cast<double>(c.size());
    Eigen::VectorXd means(c.size());
    W = 0.0;
    for (std::size_t j = 0; j < c.size(); ++j) {
        means[static_cast<Eigen::Index>(j)] = c[j].mean();
        W += (c[j].array() - means[static_cast<Eigen::Index>(j)]).square().sum() / (n - 1.0);
    }
    W /= m;
    const double B = m > 1 ? n * (means.array() - means.mean()).square().sum() / (m - 1.0) : 0.0;
    varPlus = (n - 1.0) / n * W + B / n;
}

double essOfSplit(const Chains& c) {
    const Eigen::Index n = c[0].size();
    const double m = static_cast<double>(c.size()), S = m * static_cast<double>(n);
    double W = 0.0, varPlus = 0.0;
    varianceComponents(c, W, varPlus);
    if (!(varPlus > 0.0)) return S;  // constant draws: every draw is as good as independent
    std::vector<Eigen::VectorXd> centred;
    for (const auto& x : c) centred.push_back(x.array() - x.mean());
    // rho_t = 1 - (W - mean_j acov_j(t)) / var+, acov_j(t) = (1/n) sum_i y_i y_{i+t}.
    auto rho = [&](Eigen::Index t) {
        double a = 0.0;
        for (const auto& y : centred) a += y.head(n - t).dot(y.tail(n - t)) / static_cast<double>(n);
        a /= m;
        return 1.0 - (W - a) / varPlus;
    };
    // Geyer's initial positive sequence of pair sums P_k = rho_2k + rho_2k+1, made monotone.
    double sum = 0.0, previous = std::numeric_limits<double>::infinity();
    for (Eigen::Index t = 0; t + 1 < n; t += 2) {
        double P = (t == 0 ? 1.0 : rho(t)) + rho(t + 1);
        if (!(P > 0.0)) break;
        P = std::min(P, previous);
        previous = P;
        sum += P;
    }
    const double tau = std::max(-1.0 + 2.0 * sum, 1.0 / std::log10(S));
    return S / tau;
}

double rhatOfSplit(const Chains& c) {
    double W = 0.0, varPlus = 0.0;
    varianceComponents(c, W, varPlus);
    if (!(W > 0.0)) return varPlus > 0.0 ? std::numeric_limits<double>::infinity() : 1.0;
    return std::sqrt(varPlus / W);
}

Chains mapChains(const Chains& c, const auto& f) {
    Chains out = c;
    for (auto& x : out) x = x.unaryExpr(f);
    return out;
}

}  // namespace

Eigen::VectorXd pooledDraws(const Chains& chains) {
    Eigen::Index total = 0;
    for (const auto& c : chains) total += c.size();
    Eigen::VectorXd x(total);
    Eigen::Index k = 0;
    for (const auto& c : chains) {
        x.segment(k, c.size()) = c;
        k += c.size();
    }
    return x;
}

Chains rankNormalise(const Chains& chains) {
    const Eigen::VectorXd x = pooledDraws(chains);
    const Eigen::Index S = x.size();
    std::vector<Eigen::Index> order(static_cast<std::size_t>(S));
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return x[a] < x[b]; });
    Eigen::VectorXd z(S);
    for (Eigen::Index i = 0; i < S;) {
        Eigen::Index j = i;
        while (j + 1 < S && x[order[static_cast<std::size_t>(j + 1)]] == x[order[static_cast<std::size_t>(i)]]) ++j;
        const double rank = 0.5 * static_cast<double>(i + j) + 1.0;  // average rank of the ties, 1-based
        const double score = normalQuantile((rank - 0.375) / (static_cast<double>(S) + 0.25));
        for (Eigen::Index k = i; k <= j; ++k) z[order[static_cast<std::size_t>(k)]] = score;
        i = j + 1;
    }
    Chains out;
    Eigen::Index k = 0;
    for (const auto& c : chains) {
        out.push_back(z.segment(k, c.size()));
        k += c.size();
    }
    return out;
}

double effectiveSampleSize(const Chains& chains) {
    checkChains(chains);
    return essOfSplit(splitChains(chains));
}

double splitRhat(const Chains& chains) {
    checkChains(chains);
    return rhatOfSplit(splitChains(chains));
}

ChainDiagnostics chainDiagnostics(const Chains& chains) {
    checkChains(chains);
    const Chains split = splitChains(chains);
    const Chains z = rankNormalise(split);
    const double med = quantile(pooledDraws(chains), 0.5);
    const Chains folded = rankNormalise(mapChains(split, [med](double v) { return std::abs(v - med); }));
    ChainDiagnostics d;
    d.rhat = std::max(rhatOfSplit(z), rhatOfSplit(folded));
    d.essBulk = essOfSplit(z);
    const Eigen::VectorXd all = pooledDraws(chains);
    const double q05 = quantile(all, 0.05), q95 = quantile(all, 0.95);
    d.essTail = std::min(essOfSplit(mapChains(split, [q05](double v) { return v <= q05 ? 1.0 : 0.0; })),
                         essOfSplit(mapChains(split, [q95](double v) { return v <= q95 ? 1.0 : 0.0; })));
    d.essMean = essOfSplit(split);
    return d;
}

McEstimate selfNormalisedMean(const Chains& weights, const Chains& values) {
    checkChains(weights);
    checkChains(values);
    if (weights.size() != values.size() || weights[0].size() != values[0].size())
        throw InputError("MCMC diagnostics: weights and values differ in shape");
    const Eigen::VectorXd w = pooledDraws(weights), a = pooledDraws(values);
    const double W = w.sum();
    if (!(W > 0.0) || !std::isfinite(W)) throw NumericalError("self-normalised mean: the weights sum to zero or are not finite");
    McEstimate e;
    e.value = w.dot(a) / W;
    const double wbar = W / static_cast<double>(w.size());
    Chains u;
    for (std::size_t j = 0; j < values.size(); ++j) u.push_back(weights[j].cwiseProduct(values[j].array().matrix() - Eigen::VectorXd::Constant(values[j].size(), e.value)) / wbar);
    const Eigen::VectorXd all = pooledDraws(u);
    const double var = all.squaredNorm() / static_cast<double>(all.size());  // mean of u is 0 by construction
    e.mcse = var > 0.0 ? std::sqrt(var / essOfSplit(splitChains(u))) : 0.0;
    return e;
}

McEstimate chainMean(const Chains& chains) {
    Chains ones = chains;
    for (auto& c : ones) c.setOnes();
    return selfNormalisedMean(ones, chains);
}

McEstimate chainSd(const Chains& chains) {
    checkChains(chains);
    const Eigen::VectorXd all = pooledDraws(chains);
    const double m = all.mean();
    // s^2 = mean((x - m)^2): its MCSE from the ESS of the squared deviations; s = sqrt(s^2).
    const McEstimate v = chainMean(mapChains(chains, [m](double x) { return (x - m) * (x - m); }));
    McEstimate e;
    e.value = std::sqrt(std::max(v.value, 0.0));
    e.mcse = e.value > 0.0 ? v.mcse / (2.0 * e.value) : 0.0;
    return e;
}

McEstimate chainQuantile(const Chains& chains, double p) {
    checkChains(chains);
    if (!(p > 0.0 && p < 1.0)) throw InputError(fmt::format("MCMC diagnostics: quantile level {} is not in (0, 1)", p));
    const Eigen::VectorXd all = pooledDraws(chains);
    std::vector<double> sorted(all.data(), all.data() + all.size());
    std::sort(sorted.begin(), sorted.end());
    McEstimate e;
    e.value = quantileSorted(sorted, p);
    const double q = e.value;
    const double ess = essOfSplit(splitChains(mapChains(chains, [q](double v) { return v <= q ? 1.0 : 0.0; })));
    e.mcse = quantileMcseSorted(sorted, p, ess);
    return e;
}

}  // namespace trbc
