// The joint hierarchical sampler and its diagnostics against problems with known answers:
// R-hat and ESS of independent and AR(1) chains, truncated-normal moments against quadrature, and
// a normal-normal hierarchical problem in the red-cell layout (two groups see v, mu, kb, b2, as the
// two stretching data sets do; five see r) whose hyper-posterior factorises over the components and
// is computed on a grid. Both routes to theta_new (joint MCMC; phase-1 samples + re-weighting +
// TMCMC) must recover its mean and SD.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "inference/hierarchical.hpp"
#include "inference/hierarchical_mcmc.hpp"
#include "inference/mcmc_diagnostics.hpp"
#include "inference/population.hpp"
#include "inference/rbc_hierarchical.hpp"
#include "inference/rbc_problem.hpp"
#include "inference/statistics.hpp"

namespace trbc {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

Chains ar1Chains(int chains, int n, double phi, double shift, std::uint64_t seed) {
    Chains out;
    for (int c = 0; c < chains; ++c) {
        Rng rng(seed, static_cast<std::uint64_t>(c));
        Eigen::VectorXd x(n);
        double v = rng.normal() / std::sqrt(1.0 - phi * phi);
        for (int t = 0; t < n; ++t) {
            v = phi * v + rng.normal();
            x[t] = v + (c == 0 ? shift : 0.0);
        }
        out.push_back(x);
    }
    return out;
}

TEST(McmcDiagnostics, IndependentChainsHaveRhatOneAndFullEss) {
    const Chains c = ar1Chains(8, 1000, 0.0, 0.0, 1);
    const ChainDiagnostics d = chainDiagnostics(c);
    EXPECT_LT(d.rhat, 1.01);
    EXPECT_NEAR(d.essBulk / 8000.0, 1.0, 0.12);
    EXPECT_NEAR(d.essMean / 8000.0, 1.0, 0.12);
    EXPECT_GT(d.essTail, 0.7 * 8000.0);
}

TEST(McmcDiagnostics, Ar1EssMatchesItsIntegratedAutocorrelationTime) {
    // tau = (1 + phi) / (1 - phi) = 19 for phi = 0.9.
    const Chains c = ar1Chains(8, 20000, 0.9, 0.0, 2);
    const double ess = effectiveSampleSize(c), expected = 8.0 * 20000.0 / 19.0;
    EXPECT_NEAR(ess / expected, 1.0, 0.1);
    // MCSE of the mean against the spread of means over repetitions (sd of x = 1 / sqrt(1 - phi^2)).
    const McEstimate m = chainMean(c);
    EXPECT_NEAR(m.mcse, std::sqrt(1.0 / (1.0 - 0.81)) / std::sqrt(expected), 0.1 * m.mcse);
}

TEST(McmcDiagnostics, ShiftedOrRescaledChainRaisesRhat) {
    EXPECT_GT(chainDiagnostics(ar1Chains(4, 1000, 0.5, 1.0, 3)).rhat, 1.05);
    Chains c = ar1Chains(4, 1000, 0.0, 0.0, 4);
    c[1] *= 3.0;  // same location, another scale: only the folded R-hat sees it
    EXPECT_LT(splitRhat(c), 1.05);
    EXPECT_GT(chainDiagnostics(c).rhat, 1.05);
}

TEST(McmcDiagnostics, QuantileAndSdMcseAreCalibratedOverRepetitions) {
    // 200 repetitions of 4 AR(1) chains: the stated MCSE against the observed SD of the estimates.
    std::vector<double> q, sd, mq, msd;
    for (int r = 0; r < 200; ++r) {
        const Chains c = ar1Chains(4, 500, 0.5, 0.0, 100 + static_cast<std::uint64_t>(r));
        const McEstimate a = chainQuantile(c, 0.9), b = chainSd(c);
        q.push_back(a.value), mq.push_back(a.mcse), sd.push_back(b.value), msd.push_back(b.mcse);
    }
    auto sdOf = [](const std::vector<double>& x) { return populationSd(Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(x.size()))); };
    auto meanOf = [](const std::vector<double>& x) { return mean(Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(x.size()))); };
    // 200 repetitions give the observed SD to +-10 % (1 sigma); allow 25 %.
    EXPECT_NEAR(meanOf(mq) / sdOf(q), 1.0, 0.25);
    EXPECT_NEAR(meanOf(msd) / sdOf(sd), 1.0, 0.25);
}

