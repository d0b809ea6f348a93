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
            case RbcExperiment::Flow:
                g.pooled = {kPooledV, kPooledMu, kPooledKb, kPooledB2, kPooledR};
                g.names = phase1ParameterNames(d.experiment);
                g.logVariables = {1, 2, 4, 5};
                g.logSupport = [prior](const Eigen::VectorXd& y) { return boxAndPrior(*prior, y, 5); };
                g.batchLogLikelihood = [model, d](const Eigen::MatrixXd& y) { return rbcLogLikelihood(model, d, y); };
                g.start = s;
                break;
        }
        h.groups.push_back(std::move(g));
    }
    return h;
}

namespace {

/// The box B that theta_new is restricted to: newCellBoxPrior's, or with the box off only
/// v <= 1, the kb prior box and mu, b2, r >= 0.
struct NewCellBox {
    Eigen::VectorXd lo, hi;
};

NewCellBox newCellBox(const PopulationVariant& variant) {
    NewCellBox box{newCellBoxPrior()->lowerBounds(), newCellBoxPrior()->upperBounds()};
    if (!variant.newCellBox) {
        box.lo << 0.0, 0.0, kKbLow, 0.0, 0.0;
        box.hi << 1.0, kInf, kKbHigh, kInf, kInf;
    }
    return box;
}

/// The psi draws as theta_new sees them: per draw psi_ct and pooled coordinate j the population
/// component restricted to B_j, its moments E[x_j | psi_ct, B_j] and E[x_j^2 | psi_ct, B_j], and the
/// weight w_ct = P(theta in B | psi_ct) (the component mass normalised by the population's own
/// truncation), stored relative to the largest weight.
struct NewCellDraws {
    std::size_t C = 0;
    Eigen::Index T = 0;
    std::vector<std::vector<std::array<Restricted, kPooledDimension>>> comp;  ///< [c][t][j]
    std::vector<std::array<Chains, 2>> moment;                                 ///< [j][0]: E[x_j], [j][1]: E[x_j^2]
    Chains w;
    double wsum = 0.0, wbar = 0.0;  ///< sum and mean of w

