#include "inference/rbc_hierarchical.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <functional>
#include <cmath>
#include <numbers>

#include "core/error.hpp"
#include "inference/population.hpp"
#include "inference/priors.hpp"

namespace trbc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// 0 inside [lo, hi] of every listed coordinate, -inf outside; plus the log prior of the others.
double boxAndPrior(const ProductPrior& prior, const Eigen::VectorXd& y, int pooledCount) {
    for (int j = 0; j < pooledCount; ++j)
        if (!prior.component(j).inSupport(y[j])) return -kInf;
    double s = 0.0;
    for (int j = pooledCount; j < prior.dimension(); ++j) s += prior.component(j).logDensity(y[j]);
    return s;
}

/// Gauss-Legendre nodes and weights on (0, 1) (Newton on P_n from the Chebyshev guesses).
void gaussLegendre(int n, std::vector<double>& x, std::vector<double>& w) {
    x.assign(static_cast<std::size_t>(n), 0.0);
    w.assign(static_cast<std::size_t>(n), 0.0);
    for (int i = 0; i < n; ++i) {
        double z = std::cos(std::numbers::pi * (i + 0.75) / (n + 0.5)), dp = 0.0;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1.0, p1 = z;
            for (int k = 2; k <= n; ++k) {
                const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
                p0 = p1, p1 = p2;
            }
            dp = n * (z * p1 - p0) / (z * z - 1.0);
            const double dz = p1 / dp;
            z -= dz;
            if (std::abs(dz) < 1e-15) break;
        }
        x[static_cast<std::size_t>(i)] = 0.5 * (1.0 - z);
        w[static_cast<std::size_t>(i)] = 1.0 / ((1.0 - z * z) * dp * dp);  // (2 / ((1-z^2) P'^2)) / 2
    }
}

/// Per draw of psi: the restricted component of one coordinate (mean, sd, interval).
struct Restricted {
    double m, s, a, b;
    double cdf(double x) const { return truncatedNormalCdf(x, m, s, a, b); }
    double pdf(double x) const {
        if (x < a || x > b) return 0.0;
        return std::exp(truncatedNormalLogDensity(x, m, s, a, b));
    }
    double quantile(double u) const {
        const double pa = normalCdf((a - m) / s), pb = normalCdf((b - m) / s);
        return std::clamp(m + s * normalQuantile(std::clamp(pa + u * (pb - pa), 1e-300, 1.0 - 1e-16)), a, b);
    }
};

/// Solves F(x) = p on [lo, hi] (F non-decreasing, density f) by Newton steps from `guess`, kept
/// inside a shrinking bracket (bisection whenever a step leaves it).
double solveCdf(const std::function<double(double)>& F, const std::function<double(double)>& f, double p, double lo, double hi,
                double guess) {
    double x = std::clamp(guess, lo, hi);
    for (int it = 0; it < 100; ++it) {
        const double Fx = F(x) - p;
        if (std::abs(Fx) < 1e-12) return x;
        (Fx < 0.0 ? lo : hi) = x;
        if (hi - lo < 1e-13 * std::max(1.0, std::abs(hi))) break;
        const double fx = f(x);
        const double next = fx > 0.0 ? x - Fx / fx : 0.5 * (lo + hi);
        x = (next > lo && next < hi) ? next : 0.5 * (lo + hi);
    }
    return x;
}

}  // namespace

std::vector<PopulationComponent> rbcPopulationComponents(const PopulationVariant& variant) {
    const auto prior = hyperPrior();
    std::vector<PopulationComponent> out;
    const Eigen::VectorXd psi = prior->lowerBounds();
    for (int j = 0; j < kPooledDimension; ++j) {
        PopulationComponent c;
        c.name = pooledParameterNames()[static_cast<std::size_t>(j)];
        const NormalFactor f = populationFactor(j, psi);
        if (variant.truncate) c.lo = f.lo, c.hi = f.hi;
        c.meanLo = prior->component(2 * j).lower(), c.meanHi = prior->component(2 * j).upper();
        c.sdLo = prior->component(2 * j + 1).lower(), c.sdHi = variant.sdUpperScale * prior->component(2 * j + 1).upper();
        if (!(c.sdHi > c.sdLo)) throw InputError(fmt::format("population: the SD bound scale {} leaves no SD range for {}", variant.sdUpperScale, c.name));
        out.push_back(c);
    }
    return out;
}

