// Priors of the generic sampler (docs/BAYESIAN_INFERENCE.md) and their random numbers.
//
// Monte-Carlo tolerances: a sample mean of n draws has standard error sd / sqrt(n), a sample
// variance sqrt((m4 - var^2) / n) (m4 = fourth central moment, estimated from the same draws).
// Checks use 5 standard errors, so a correct sampler fails with probability < 1e-6 per check
// (and the seeds are fixed, so the outcome is reproducible anyway).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "core/error.hpp"
#include "inference/priors.hpp"

namespace trbc {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Composite Simpson rule with `m` (even) intervals on [a, b].
template <class F>
double simpson(F&& f, double a, double b, int m = 20000) {
    const double h = (b - a) / m;
    double s = f(a) + f(b);
    for (int i = 1; i < m; ++i) s += (i % 2 ? 4.0 : 2.0) * f(a + i * h);
    return s * h / 3.0;
}

/// Integral of the density over [a, b], split at the given interior kinks.
double integrateDensity(const ScalarPrior& p, double a, double b, std::vector<double> kinks = {}) {
    kinks.push_back(a);
    kinks.push_back(b);
    std::sort(kinks.begin(), kinks.end());
    double total = 0.0;
    for (std::size_t i = 0; i + 1 < kinks.size(); ++i) {
        const double lo = std::max(a, kinks[i]), hi = std::min(b, kinks[i + 1]);
        if (hi > lo) total += simpson([&](double x) { return std::exp(p.logDensity(x)); }, lo, hi);
    }
    return total;
}

struct SampleMoments {
    double mean = 0, var = 0, seMean = 0, seVar = 0;
};

SampleMoments drawMoments(const ScalarPrior& p, int n, std::uint64_t seed) {
    Rng rng(seed);
    std::vector<double> x(static_cast<std::size_t>(n));
    for (auto& v : x) v = p.sample(rng);
    SampleMoments m;
    for (double v : x) m.mean += v;
    m.mean /= n;
    double m4 = 0;
    for (double v : x) {
        const double d = v - m.mean;
        m.var += d * d;
        m4 += d * d * d * d;
    }
    m.var /= n;
    m4 /= n;
    m.seMean = std::sqrt(m.var / n);
    m.seVar = std::sqrt((m4 - m.var * m.var) / n);
    return m;
}

void expectMoments(const ScalarPrior& p, double mean, double var, std::uint64_t seed) {
    const SampleMoments m = drawMoments(p, 200000, seed);
    EXPECT_NEAR(m.mean, mean, 5 * m.seMean) << p.describe();
    EXPECT_NEAR(m.var, var, 5 * m.seVar) << p.describe();
}

// Analytic moments of N(m, s^2) truncated to [lo, hi].
void truncatedNormalMoments(double m, double s, double lo, double hi, double& mean, double& var) {
    const double a = (lo - m) / s, b = (hi - m) / s;
    const double Z = normalCdf(b) - normalCdf(a);
    const double r = (normalPdf(a) - normalPdf(b)) / Z;
    mean = m + s * r;
    const double aPhi = std::isinf(a) ? 0.0 : a * normalPdf(a), bPhi = std::isinf(b) ? 0.0 : b * normalPdf(b);
    var = s * s * (1 + (aPhi - bPhi) / Z - r * r);
}

// The two ratio-uniform priors of docs/BAYESIAN_INFERENCE.md.
ScalarPriorPtr fvkPrior() { return ratioUniformPrior(1.0, 10.0, 0.01, 0.1); }
ScalarPriorPtr rPrior() { return ratioUniformPrior(0.1, 1.0, 1.0, 10.0); }

TEST(PriorRng, StreamsAreDeterministicAndDistinct) {
    Rng a(42, 1, 2, 3), b(42, 1, 2, 3), c(42, 1, 2, 4), d(42, 2, 1, 3);
    for (int i = 0; i < 100; ++i) {
        const auto x = a();
        EXPECT_EQ(x, b());
        EXPECT_NE(x, c());
        EXPECT_NE(x, d());
    }
}

TEST(PriorRng, UniformAndNormalMoments) {
    Rng rng(7);
    const int n = 400000;
    double su = 0, su2 = 0, sn = 0, sn2 = 0, sn4 = 0, umin = 1, umax = 0;
    for (int i = 0; i < n; ++i) {
        const double u = rng.uniformOpen();
        umin = std::min(umin, u);
        umax = std::max(umax, u);
        su += u;
        su2 += u * u;
        const double z = rng.normal();
        sn += z;
        sn2 += z * z;
        sn4 += z * z * z * z;
    }
    EXPECT_GT(umin, 0.0);
    EXPECT_LT(umax, 1.0);
    // U(0,1): mean 1/2 (SE sqrt(1/12/n)), E u^2 = 1/3 (SE sqrt(4/45/n)).
    EXPECT_NEAR(su / n, 0.5, 5 * std::sqrt(1.0 / 12 / n));
    EXPECT_NEAR(su2 / n, 1.0 / 3, 5 * std::sqrt(4.0 / 45 / n));
    // N(0,1): mean 0 (SE 1/sqrt n), E z^2 = 1 (SE sqrt(2/n)), E z^4 = 3 (SE sqrt(96/n)).
    EXPECT_NEAR(sn / n, 0.0, 5 / std::sqrt(n));
    EXPECT_NEAR(sn2 / n, 1.0, 5 * std::sqrt(2.0 / n));
    EXPECT_NEAR(sn4 / n, 3.0, 5 * std::sqrt(96.0 / n));
}

TEST(PriorNormalHelpers, QuantileInvertsCdf) {
    for (double p : {1e-300, 1e-100, 1e-20, 1e-8, 0.001, 0.025, 0.3, 0.5, 0.7, 0.975, 0.999999}) {
        const double x = normalQuantile(p);
        // compare in the tail that holds the precision: Phi(x) / p or Phi(-x) / (1 - p)
        const double back = p < 0.5 ? normalCdf(x) / p : normalCdf(-x) / (1.0 - p);
        EXPECT_NEAR(back, 1.0, 1e-12) << "p = " << p;
    }
    EXPECT_NEAR(normalQuantile(0.975), 1.959963984540054, 1e-14);
    EXPECT_NEAR(normalQuantile(0.5), 0.0, 1e-15);
    // log mass in the far tail: log(Phi(-30) - Phi(-40)) = log Phi(-30) (no underflow to -inf)
    EXPECT_NEAR(logNormalMass(30.0, 40.0), std::log(0.5 * std::erfc(30.0 / std::numbers::sqrt2)), 1e-10);
    EXPECT_NEAR(logNormalMass(-kInf, kInf), 0.0, 1e-15);
}

TEST(PriorDensity, IntegratesToOne) {
    // Simpson with 20000 intervals per smooth piece: error far below 1e-8 for these densities.
    const double tol = 1e-8;
    EXPECT_NEAR(integrateDensity(*uniformPrior(-2.0, 3.0), -2.0, 3.0), 1.0, tol);
    EXPECT_NEAR(integrateDensity(*normalPrior(1.0, 0.5), 1.0 - 20 * 0.5, 1.0 + 20 * 0.5), 1.0, tol);
    EXPECT_NEAR(integrateDensity(*normalPrior(1.0, 2.0, 0.0, 1.5), 0.0, 1.5), 1.0, tol);
    EXPECT_NEAR(integrateDensity(*normalPrior(0.0, 1.0, 3.0, kInf), 3.0, 30.0), 1.0, tol);  // tail truncation
    // Log-normal: integrate in y = log x, dx = e^y dy.
    const auto ln = logNormalPrior(0.3, 0.6);
    EXPECT_NEAR(simpson([&](double y) { return std::exp(ln->logDensity(std::exp(y)) + y); }, 0.3 - 15 * 0.6, 0.3 + 15 * 0.6),
                1.0, tol);
    const auto lnt = logNormalPrior(0.3, 0.6, 0.5, 4.0);
    EXPECT_NEAR(integrateDensity(*lnt, 0.5, 4.0), 1.0, tol);
    // Ratio-uniform: piecewise smooth with kinks at a/c and b/e (where min/max switch branch).
    const auto fvk = fvkPrior(), r = rPrior();
    EXPECT_NEAR(integrateDensity(*fvk, 10.0, 1000.0, {1.0 / 0.01, 10.0 / 0.1}), 1.0, tol);
    EXPECT_NEAR(integrateDensity(*r, 0.01, 1.0, {0.1 / 1.0, 1.0 / 10.0}), 1.0, tol);
    const auto ru = ratioUniformPrior(2.0, 3.0, 0.5, 4.0);  // a/c = 4 > b/e = 0.75
    EXPECT_NEAR(integrateDensity(*ru, 0.5, 6.0, {4.0, 0.75}), 1.0, tol);
}

TEST(PriorSampling, MatchesAnalyticMoments) {
    expectMoments(*uniformPrior(-2.0, 3.0), 0.5, 25.0 / 12, 1);
    expectMoments(*normalPrior(1.0, 0.5), 1.0, 0.25, 2);
    double m = 0, v = 0;
    truncatedNormalMoments(1.0, 2.0, 0.0, 1.5, m, v);
    expectMoments(*normalPrior(1.0, 2.0, 0.0, 1.5), m, v, 3);
    truncatedNormalMoments(0.0, 1.0, 3.0, kInf, m, v);
    expectMoments(*normalPrior(0.0, 1.0, 3.0, kInf), m, v, 4);
    truncatedNormalMoments(0.0, 1.0, -kInf, -8.0, m, v);  // far tail: inversion must stay accurate
    expectMoments(*normalPrior(0.0, 1.0, -kInf, -8.0), m, v, 5);
    // log-normal: E = exp(m + s^2/2), Var = (exp(s^2) - 1) exp(2m + s^2)
    const double mu = 0.3, s = 0.6;
    expectMoments(*logNormalPrior(mu, s), std::exp(mu + s * s / 2), (std::exp(s * s) - 1) * std::exp(2 * mu + s * s), 6);
    for (auto [a, b, c, e] : {std::array{1.0, 10.0, 0.01, 0.1}, {0.1, 1.0, 1.0, 10.0}, {2.0, 3.0, 0.5, 4.0}}) {
        const double m1 = ratioUniformMean(a, b, c, e), m2 = ratioUniformSecondMoment(a, b, c, e);
        expectMoments(*ratioUniformPrior(a, b, c, e), m1, m2 - m1 * m1, 7);
    }
}

TEST(PriorSampling, DrawsStayInSupport) {
    Rng rng(11);
    for (const auto& p : {uniformPrior(0.0, 1.0), normalPrior(0.0, 1.0, -0.1, 0.2), logNormalPrior(0.0, 2.0, 0.5, 3.0),
                          fvkPrior(), rPrior()})
        for (int i = 0; i < 20000; ++i) {
            const double x = p->sample(rng);
            ASSERT_TRUE(p->inSupport(x)) << p->describe() << " drew " << x;
            ASSERT_GT(p->logDensity(x), -kInf) << p->describe() << " at " << x;
        }
}

/// Histogram of 2e5 draws in 40 log-spaced bins against the bin probabilities integrated from
/// the density: |count - n P| <= 5 sqrt(n P (1 - P)) per bin; and the Kolmogorov-Smirnov
/// distance sqrt(n) D <= 1.95 (the 0.1 % critical value) against the integrated CDF.
void checkRatioUniformHistogram(const ScalarPrior& p, std::uint64_t seed) {
    const int n = 200000, bins = 40;
    Rng rng(seed);
    std::vector<double> x(n);
    for (auto& v : x) v = p.sample(rng);
    std::sort(x.begin(), x.end());
    const double lo = p.lower(), hi = p.upper(), ratio = std::log(hi / lo);
    std::vector<double> edges(bins + 1);
    for (int b = 0; b <= bins; ++b) edges[b] = lo * std::exp(ratio * b / bins);
    // CDF on a fine log grid (cumulative Simpson per cell), linear interpolation in between.
    const int cells = 20000;
    std::vector<double> grid(cells + 1), cdf(cells + 1, 0.0);
    for (int i = 0; i <= cells; ++i) grid[i] = lo * std::exp(ratio * i / cells);
    for (int i = 0; i < cells; ++i)
        cdf[i + 1] = cdf[i] + simpson([&](double z) { return std::exp(p.logDensity(z)); }, grid[i], grid[i + 1], 4);
    auto F = [&](double z) {
        const auto it = std::upper_bound(grid.begin(), grid.end(), z);
        if (it == grid.begin()) return 0.0;
        if (it == grid.end()) return 1.0;
        const std::size_t i = static_cast<std::size_t>(it - grid.begin()) - 1;
        return cdf[i] + (cdf[i + 1] - cdf[i]) * (z - grid[i]) / (grid[i + 1] - grid[i]);
    };
    EXPECT_NEAR(cdf.back(), 1.0, 1e-6);
    for (int b = 0; b < bins; ++b) {
        const double P = F(edges[b + 1]) - F(edges[b]);
        const auto count = std::lower_bound(x.begin(), x.end(), edges[b + 1]) - std::lower_bound(x.begin(), x.end(), edges[b]);
        EXPECT_NEAR(static_cast<double>(count), n * P, 5 * std::sqrt(n * P * (1 - P)) + 1) << p.describe() << " bin " << b;
    }
    double D = 0.0;
    for (int i = 0; i < n; ++i) {
        const double Fi = F(x[i]);
        D = std::max({D, std::abs(Fi - static_cast<double>(i) / n), std::abs(Fi - static_cast<double>(i + 1) / n)});
    }
    EXPECT_LT(std::sqrt(static_cast<double>(n)) * D, 1.95) << p.describe();
}

TEST(PriorRatioUniform, SamplerMatchesDensityByHistogram) {
    checkRatioUniformHistogram(*fvkPrior(), 21);
    checkRatioUniformHistogram(*rPrior(), 22);
}

TEST(PriorRatioUniform, DensityFormula) {
    // FvK prior: support [10, 1000]; p is continuous with p(10) = p(1000) = 0 and on
    // [a/c, ...] reduces to (b/z)^2 - c^2 etc. Check one point by hand: z = 50:
    // min(0.1, 10/50)^2 - max(0.01, 1/50)^2 = 0.01 - 0.0004 = 0.0096; / (2 * 9 * 0.09) = 0.0059259...
    const auto p = fvkPrior();
    EXPECT_NEAR(std::exp(p->logDensity(50.0)), 0.0096 / (2 * 9 * 0.09), 1e-15);
    EXPECT_EQ(p->logDensity(10.0), -kInf);  // density 0 at the support ends
    EXPECT_EQ(p->logDensity(1000.0), -kInf);
    EXPECT_DOUBLE_EQ(p->lower(), 10.0);
    EXPECT_DOUBLE_EQ(p->upper(), 1000.0);
    EXPECT_DOUBLE_EQ(rPrior()->lower(), 0.01);
    EXPECT_DOUBLE_EQ(rPrior()->upper(), 1.0);
}

TEST(PriorDensity, OutsideSupportIsMinusInfinity) {
    const auto u = uniformPrior(-1.0, 2.0);
    EXPECT_EQ(u->logDensity(-1.0 - 1e-12), -kInf);
    EXPECT_EQ(u->logDensity(2.0 + 1e-12), -kInf);
    EXPECT_DOUBLE_EQ(u->logDensity(-1.0), -std::log(3.0));
    EXPECT_DOUBLE_EQ(u->logDensity(2.0), -std::log(3.0));
    EXPECT_EQ(u->logDensity(std::nan("")), -kInf);
    const auto tn = normalPrior(0.0, 1.0, 0.0, 1.0);
    EXPECT_EQ(tn->logDensity(-1e-9), -kInf);
    EXPECT_EQ(tn->logDensity(1.5), -kInf);
    EXPECT_GT(normalPrior(0.0, 1.0)->logDensity(30.0), -kInf);  // untruncated: whole real line
    EXPECT_EQ(logNormalPrior(0.0, 1.0)->logDensity(0.0), -kInf);
    EXPECT_EQ(logNormalPrior(0.0, 1.0)->logDensity(-1.0), -kInf);
    EXPECT_EQ(logNormalPrior(0.0, 1.0, 1.0, 2.0)->logDensity(2.5), -kInf);
    EXPECT_EQ(fvkPrior()->logDensity(9.99), -kInf);
    EXPECT_EQ(fvkPrior()->logDensity(1000.01), -kInf);
    EXPECT_EQ(fvkPrior()->logDensity(-5.0), -kInf);
    int calls = 0;
    const auto custom = customScalarPrior(
        0.0, 1.0, [](Rng& r) { return r.uniform(); }, [&](double) { ++calls; return 0.0; });
    EXPECT_EQ(custom->logDensity(1.5), -kInf);
    EXPECT_EQ(calls, 0);  // the callback is not asked outside [lo, hi]
    EXPECT_EQ(custom->logDensity(0.5), 0.0);
    EXPECT_EQ(calls, 1);
    ProductPrior box({uniformPrior(0.0, 1.0), normalPrior(0.0, 1.0)});
    EXPECT_EQ(box.logDensity(Eigen::Vector2d(1.5, 0.0)), -kInf);
}

TEST(PriorProduct, SumsComponentLogDensitiesAndSamplesAll) {
    ProductPrior p({uniformPrior(0.0, 2.0), normalPrior(1.0, 0.5), fvkPrior()});
    EXPECT_EQ(p.dimension(), 3);
    const Eigen::Vector3d x(0.5, 1.2, 50.0);
    EXPECT_NEAR(p.logDensity(x),
                -std::log(2.0) + normalPrior(1.0, 0.5)->logDensity(1.2) + fvkPrior()->logDensity(50.0), 1e-14);
    Rng rng(3);
    for (int k = 0; k < 1000; ++k) {
        const Eigen::VectorXd t = p.sample(rng);
        ASSERT_EQ(t.size(), 3);
        ASSERT_GT(p.logDensity(t), -kInf);
    }
    EXPECT_THROW(p.logDensity(Eigen::Vector2d(0.5, 1.0)), InputError);
    const auto box = uniformBoxPrior(Eigen::Vector2d(-1, 0), Eigen::Vector2d(1, 5));
    EXPECT_DOUBLE_EQ(box->logDensity(Eigen::Vector2d(0, 1)), -std::log(10.0));
    EXPECT_EQ(box->lowerBounds(), Eigen::Vector2d(-1, 0));
    EXPECT_EQ(box->upperBounds(), Eigen::Vector2d(1, 5));
}

TEST(PriorCustom, MultivariateCallbacks) {
    // Standard bivariate normal given by callbacks.
    CustomPrior p(
        2, [](Rng& r) { return Eigen::Vector2d(r.normal(), r.normal()); },
        [](const Eigen::VectorXd& t) { return -0.5 * t.squaredNorm() - std::log(2 * std::numbers::pi); });
    EXPECT_EQ(p.dimension(), 2);
    EXPECT_NEAR(p.logDensity(Eigen::Vector2d(0, 0)), -std::log(2 * std::numbers::pi), 1e-15);
    Rng rng(5);
    EXPECT_EQ(p.sample(rng).size(), 2);
    CustomPrior wrong(3, [](Rng&) { return Eigen::VectorXd(Eigen::Vector2d(0, 0)); }, [](const Eigen::VectorXd&) { return 0.0; });
    EXPECT_THROW(wrong.sample(rng), InputError);
}

TEST(PriorErrors, InvalidParametersThrowInputError) {
    auto expectMessage = [](auto&& make, const std::string& word) {
        try {
            make();
            ADD_FAILURE() << "no exception, expected one naming " << word;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    expectMessage([] { uniformPrior(1.0, 1.0); }, "a < b");
    expectMessage([] { uniformPrior(0.0, kInf); }, "b");
    expectMessage([] { normalPrior(0.0, 0.0); }, "sd");
    expectMessage([] { normalPrior(0.0, 1.0, 2.0, 1.0); }, "lo < hi");
    expectMessage([] { normalPrior(0.0, 1.0, 60.0, 70.0); }, "no probability mass");
    expectMessage([] { logNormalPrior(0.0, -1.0); }, "sdLog");
    expectMessage([] { logNormalPrior(0.0, 1.0, -1.0); }, "lo");
    expectMessage([] { ratioUniformPrior(0.0, 1.0, 1.0, 2.0); }, "0 < a < b");
    expectMessage([] { ratioUniformPrior(1.0, 2.0, 3.0, 2.0); }, "0 < c < e");
    expectMessage([] { ProductPrior({}); }, "dimension");
    expectMessage([] { CustomPrior(0, nullptr, nullptr); }, "dimension");
    expectMessage([] { customScalarPrior(0.0, 1.0, nullptr, [](double) { return 0.0; }); }, "sampler");
}

}  // namespace
}  // namespace trbc