    const Restricted& component(std::size_t c, Eigen::Index t, std::size_t j) const { return comp[c][static_cast<std::size_t>(t)][j]; }
};

/// log w_ct = sum_j log P(B_j | psi_ct) - log P([lo_j, hi_j] | psi_ct) with [lo_j, hi_j] the
/// population's truncation; B_j is intersected with it, so the restricted component is TN on
/// [max(lo_j, B_j lo), min(hi_j, B_j hi)].
NewCellDraws newCellDraws(const std::vector<Eigen::MatrixXd>& psiChains, const std::vector<PopulationComponent>& pop,
                          const NewCellBox& box) {
    NewCellDraws d;
    const std::size_t C = d.C = psiChains.size();
    const Eigen::Index T = d.T = psiChains[0].cols();
    d.comp.resize(C);
    d.moment.assign(kPooledDimension, {Chains(C, Eigen::VectorXd(T)), Chains(C, Eigen::VectorXd(T))});
    Chains logW(C, Eigen::VectorXd(T));
    double maxLogW = -kInf;
    for (std::size_t c = 0; c < C; ++c) {
        if (psiChains[c].rows() != kHyperDimension || psiChains[c].cols() != T)
            throw InputError("theta_new: the hyper-parameter chains differ in shape");
        d.comp[c].resize(static_cast<std::size_t>(T));
        for (Eigen::Index t = 0; t < T; ++t) {
            double lw = 0.0;
            for (int j = 0; j < kPooledDimension; ++j) {
                const auto J = static_cast<std::size_t>(j);
                const PopulationComponent& p = pop[J];
                const double m = psiChains[c](2 * j, t), s = psiChains[c](2 * j + 1, t);
                const double a = std::max(p.lo, box.lo[j]), b = std::min(p.hi, box.hi[j]);
                const TruncatedMoments tm = truncatedNormalMoments(m, s, a, b);
                lw += tm.logMass - ((std::isfinite(p.lo) || std::isfinite(p.hi)) ? logNormalMass((p.lo - m) / s, (p.hi - m) / s) : 0.0);
                d.comp[c][static_cast<std::size_t>(t)][J] = {m, s, a, b};
                d.moment[J][0][c][t] = tm.mean;
                d.moment[J][1][c][t] = tm.variance + tm.mean * tm.mean;
            }
            logW[c][t] = lw;
            maxLogW = std::max(maxLogW, lw);
        }
    }
    if (!(maxLogW > -kInf)) throw NumericalError("theta_new: no hyper-parameter draw puts mass inside the box of 4.5");
    // Relative to the largest weight: exp(log w - max log w) cannot overflow.
    d.w = logW;
    for (auto& x : d.w) {
        x = (x.array() - maxLogW).exp().matrix();
        d.wsum += x.sum();
    }
    d.wbar = d.wsum / static_cast<double>(C * static_cast<std::size_t>(T));
    return d;
}

/// A quantity per psi draw, h(c, t).
using DrawFunction = std::function<double(std::size_t, Eigen::Index)>;
/// A function of x per psi draw, g(c, t, x): the CDF or density of theta_new's coordinate given psi_ct.
using DrawCurve = std::function<double(std::size_t, Eigen::Index, double)>;

/// MCSE of a self-normalised estimate sum w g / sum w whose influence per draw is h: by the delta
/// method, the MCSE of the multi-chain mean of (w / wbar) h (autocorrelation through its ESS).
double influenceMcse(const NewCellDraws& d, const DrawFunction& h) {
    Chains u(d.C, Eigen::VectorXd(d.T));
    for (std::size_t c = 0; c < d.C; ++c)
        for (Eigen::Index t = 0; t < d.T; ++t) u[c][t] = d.w[c][t] / d.wbar * h(c, t);
    return chainMean(u).mcse;
}

/// The restricted mixture at x, sum_ct w_ct g_ct(x) / sum_ct w_ct (its CDF or density).
double weightedMixture(const NewCellDraws& d, const DrawCurve& g, double x) {
    double s = 0.0;
    for (std::size_t c = 0; c < d.C; ++c)
        for (Eigen::Index t = 0; t < d.T; ++t) s += d.w[c][t] * g(c, t, x);
    return s / d.wsum;
}

/// Mean and SD of one coordinate, unscaled (the SD also sets the quantile search).
struct CoordinateMoments {
    double mean = 0.0, sd = 0.0;
};

/// E[x] and E[x^2] are self-normalised means of the per-draw moments a1, a2; sd = sqrt(E[x^2] - E[x]^2)
/// (clamped at 0 against round-off). The variance's influence is (a2 - E[x^2]) - 2 E[x] (a1 - E[x]),
/// and MCSE(sd) = MCSE(var) / (2 sd) by the delta method. Sets st.mean and st.sd (times scale).
CoordinateMoments momentStatistics(const NewCellDraws& d, const Chains& a1, const Chains& a2, double scale, NewCellStatistic& st) {
    const McEstimate mean = selfNormalisedMean(d.w, a1), e2 = selfNormalisedMean(d.w, a2);
    const double var = std::max(e2.value - mean.value * mean.value, 0.0), sd = std::sqrt(var);
    const double mcseVar = influenceMcse(d, [&](std::size_t c, Eigen::Index t) {
        return (a2[c][t] - e2.value) - 2.0 * mean.value * (a1[c][t] - mean.value);
    });
    st.mean = {scale * mean.value, scale * mean.mcse};
    st.sd = {scale * sd, sd > 0.0 ? scale * mcseVar / (2.0 * sd) : 0.0};
    return {mean.value, sd};
}

/// R-hat and ESS of the chains of E[x | psi_ct, B] (the Rao-Blackwellised draws); split R-hat
/// needs at least two chains of four draws, otherwise they stay NaN.
void momentDiagnostics(const NewCellDraws& d, const Chains& a1, NewCellStatistic& st) {
    if (d.C < 2 || d.T < 4) return;
    const ChainDiagnostics diag = chainDiagnostics(a1);
    st.rhat = diag.rhat, st.essBulk = diag.essBulk, st.essTail = diag.essTail;
}

/// Median, q05 and q95: the roots of F(q) = p of the mixture CDF F on the support [lo, hi],
/// narrowed to mean +- 60 SD (F is 0 or 1 to double precision beyond it) and started at the normal
/// guess mean + sd z_p. MCSE(q) = MCSE(F(q)) / f(q) with the influence F_ct(q) - p (infinite where
/// the density vanishes).
void quantileStatistics(const NewCellDraws& d, const DrawCurve& cdf, const DrawCurve& pdf, double lo, double hi,
                        const CoordinateMoments& mom, double scale, NewCellStatistic& st) {
    auto F = [&](double x) { return weightedMixture(d, cdf, x); };
    auto density = [&](double x) { return weightedMixture(d, pdf, x); };
    lo = std::max(lo, mom.mean - 60.0 * mom.sd), hi = std::min(hi, mom.mean + 60.0 * mom.sd);
    for (auto [p, out] : {std::pair{0.5, &st.median}, std::pair{0.05, &st.q05}, std::pair{0.95, &st.q95}}) {
        const double q = solveCdf(F, density, p, lo, hi, mom.mean + mom.sd * normalQuantile(p));
        const double f = density(q);
        const double mcseF = influenceMcse(d, [&](std::size_t c, Eigen::Index t) { return cdf(c, t, q) - p; });
        *out = {scale * q, f > 0.0 ? scale * mcseF / f : kInf};
    }
}

/// One coordinate of theta_new from its per-draw first and second moments a1, a2, CDF and density;
/// [lo, hi] is its support, scale converts to output units.
NewCellStatistic coordinateStatistics(const NewCellDraws& d, const std::string& name, double scale, const Chains& a1, const Chains& a2,
                                      const DrawCurve& cdf, const DrawCurve& pdf, double lo, double hi) {
    NewCellStatistic st;
    st.name = name;
    const CoordinateMoments mom = momentStatistics(d, a1, a2, scale, st);
    momentDiagnostics(d, a1, st);
    quantileStatistics(d, cdf, pdf, lo, hi, mom, scale, st);
    return st;
}

/// Gauss-Legendre nodes in the probability of mu for the CDF of eta_m = mu r.
constexpr std::size_t kEtaNodes = 24;

/// eta_m = mu r with mu and r independent given psi: E[eta^k | psi] = E[mu^k | psi] E[r^k | psi]
/// (e1, e2), and F_eta(x | psi) = int F_r(x / mu) dP(mu) = int_0^1 F_r(x / Q_mu(u)) du, a quadrature
/// in u whose nodes Q_mu(u_k | psi_ct) are kept per draw (muNodes[c][t][k]).
struct EtaDraws {
    std::vector<double> u, weights;
    std::vector<std::vector<std::array<double, kEtaNodes>>> muNodes;
    Chains e1, e2;
};

EtaDraws etaDraws(const NewCellDraws& d) {
    EtaDraws e;
    gaussLegendre(static_cast<int>(kEtaNodes), e.u, e.weights);
    e.muNodes.resize(d.C);
    e.e1.assign(d.C, Eigen::VectorXd(d.T));
    e.e2.assign(d.C, Eigen::VectorXd(d.T));
    for (std::size_t c = 0; c < d.C; ++c) {
        e.muNodes[c].resize(static_cast<std::size_t>(d.T));
        for (Eigen::Index t = 0; t < d.T; ++t) {
            const Restricted& mu = d.component(c, t, kPooledMu);
            for (std::size_t k = 0; k < kEtaNodes; ++k) e.muNodes[c][static_cast<std::size_t>(t)][k] = mu.quantile(e.u[k]);
            e.e1[c][t] = d.moment[kPooledMu][0][c][t] * d.moment[kPooledR][0][c][t];
            e.e2[c][t] = d.moment[kPooledMu][1][c][t] * d.moment[kPooledR][1][c][t];
        }
    }
    return e;
}

/// F_eta(x | psi_ct) = sum_k w_k F_r(x / mu_k); a node mu_k = 0 gives eta = 0 <= x, probability 1.
double etaCdf(const NewCellDraws& d, const EtaDraws& e, std::size_t c, Eigen::Index t, double x) {
    const Restricted& r = d.component(c, t, kPooledR);
    double s = 0.0;
    for (std::size_t k = 0; k < kEtaNodes; ++k) {
        const double mu = e.muNodes[c][static_cast<std::size_t>(t)][k];
        s += e.weights[k] * (mu > 0.0 ? r.cdf(x / mu) : 1.0);
    }
    return s;
}

/// f_eta(x | psi_ct) = sum_k w_k f_r(x / mu_k) / mu_k (d/dx of etaCdf; a node mu_k = 0 is a point
/// mass at 0 and adds no density).
double etaPdf(const NewCellDraws& d, const EtaDraws& e, std::size_t c, Eigen::Index t, double x) {
    const Restricted& r = d.component(c, t, kPooledR);
    double s = 0.0;
    for (std::size_t k = 0; k < kEtaNodes; ++k) {
        const double mu = e.muNodes[c][static_cast<std::size_t>(t)][k];
        s += mu > 0.0 ? e.weights[k] * r.pdf(x / mu) / mu : 0.0;
    }
    return s;
}

/// eta_m on its support [0, mu_hi r_hi] (mu, r >= 0 in B).
NewCellStatistic etaStatistics(const NewCellDraws& d, const NewCellBox& box) {
    const EtaDraws e = etaDraws(d);
    const double etaHi = box.hi[kPooledMu] * box.hi[kPooledR];
    return coordinateStatistics(
        d, "etam_Pa_s_um", 1.0, e.e1, e.e2, [&](std::size_t c, Eigen::Index t, double x) { return etaCdf(d, e, c, t, x); },
        [&](std::size_t c, Eigen::Index t, double x) { return etaPdf(d, e, c, t, x); }, 0.0, etaHi);
}

}  // namespace

std::vector<NewCellStatistic> newCellStatistics(const std::vector<Eigen::MatrixXd>& psiChains, const PopulationVariant& variant) {
    if (psiChains.empty()) throw InputError("theta_new: no hyper-parameter draws");
    const std::vector<PopulationComponent> pop = rbcPopulationComponents(variant);
    const NewCellBox box = newCellBox(variant);
    const NewCellDraws d = newCellDraws(psiChains, pop, box);
    std::vector<NewCellStatistic> out;
    const Eigen::VectorXd outScale = pooledOutputScale();
    for (int j = 0; j < kPooledDimension; ++j) {
        const auto J = static_cast<std::size_t>(j);
        out.push_back(coordinateStatistics(
            d, pooledOutputNames()[J], outScale[j], d.moment[J][0], d.moment[J][1],
            [&](std::size_t c, Eigen::Index t, double x) { return d.component(c, t, J).cdf(x); },
            [&](std::size_t c, Eigen::Index t, double x) { return d.component(c, t, J).pdf(x); },
            std::max(pop[J].lo, box.lo[j]), std::min(pop[J].hi, box.hi[j])));
    }
    out.push_back(etaStatistics(d, box));
    return out;
}

}  // namespace trbc