Eigen::MatrixXd rbcGroupToPhase1(RbcExperiment e, const Eigen::MatrixXd& y) {
    if (e != RbcExperiment::Equilibrium) return y;
    Eigen::MatrixXd x(3, y.cols());
    for (Eigen::Index k = 0; k < y.cols(); ++k) x.col(k) << y(0, k), fvkFromModuli(y(1, k), y(2, k)), y(3, k);
    return x;
}

HierarchicalModel rbcHierarchicalModel(const RbcModel& model, const std::vector<RbcDataSet>& data,
                                       const std::vector<Eigen::MatrixXd>& phase1Samples, std::uint64_t seed,
                                       const PopulationVariant& variant) {
    if (phase1Samples.size() != data.size())
        throw InputError(fmt::format("hierarchical model: {} phase-1 sample sets for {} data sets", phase1Samples.size(), data.size()));
    HierarchicalModel h;
    h.population = rbcPopulationComponents(variant);
    for (std::size_t i = 0; i < data.size(); ++i) {
        const RbcDataSet& d = data[i];
        const auto prior = phase1Prior(d);
        HierarchicalGroup g;
        g.name = d.name;
        const Eigen::MatrixXd& s = phase1Samples[i];
        switch (d.experiment) {
            case RbcExperiment::Equilibrium: {
                g.pooled = {kPooledV, kPooledMu, kPooledKb};
                g.names = {"v", "mu", "kb", "sigma"};
                g.logVariables = {1, 2, 3};
                g.stepsPerSweep = 8;  // one network row per candidate
                // v in the box, FvK in its prior support; sigma keeps its prior.
                g.logSupport = [prior](const Eigen::VectorXd& y) {
                    if (!(y[2] > 0.0) || !prior->component(0).inSupport(y[0]) || !prior->component(1).inSupport(fvkFromModuli(y[1], y[2])))
                        return -kInf;
                    return prior->component(2).logDensity(y[3]);
                };
                g.batchLogLikelihood = [model, d](const Eigen::MatrixXd& y) {
                    return equilibriumLogLikelihood(model, d, rbcGroupToPhase1(RbcExperiment::Equilibrium, y));
                };
                Rng rng(seed, 0x6571, i);
                g.start.resize(4, s.cols());
                for (Eigen::Index k = 0; k < s.cols(); ++k) {
                    const double kb = kKbLow + (kKbHigh - kKbLow) * rng.uniform();
                    g.start.col(k) << s(0, k), s(1, k) * kb / kRbcAreaRadius2, kb, s(2, k);
                }
                break;
            }
            case RbcExperiment::Stretching:
                g.pooled = {kPooledV, kPooledMu, kPooledKb, kPooledB2};
                g.names = phase1ParameterNames(d.experiment);
                g.logVariables = {1, 2, 4, 5};
                g.logSupport = [prior](const Eigen::VectorXd& y) { return boxAndPrior(*prior, y, 4); };
                g.batchLogLikelihood = [model, d](const Eigen::MatrixXd& y) { return stretchingLogLikelihood(model, d, y); };
                g.start = s;
                break;
            case RbcExperiment::Relaxation:
                g.pooled = {kPooledR};
                g.names = phase1ParameterNames(d.experiment);
                g.logVariables = {0, 1, 2, 5};
                g.stepsPerSweep = 3;  // one network row per candidate
                g.logSupport = [prior](const Eigen::VectorXd& y) { return boxAndPrior(*prior, y, 1); };
                g.batchLogLikelihood = [model, d](const Eigen::MatrixXd& y) { return relaxationLogLikelihood(model, d, y); };
                g.start = s;
                break;
        }
        h.groups.push_back(std::move(g));
    }
    return h;
}