TEST(TruncatedNormal, MomentsAndCdfMatchQuadratureIncludingFarTails) {
    struct Case { double m, s, a, b; };
    for (const Case& k : {Case{0.3, 1.0, -0.5, 2.0}, Case{0.0, 1.0, 5.0, 9.0}, Case{0.0, 1.0, -40.0, -30.0}, Case{0.9, 0.05, 0.65, 1.0},
                          Case{2.0, 10.0, 0.0, 10.0}, Case{0.0, 1.0, 3.0, kInf}, Case{5.0, 2.0, -kInf, 1.0}}) {
        // Simpson on [a', b'] (infinite ends cut 40 sd out), relative to the peak inside.
        const double a = std::isinf(k.a) ? k.m - 40 * k.s : k.a, b = std::isinf(k.b) ? k.m + 40 * k.s : k.b;
        const int n = 200000;
        const double h = (b - a) / n, peak = std::clamp(k.m, a, b);
        double z = 0, m1 = 0, m2 = 0;
        for (int i = 0; i <= n; ++i) {
            const double x = a + i * h, w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
            const double f = std::exp(-0.5 * ((x - k.m) * (x - k.m) - (peak - k.m) * (peak - k.m)) / (k.s * k.s));
            z += w * f, m1 += w * f * x, m2 += w * f * x * x;
        }
        m1 /= z, m2 /= z;
        const TruncatedMoments t = truncatedNormalMoments(k.m, k.s, k.a, k.b);
        const double sd = std::sqrt(m2 - m1 * m1);
        EXPECT_NEAR(t.mean, m1, 1e-7 * (std::abs(m1) + sd)) << k.m << " " << k.a << " " << k.b;
        EXPECT_NEAR(std::sqrt(t.variance), sd, 1e-6 * sd) << k.m << " " << k.a << " " << k.b;
        const double logZ = std::log(z * h / 3.0 / (std::sqrt(2.0 * std::numbers::pi) * k.s)) - 0.5 * (peak - k.m) * (peak - k.m) / (k.s * k.s);
        EXPECT_NEAR(t.logMass, logZ, 1e-6);
        // CDF at the mean against Simpson on [a', mean].
        double below = 0.0;
        const double hb = (t.mean - a) / n;
        for (int i = 0; i <= n; ++i) {
            const double x = a + i * hb, w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
            below += w * std::exp(-0.5 * ((x - k.m) * (x - k.m) - (peak - k.m) * (peak - k.m)) / (k.s * k.s));
        }
        EXPECT_NEAR(truncatedNormalCdf(t.mean, k.m, k.s, k.a, k.b), below * hb / (z * h), 1e-8) << k.m << " " << k.a << " " << k.b;
    }
}

// ------------------------------------------------------------------------------------------------
// Normal-normal problem in the red-cell layout

struct GroupData {
    RbcExperiment experiment;
    std::vector<double> ybar, s;  ///< per pooled coordinate of the group
};

std::vector<GroupData> normalNormalGroups() {
    return {{RbcExperiment::Stretching, {0.92, 5.0, 0.35, 1.2}, {0.03, 0.8, 0.08, 0.6}},
            {RbcExperiment::Stretching, {0.96, 6.5, 0.25, 2.4}, {0.02, 1.2, 0.06, 0.9}},
            {RbcExperiment::Relaxation, {0.15}, {0.01}},
            {RbcExperiment::Relaxation, {0.22}, {0.02}},
            {RbcExperiment::Relaxation, {0.19}, {0.015}},
            {RbcExperiment::Relaxation, {0.30}, {0.03}},
            {RbcExperiment::Relaxation, {0.12}, {0.01}}};
}

