#include "inference/statistics.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "core/error.hpp"

namespace trbc {

namespace {

void requireProbability(const char* what, double p) {
    if (!(p >= 0.0 && p <= 1.0)) throw InputError(fmt::format("{}: p = {} is invalid: must be in [0, 1]", what, p));
}

void requireNonEmpty(const char* what, Eigen::Index n) {
    if (n < 1) throw InputError(fmt::format("{}: needs at least one sample", what));
}

/// Normalised weights (sum 1), checked to be finite and >= 0 with a positive sum.
Eigen::VectorXd normalisedWeights(const Eigen::VectorXd& weights, Eigen::Index n, const char* what) {
    if (weights.size() != n)
        throw InputError(fmt::format("{}: {} weights for {} samples", what, weights.size(), n));
    double sum = 0.0;
    for (Eigen::Index k = 0; k < n; ++k) {
        if (!(weights[k] >= 0.0 && std::isfinite(weights[k])))
            throw InputError(fmt::format("{}: weight {} = {} is invalid: must be finite and >= 0", what, k, weights[k]));
        sum += weights[k];
    }
    if (!(sum > 0.0)) throw InputError(fmt::format("{}: all weights are zero", what));
    return weights / sum;
}

}  // namespace

double quantileSorted(const std::vector<double>& sorted, double p) {
    requireProbability("quantile", p);
    requireNonEmpty("quantile", static_cast<Eigen::Index>(sorted.size()));
    const double h = static_cast<double>(sorted.size() - 1) * p;  // type 7
    const std::size_t i = static_cast<std::size_t>(std::floor(h));
    if (i + 1 >= sorted.size()) return sorted.back();
    return sorted[i] + (h - static_cast<double>(i)) * (sorted[i + 1] - sorted[i]);
}

namespace {
double quantileLevelSpread(double p, double ess) { return std::sqrt(p * (1.0 - p) / std::max(ess, 1.0)); }
}  // namespace

bool quantileMcseIsLowerBound(double p, double ess) {
    const double se = quantileLevelSpread(p, ess);
    return p - se < 0.0 || p + se > 1.0;
}

double quantileMcseSorted(const std::vector<double>& sorted, double p, double ess) {
    requireProbability("quantile", p);
    requireNonEmpty("quantile", static_cast<Eigen::Index>(sorted.size()));
    const double se = quantileLevelSpread(p, ess);
    return 0.5 * (quantileSorted(sorted, std::min(p + se, 1.0)) - quantileSorted(sorted, std::max(p - se, 0.0)));
}

double quantile(const Eigen::VectorXd& values, double p) {
    std::vector<double> v(values.data(), values.data() + values.size());
    std::sort(v.begin(), v.end());
    return quantileSorted(v, p);
}

double weightedQuantile(const Eigen::VectorXd& values, const Eigen::VectorXd& weights, double p) {
    requireProbability("weightedQuantile", p);
    requireNonEmpty("weightedQuantile", values.size());
    const Eigen::VectorXd w = normalisedWeights(weights, values.size(), "weightedQuantile");
    std::vector<Eigen::Index> order;
    for (Eigen::Index k = 0; k < values.size(); ++k)
        if (w[k] > 0.0) order.push_back(k);
    std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return values[a] < values[b]; });
    const std::size_t m = order.size();
    if (m == 1) return values[order[0]];
    // Plotting positions p_i = (C_i - w_i/2 - w_1/2) / (1 - w_1/2 - w_m/2): p_1 = 0, p_m = 1, and
    // (i-1)/(N-1) for equal weights (type 7).
    const double w1 = w[order.front()], wm = w[order.back()];
    const double scale = 1.0 - 0.5 * (w1 + wm);
    std::vector<double> pos(m);
    double cumulative = 0.0;
    for (std::size_t i = 0; i < m; ++i) {
        const double wi = w[order[i]];
        cumulative += wi;
        pos[i] = (cumulative - 0.5 * wi - 0.5 * w1) / scale;
    }
    pos.front() = 0.0;
    pos.back() = 1.0;
    const auto it = std::upper_bound(pos.begin(), pos.end(), p);  // first position > p
    if (it == pos.end()) return values[order.back()];
    const std::size_t j = static_cast<std::size_t>(it - pos.begin());  // j >= 1 since pos[0] = 0 <= p
    const double x0 = values[order[j - 1]], x1 = values[order[j]];
    const double t = (p - pos[j - 1]) / (pos[j] - pos[j - 1]);
    return x0 + t * (x1 - x0);
}

double mean(const Eigen::VectorXd& values) {
    requireNonEmpty("mean", values.size());
    return values.sum() / static_cast<double>(values.size());
}

double populationSd(const Eigen::VectorXd& values) {
    const double m = mean(values);
    return std::sqrt((values.array() - m).square().sum() / static_cast<double>(values.size()));
}

double weightedMean(const Eigen::VectorXd& values, const Eigen::VectorXd& weights) {
    requireNonEmpty("weightedMean", values.size());
    return normalisedWeights(weights, values.size(), "weightedMean").dot(values);
}

double weightedSd(const Eigen::VectorXd& values, const Eigen::VectorXd& weights) {
    requireNonEmpty("weightedSd", values.size());
    const Eigen::VectorXd w = normalisedWeights(weights, values.size(), "weightedSd");
    const double m = w.dot(values);
    const double denom = 1.0 - w.squaredNorm();  // 1 - sum w^2 (= (N-1)/N for equal weights)
    if (!(denom > 0.0)) return 0.0;              // a single sample carries all the weight
    return std::sqrt((w.array() * (values.array() - m).square()).sum() / denom);
}