std::vector<NewCellStatistic> newCellStatistics(const std::vector<Eigen::MatrixXd>& psiChains, const PopulationVariant& variant) {
    if (psiChains.empty()) throw InputError("theta_new: no hyper-parameter draws");
    const std::vector<PopulationComponent> pop = rbcPopulationComponents(variant);
    Eigen::VectorXd boxLo = newCellBoxPrior()->lowerBounds(), boxHi = newCellBoxPrior()->upperBounds();
    if (!variant.newCellBox) {
        boxLo << 0.0, 0.0, kKbLow, 0.0, 0.0;
        boxHi << 1.0, kInf, kKbHigh, kInf, kInf;
    }
    const std::size_t C = psiChains.size();
    const Eigen::Index T = psiChains[0].cols();
    // Restricted components and log weights log w = sum_j log P(B_j | psi) - log P([lo_j, hi_j] | psi).
    std::vector<std::vector<std::array<Restricted, kPooledDimension>>> comp(C);
    Chains logW(C, Eigen::VectorXd(T));
    std::vector<std::array<Chains, 2>> moment(kPooledDimension, {Chains(C, Eigen::VectorXd(T)), Chains(C, Eigen::VectorXd(T))});
    double maxLogW = -kInf;
    for (std::size_t c = 0; c < C; ++c) {
        if (psiChains[c].rows() != kHyperDimension || psiChains[c].cols() != T)
            throw InputError("theta_new: the hyper-parameter chains differ in shape");
        comp[c].resize(static_cast<std::size_t>(T));
        for (Eigen::Index t = 0; t < T; ++t) {
            double lw = 0.0;
            for (int j = 0; j < kPooledDimension; ++j) {
                const PopulationComponent& p = pop[static_cast<std::size_t>(j)];
                const double m = psiChains[c](2 * j, t), s = psiChains[c](2 * j + 1, t);
                const double a = std::max(p.lo, boxLo[j]), b = std::min(p.hi, boxHi[j]);
                const TruncatedMoments tm = truncatedNormalMoments(m, s, a, b);
                lw += tm.logMass - ((std::isfinite(p.lo) || std::isfinite(p.hi)) ? logNormalMass((p.lo - m) / s, (p.hi - m) / s) : 0.0);
                comp[c][static_cast<std::size_t>(t)][static_cast<std::size_t>(j)] = {m, s, a, b};
                moment[static_cast<std::size_t>(j)][0][c][t] = tm.mean;
                moment[static_cast<std::size_t>(j)][1][c][t] = tm.variance + tm.mean * tm.mean;
            }
            logW[c][t] = lw;
            maxLogW = std::max(maxLogW, lw);
        }
    }
    if (!(maxLogW > -kInf)) throw NumericalError("theta_new: no hyper-parameter draw puts mass inside the box of 4.5");
    Chains w = logW;
    double wsum = 0.0;
    for (auto& x : w) {
        x = (x.array() - maxLogW).exp().matrix();
        wsum += x.sum();
    }
    const double wbar = wsum / static_cast<double>(C * static_cast<std::size_t>(T));
    auto influenceMcse = [&](const std::function<double(std::size_t, Eigen::Index)>& h) {
        Chains u(C, Eigen::VectorXd(T));
        for (std::size_t c = 0; c < C; ++c)
            for (Eigen::Index t = 0; t < T; ++t) u[c][t] = w[c][t] / wbar * h(c, t);
        return chainMean(u).mcse;
    };
    // Mean, SD and quantiles of a coordinate given per-draw first/second moments, CDF and density.
    auto summarise = [&](const std::string& name, double scale, const Chains& a1, const Chains& a2,
                         const std::function<double(std::size_t, Eigen::Index, double)>& cdf,
                         const std::function<double(std::size_t, Eigen::Index, double)>& pdf, double lo, double hi) {
        // lo, hi: the support; narrowed to +-60 SD around the mean for the root search
        NewCellStatistic st;
        st.name = name;
        const McEstimate mean = selfNormalisedMean(w, a1), e2 = selfNormalisedMean(w, a2);
        const double var = std::max(e2.value - mean.value * mean.value, 0.0), sd = std::sqrt(var);
        const double mcseVar = influenceMcse([&](std::size_t c, Eigen::Index t) {
            return (a2[c][t] - e2.value) - 2.0 * mean.value * (a1[c][t] - mean.value);
        });
        st.mean = {scale * mean.value, scale * mean.mcse};
        if (C >= 2 && T >= 4) {
            const ChainDiagnostics d = chainDiagnostics(a1);
            st.rhat = d.rhat, st.essBulk = d.essBulk, st.essTail = d.essTail;
        }
        st.sd = {scale * sd, sd > 0.0 ? scale * mcseVar / (2.0 * sd) : 0.0};
        auto F = [&](double x) {
            double s = 0.0;
            for (std::size_t c = 0; c < C; ++c)
                for (Eigen::Index t = 0; t < T; ++t) s += w[c][t] * cdf(c, t, x);
            return s / wsum;
        };
        auto density = [&](double x) {
            double s = 0.0;
            for (std::size_t c = 0; c < C; ++c)
                for (Eigen::Index t = 0; t < T; ++t) s += w[c][t] * pdf(c, t, x);
            return s / wsum;
        };
        const double sdGuess = std::sqrt(var);
        lo = std::max(lo, mean.value - 60.0 * sdGuess), hi = std::min(hi, mean.value + 60.0 * sdGuess);
        for (auto [p, out] : {std::pair{0.5, &st.median}, std::pair{0.05, &st.q05}, std::pair{0.95, &st.q95}}) {
            const double q = solveCdf(F, density, p, lo, hi, mean.value + sdGuess * normalQuantile(p));
            const double f = density(q);
            const double mcseF = influenceMcse([&](std::size_t c, Eigen::Index t) { return cdf(c, t, q) - p; });
            *out = {scale * q, f > 0.0 ? scale * mcseF / f : kInf};
        }
        return st;
    };
    std::vector<NewCellStatistic> out;
    const Eigen::VectorXd outScale = pooledOutputScale();
    for (int j = 0; j < kPooledDimension; ++j) {
        const auto J = static_cast<std::size_t>(j);
        out.push_back(summarise(
            pooledOutputNames()[J], outScale[j], moment[J][0], moment[J][1],
            [&](std::size_t c, Eigen::Index t, double x) { return comp[c][static_cast<std::size_t>(t)][J].cdf(x); },
            [&](std::size_t c, Eigen::Index t, double x) { return comp[c][static_cast<std::size_t>(t)][J].pdf(x); },
            std::max(pop[J].lo, boxLo[j]), std::min(pop[J].hi, boxHi[j])));
    }
    // eta_m = mu r: moments multiply; the CDF integrates F_r(x / mu) over the probability of mu.
    std::vector<double> gx, gw;
    gaussLegendre(24, gx, gw);
    std::vector<std::vector<std::array<double, 24>>> muNodes(C);
    Chains e1(C, Eigen::VectorXd(T)), e2(C, Eigen::VectorXd(T));
    for (std::size_t c = 0; c < C; ++c) {
        muNodes[c].resize(static_cast<std::size_t>(T));
        for (Eigen::Index t = 0; t < T; ++t) {
            for (std::size_t k = 0; k < 24; ++k) muNodes[c][static_cast<std::size_t>(t)][k] = comp[c][static_cast<std::size_t>(t)][kPooledMu].quantile(gx[k]);
            e1[c][t] = moment[kPooledMu][0][c][t] * moment[kPooledR][0][c][t];
            e2[c][t] = moment[kPooledMu][1][c][t] * moment[kPooledR][1][c][t];
        }
    }
    auto etaCdf = [&](std::size_t c, Eigen::Index t, double x) {
        const Restricted& r = comp[c][static_cast<std::size_t>(t)][kPooledR];
        double s = 0.0;
        for (std::size_t k = 0; k < 24; ++k) {
            const double mu = muNodes[c][static_cast<std::size_t>(t)][k];
            s += gw[k] * (mu > 0.0 ? r.cdf(x / mu) : 1.0);
        }
        return s;
    };
    auto etaPdf = [&](std::size_t c, Eigen::Index t, double x) {
        const Restricted& r = comp[c][static_cast<std::size_t>(t)][kPooledR];
        double s = 0.0;
        for (std::size_t k = 0; k < 24; ++k) {
            const double mu = muNodes[c][static_cast<std::size_t>(t)][k];
            s += mu > 0.0 ? gw[k] * r.pdf(x / mu) / mu : 0.0;
        }
        return s;
    };
    const double etaHi = boxHi[kPooledMu] * boxHi[kPooledR];
    out.push_back(summarise("etam_Pa_s_um", 1.0, e1, e2, etaCdf, etaPdf, 0.0, etaHi));
    return out;
}

}  // namespace trbc