RbcDataSet layoutDataSet(RbcExperiment e, int i) {
    RbcDataSet d;
    d.name = "group" + std::to_string(i);
    d.experiment = e;
    d.aspect = Eigen::Vector2d(2.0, 1.5);
    return d;
}

/// Group likelihood: independent normals on the pooled coordinates, and N(0.5, 0.1^2)-like terms on
/// the error-model variables (they do not touch the population, so the hyper-posterior stays exact).
double groupLogLikelihood(const GroupData& g, const Eigen::VectorXd& y) {
    double l = 0.0;
    for (std::size_t k = 0; k < g.ybar.size(); ++k) l -= 0.5 * std::pow((y[static_cast<Eigen::Index>(k)] - g.ybar[k]) / g.s[k], 2);
    return l;
}

/// Exact draws of a group's phase-1 posterior (likelihood x phase-1 prior), by rejection from the
/// prior restricted to +-6 s around the data.
Eigen::MatrixXd exactPhase1Samples(const GroupData& g, const RbcDataSet& d, int n, std::uint64_t seed) {
    const auto prior = phase1Prior(d);
    Rng rng(seed, 77);
    Eigen::MatrixXd x(prior->dimension(), n);
    double maxLogPrior = -kInf;
    for (int k = 0; k < 20000; ++k) maxLogPrior = std::max(maxLogPrior, prior->logDensity(prior->sample(rng)));
    for (int k = 0; k < n;) {
        Eigen::VectorXd y = prior->sample(rng);
        for (std::size_t j = 0; j < g.ybar.size(); ++j) y[static_cast<Eigen::Index>(j)] = g.ybar[j] + g.s[j] * (12.0 * rng.uniform() - 6.0);
        const double lp = prior->logDensity(y);
        if (!(lp > -kInf)) continue;
        // target / proposal = exp(l) pi(pooled) / const: accept with that ratio
        double lpPooled = 0.0;
        for (std::size_t j = 0; j < g.ybar.size(); ++j) lpPooled += prior->component(static_cast<int>(j)).logDensity(y[static_cast<Eigen::Index>(j)]);
        double maxPooled = 0.0;
        for (std::size_t j = 0; j < g.ybar.size(); ++j) {
            const ScalarPrior& c = prior->component(static_cast<int>(j));
            double best = -kInf;
            for (int i = 0; i <= 200; ++i) best = std::max(best, c.logDensity(c.lower() + (c.upper() - c.lower()) * i / 200.0));
            maxPooled += best + 0.01;
        }
        if (std::log(rng.uniformOpen()) < groupLogLikelihood(g, y) + lpPooled - maxPooled) x.col(k++) = y;
    }
    return x;
}