double effectiveSampleSize(const Eigen::VectorXd& weights) {
    requireNonEmpty("effectiveSampleSize", weights.size());
    return 1.0 / normalisedWeights(weights, weights.size(), "effectiveSampleSize").squaredNorm();
}

Eigen::Index argmax(const Eigen::VectorXd& values) {
    Eigen::Index best = 0;
    double bestValue = -std::numeric_limits<double>::infinity();
    for (Eigen::Index k = 0; k < values.size(); ++k)
        if (values[k] > bestValue) {
            bestValue = values[k];
            best = k;
        }
    return best;
}

const ParameterSummary& PosteriorSummary::operator[](const std::string& name) const {
    for (const auto& p : parameters)
        if (p.name == name) return p;
    throw InputError(fmt::format("posterior summary: no parameter named '{}'", name));
}

PosteriorSummary posteriorStatistics(const Eigen::MatrixXd& samples, const Eigen::VectorXd& logLikelihood,
                                     const Eigen::VectorXd& logPrior, const std::vector<std::string>& names,
                                     const Eigen::VectorXd& weights, const std::vector<double>& levels) {
    const Eigen::Index n = samples.rows(), N = samples.cols();
    requireNonEmpty("posteriorStatistics", N);
    if (logLikelihood.size() != N || logPrior.size() != N)
        throw InputError(fmt::format("posteriorStatistics: {} samples but {} log-likelihoods and {} log-priors", N,
                                     logLikelihood.size(), logPrior.size()));
    if (!names.empty() && static_cast<Eigen::Index>(names.size()) != n)
        throw InputError(fmt::format("posteriorStatistics: {} names for {} parameters", names.size(), n));
    for (double c : levels)
        if (!(c > 0.0 && c < 1.0))
            throw InputError(fmt::format("posteriorStatistics: credible level {} is invalid: must be in (0, 1)", c));
    const bool weighted = weights.size() > 0;
    const Eigen::VectorXd w = weighted ? normalisedWeights(weights, N, "posteriorStatistics") : Eigen::VectorXd();

    PosteriorSummary s;
    s.mlIndex = argmax(logLikelihood);
    s.mapIndex = argmax(logLikelihood + logPrior);
    s.maxLogLikelihood = logLikelihood[s.mlIndex];
    s.maxLogPosterior = logLikelihood[s.mapIndex] + logPrior[s.mapIndex];
    s.effectiveSampleSize = weighted ? 1.0 / w.squaredNorm() : static_cast<double>(N);

    for (Eigen::Index i = 0; i < n; ++i) {
        const Eigen::VectorXd x = samples.row(i).transpose();
        ParameterSummary p;
        p.name = names.empty() ? fmt::format("theta{}", i) : names[static_cast<std::size_t>(i)];
        std::vector<double> sorted;
        if (!weighted) {
            sorted.assign(x.data(), x.data() + N);
            std::sort(sorted.begin(), sorted.end());
        }
        auto q = [&](double prob) { return weighted ? weightedQuantile(x, w, prob) : quantileSorted(sorted, prob); };
        p.mean = weighted ? w.dot(x) : mean(x);
        p.sd = weighted ? weightedSd(x, w) : populationSd(x);
        p.median = q(0.5);
        p.q05 = q(0.05);
        p.q95 = q(0.95);
        for (double c : levels) p.intervals.push_back({c, q(0.5 * (1.0 - c)), q(0.5 * (1.0 + c))});
        p.ml = x[s.mlIndex];
        p.map = x[s.mapIndex];
        s.parameters.push_back(std::move(p));
    }
    return s;
}

PosteriorSummary posteriorStatistics(const TmcmcResult& result, const std::vector<std::string>& names) {
    return posteriorStatistics(result.samples, result.logLikelihood, result.logPrior, names);
}

ProfileLikelihood profileLikelihood(const Eigen::VectorXd& values, const Eigen::VectorXd& logLikelihood, int bins) {
    requireNonEmpty("profileLikelihood", values.size());
    if (bins < 1) throw InputError(fmt::format("profileLikelihood: bins = {} is invalid: must be >= 1", bins));
    if (logLikelihood.size() != values.size())
        throw InputError(fmt::format("profileLikelihood: {} values but {} log-likelihoods", values.size(), logLikelihood.size()));
    const double lo = values.minCoeff(), hi = values.maxCoeff();
    ProfileLikelihood r;
    r.edges = Eigen::VectorXd::LinSpaced(bins + 1, lo, hi);
    r.counts = Eigen::VectorXi::Zero(bins);
    r.maxLogLikelihood = Eigen::VectorXd::Constant(bins, -std::numeric_limits<double>::infinity());
    const double width = (hi - lo) / bins;
    for (Eigen::Index k = 0; k < values.size(); ++k) {
        int b = width > 0.0 ? static_cast<int>((values[k] - lo) / width) : 0;
        b = std::clamp(b, 0, bins - 1);  // the maximum falls into the last bin
        ++r.counts[b];
        r.maxLogLikelihood[b] = std::max(r.maxLogLikelihood[b], logLikelihood[k]);
    }
    return r;
}

void appendDerivedParameter(Eigen::MatrixXd& samples, std::vector<std::string>& names, const std::string& name,
                            const std::function<double(const Eigen::VectorXd&)>& f) {
    const Eigen::Index n = samples.rows(), N = samples.cols();
    Eigen::VectorXd derived(N);
    for (Eigen::Index k = 0; k < N; ++k) derived[k] = f(samples.col(k));
    samples.conservativeResize(n + 1, Eigen::NoChange);
    samples.row(n) = derived.transpose();
    names.push_back(name);
}

}  // namespace trbc