/// Exact theta_new mean and SD per pooled component by a grid over (m_j, s_j) (the hyper-posterior
/// factorises: each group's likelihood is a product over coordinates).
struct Exact { double mean, sd; };
std::vector<Exact> exactNewCell(const std::vector<GroupData>& groups) {
    const std::vector<PopulationComponent> pop = rbcPopulationComponents();
    const auto box = newCellBoxPrior();
    std::vector<Exact> out;
    for (int j = 0; j < kPooledDimension; ++j) {
        const PopulationComponent& p = pop[static_cast<std::size_t>(j)];
        std::vector<std::pair<double, double>> seen;  // (ybar, s) of the groups that see j
        std::vector<std::pair<double, double>> support;
        for (std::size_t i = 0; i < groups.size(); ++i) {
            const GroupData& g = groups[i];
            const auto prior = phase1Prior(layoutDataSet(g.experiment, static_cast<int>(i)));
            const int k = g.experiment == RbcExperiment::Relaxation ? (j == kPooledR ? 0 : -1) : (j < kPooledR ? j : -1);
            if (k < 0) continue;
            seen.push_back({g.ybar[static_cast<std::size_t>(k)], g.s[static_cast<std::size_t>(k)]});
            support.push_back({std::max(p.lo, prior->component(k).lower()), std::min(p.hi, prior->component(k).upper())});
        }
        const double a3 = std::max(p.lo, box->component(j).lower()), b3 = std::min(p.hi, box->component(j).upper());
        const int n = 500;
        double W = 0, M1 = 0, M2 = 0;
        for (int im = 0; im < n; ++im)
            for (int is = 0; is < n; ++is) {
                const double m = p.meanLo + (p.meanHi - p.meanLo) * (im + 0.5) / n, t = p.sdLo + (p.sdHi - p.sdLo) * (is + 0.5) / n;
                const double logZ = (std::isfinite(p.lo) || std::isfinite(p.hi)) ? logNormalMass((p.lo - m) / t, (p.hi - m) / t) : 0.0;
                double l = 0.0;
                for (std::size_t i = 0; i < seen.size(); ++i) {
                    const auto [y, s] = seen[i];
                    const double v = 1.0 / (1.0 / (s * s) + 1.0 / (t * t)), mu = v * (y / (s * s) + m / (t * t));
                    l += -0.5 * (y - m) * (y - m) / (s * s + t * t) - 0.5 * std::log(s * s + t * t) +
                         logNormalMass((support[i].first - mu) / std::sqrt(v), (support[i].second - mu) / std::sqrt(v)) - logZ;
                }
                const TruncatedMoments tm = truncatedNormalMoments(m, t, a3, b3);
                const double w = std::exp(l + tm.logMass - logZ);
                W += w, M1 += w * tm.mean, M2 += w * (tm.variance + tm.mean * tm.mean);
            }
        M1 /= W, M2 /= W;
        out.push_back({M1, std::sqrt(M2 - M1 * M1)});
    }
    return out;
}

HierarchicalModel normalNormalModel(const std::vector<GroupData>& groups, const std::vector<Eigen::MatrixXd>& starts) {
    HierarchicalModel h;
    h.population = rbcPopulationComponents();
    for (std::size_t i = 0; i < groups.size(); ++i) {
        const GroupData g = groups[i];
        const RbcDataSet d = layoutDataSet(g.experiment, static_cast<int>(i));
        const auto prior = phase1Prior(d);
        HierarchicalGroup G;
        G.name = d.name;
        G.names = phase1ParameterNames(d.experiment);
        G.pooled = g.experiment == RbcExperiment::Relaxation ? std::vector<int>{kPooledR} : std::vector<int>{kPooledV, kPooledMu, kPooledKb, kPooledB2};
        const int np = static_cast<int>(G.pooled.size());
        G.logSupport = [prior, np](const Eigen::VectorXd& y) {
            double s = 0.0;
            for (int j = 0; j < prior->dimension(); ++j) {
                if (!prior->component(j).inSupport(y[j])) return -kInf;
                if (j >= np) s += prior->component(j).logDensity(y[j]);
            }
            return s;
        };
        G.batchLogLikelihood = [g](const Eigen::MatrixXd& y) {
            Eigen::VectorXd l(y.cols());
            for (Eigen::Index k = 0; k < y.cols(); ++k) l[k] = groupLogLikelihood(g, y.col(k));
            return l;
        };
        G.start = starts[i];
        h.groups.push_back(G);
    }
    return h;
}

TEST(HierarchicalMcmc, NormalNormalTheJointSamplerRecoversThetaNewWithinItsMcse) {
    const std::vector<GroupData> groups = normalNormalGroups();
    std::vector<Eigen::MatrixXd> starts;
    for (std::size_t i = 0; i < groups.size(); ++i)
        starts.push_back(exactPhase1Samples(groups[i], layoutDataSet(groups[i].experiment, static_cast<int>(i)), 400, 10 + i));
    HierarchicalMcmcOptions o;
    o.chains = 8;
    o.warmup = 1000;
    o.draws = 3000;
    o.seed = 5;
    const HierarchicalMcmcResult r = runHierarchicalMcmc(normalNormalModel(groups, starts), o);
    for (int p = 0; p < 2 * kPooledDimension; ++p) {
        Chains c;
        for (const auto& h : r.hyper) c.push_back(h.row(p).transpose());
        const ChainDiagnostics d = chainDiagnostics(c);
        EXPECT_LT(d.rhat, 1.01) << hyperParameterNames()[static_cast<std::size_t>(p)];
        EXPECT_GT(d.essBulk, 400) << hyperParameterNames()[static_cast<std::size_t>(p)];
    }
    const std::vector<Exact> exact = exactNewCell(groups);
    const std::vector<NewCellStatistic> st = newCellStatistics(r.hyper);
    const Eigen::VectorXd scale = pooledOutputScale();
    for (int j = 0; j < kPooledDimension; ++j) {
        const NewCellStatistic& s = st[static_cast<std::size_t>(j)];
        const double m = exact[static_cast<std::size_t>(j)].mean * scale[j], sd = exact[static_cast<std::size_t>(j)].sd * scale[j];
        // 4 MCSE: a false alarm in 1 of ~16000 per check.
        std::cerr << s.name << ": mean error " << (s.mean.value - m) / s.mean.mcse << " MCSE, SD error " << (s.sd.value - sd) / s.sd.mcse
                  << " MCSE; MCSE of the mean " << s.mean.mcse / sd << " SD\n";
        EXPECT_NEAR(s.mean.value, m, 4.0 * s.mean.mcse) << s.name << " (MCSE " << s.mean.mcse / sd << " SD)";
        EXPECT_NEAR(s.sd.value, sd, 4.0 * s.sd.mcse) << s.name;
        EXPECT_LT(s.mean.mcse, 0.1 * sd) << s.name;
    }
}

TEST(HierarchicalMcmc, NormalNormalTheThreePhaseRouteRecoversThetaNew) {
    const std::vector<GroupData> groups = normalNormalGroups();
    std::vector<ReweightingSamples> sets;
    for (std::size_t i = 0; i < groups.size(); ++i) {
        const RbcDataSet d = layoutDataSet(groups[i].experiment, static_cast<int>(i));
        sets.push_back(reweightingSamples(d, exactPhase1Samples(groups[i], d, 5000, 30 + i)));
    }
    TmcmcOptions opt;
    opt.populationSize = 4000;
    opt.targetCoV = 0.4;
    opt.covarianceScaling = 0.06;
    opt.burnIn = {2};
    opt.seed = 7;
    const TmcmcResult r = runTmcmc(phase2Problem(sets), opt);
    const std::vector<Exact> exact = exactNewCell(groups);
    const std::vector<NewCellStatistic> st = newCellStatistics({r.samples});
    const Eigen::VectorXd scale = pooledOutputScale();
    for (int j = 0; j < kPooledDimension; ++j) {
        const NewCellStatistic& s = st[static_cast<std::size_t>(j)];
        const double m = exact[static_cast<std::size_t>(j)].mean * scale[j], sd = exact[static_cast<std::size_t>(j)].sd * scale[j];
        std::cerr << s.name << ": mean error " << (s.mean.value - m) / sd << " SD, SD error " << (s.sd.value - sd) / sd << "\n";
        EXPECT_NEAR(s.mean.value, m, 0.1 * sd) << s.name << " exact " << m << " sd " << sd;
        EXPECT_NEAR(s.sd.value, sd, 0.1 * sd) << s.name << " exact sd " << sd;
    }
}

}  // namespace
}  // namespace trbc
