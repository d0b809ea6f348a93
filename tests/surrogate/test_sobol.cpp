// Sobol' sequence and Sobol' sensitivity indices (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices): Joe-Kuo points,
// stratification, QMC integration; Ishigami and linear-model analytic indices, bootstrap coverage,
// invariances, ignored inputs, determinism, batching, CSV output and bad options.
#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "surrogate/sobol.hpp"
#include "surrogate/sobol_io.hpp"
#include "sampling/sobol_sequence.hpp"
#include "surrogate/surrogate_sobol.hpp"

namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using trbc::SobolBase;
using trbc::SobolOptions;
using trbc::SobolResult;
using trbc::SobolSequence;

constexpr double kPi = std::numbers::pi;

// ---------------------------------------------------------------------------------------------
// Sobol' sequence
// ---------------------------------------------------------------------------------------------

TEST(SobolSequence, FirstPointsOfDimensionsOneToThree) {
    SobolSequence seq(3);  // default skip = 1 drops the origin
    const MatrixXd P = seq.next(7);
    const double d1[] = {0.5, 0.75, 0.25, 0.375, 0.875, 0.625, 0.125};
    const double d2[] = {0.5, 0.25, 0.75, 0.375, 0.875, 0.125, 0.625};
    const double d3[] = {0.5, 0.25, 0.75, 0.625, 0.125, 0.875, 0.375};
    for (int k = 0; k < 7; ++k) {
        EXPECT_EQ(P(k, 0), d1[k]) << "point " << k + 1;
        EXPECT_EQ(P(k, 1), d2[k]) << "point " << k + 1;
        EXPECT_EQ(P(k, 2), d3[k]) << "point " << k + 1;
    }
    EXPECT_EQ(seq.index(), 8u);
    SobolSequence raw(3, 0);
    EXPECT_EQ(raw.next(), VectorXd::Zero(3));
}

// All 21 built-in dimensions at two indices, as integers x * 2^32. Reference values from an
// independent implementation of the same Joe-Kuo table (SciPy 1.10 qmc.Sobol, scramble=False).
// Index 0x2AAAAAAA has Gray code 2^30 - 1, so the point is the XOR of the first 30 direction
// numbers of every dimension: a check of the typed table and of the recurrence.
TEST(SobolSequence, MatchesReferenceImplementationInAllDimensions) {
    const std::array<std::uint64_t, 21> at1000 = {
        943718400u,  415236096u,  2227175424u, 2906652672u, 1203765248u, 3896508416u, 197132288u,
        3862953984u, 2151677952u, 297795584u,  364904448u,  1094713344u, 692060160u,  1648361472u,
        616562688u,  1589641216u, 3091202048u, 1480589312u, 4257218560u, 3116367872u, 2243952640u};
    const std::array<std::uint64_t, 21> atGray30 = {
        4294967292u, 1431655764u, 67126340u,   1074528188u, 3221712244u, 8158332u,    4223180u,
        3473290428u, 2345404284u, 3125233268u, 3641874548u, 3453699596u, 3422294012u, 1979511628u,
        657617900u,  3741906156u, 1090731260u, 835132636u,  1964425372u, 263679700u,  1677736052u};
    SobolSequence seq(SobolSequence::kMaxDimensions, 1000);
    const VectorXd p = seq.next();
    seq.seek(0x2AAAAAAAu);
    const VectorXd q = seq.next();
    for (int j = 0; j < SobolSequence::kMaxDimensions; ++j) {
        EXPECT_EQ(p[j] * 0x1p32, static_cast<double>(at1000[j])) << "dimension " << j + 1;
        EXPECT_EQ(q[j] * 0x1p32, static_cast<double>(atGray30[j])) << "dimension " << j + 1;
    }
}

TEST(SobolSequence, SeekEqualsSequentialGeneration) {
    SobolSequence a(7, 0), b(7, 0);
    const MatrixXd P = a.next(3000);
    for (std::uint64_t n : {0u, 1u, 2u, 1023u, 1024u, 2047u, 2999u}) {
        b.seek(n);
        EXPECT_EQ(b.next(), P.row(static_cast<Index>(n)).transpose()) << "index " << n;
    }
}

// The first 2^k points (origin included) of every coordinate are a permutation of j / 2^k.
TEST(SobolSequence, FirstPowerOfTwoPointsArePermutationsOfTheGrid) {
    const int dims = SobolSequence::kMaxDimensions;
    SobolSequence seq(dims, 0);
    const MatrixXd P = seq.next(1 << 12);
    for (int k = 0; k <= 12; ++k) {
        const Index n = Index{1} << k;
        for (int j = 0; j < dims; ++j) {
            std::vector<double> c(P.col(j).data(), P.col(j).data() + n);
            std::sort(c.begin(), c.end());
            for (Index i = 0; i < n; ++i)
                ASSERT_EQ(c[i], static_cast<double>(i) / static_cast<double>(n)) << "k = " << k << ", dimension " << j + 1;
        }
    }
}

// An aligned block [q 2^m, q 2^m + 2^k), k <= m, puts one value of every coordinate in each
// interval [i 2^-k, (i+1) 2^-k) (the block used by the Saltelli design with the default skip).
TEST(SobolSequence, AlignedBlockIsStratified) {
    const int dims = 10;
    SobolSequence seq(dims, 1024);
    const MatrixXd P = seq.next(1024);
    for (int k : {4, 8, 10}) {
        const Index n = Index{1} << k;
        for (int j = 0; j < dims; ++j) {
            std::vector<int> count(static_cast<std::size_t>(n), 0);
            for (Index i = 0; i < n; ++i) ++count[static_cast<std::size_t>(std::floor(P(i, j) * static_cast<double>(n)))];
            EXPECT_TRUE(std::all_of(count.begin(), count.end(), [](int c) { return c == 1; }))
                << "k = " << k << ", dimension " << j + 1;
        }
    }
}

// QMC integration of the smooth product f(x) = prod_{j=1..10} (1 + 3 (x_j - 1/2) / j), integral 1,
// Var f = prod_j (1 + 3/(4 j^2)) - 1: the Sobol' error at n = 2^14 (raw sequence from the origin)
// must be far below the plain Monte Carlo standard error sigma / sqrt(n).
TEST(SobolSequence, LowDiscrepancyIntegration) {
    const int dims = 10;
    auto f = [&](const Eigen::Ref<const VectorXd>& x) {
        double p = 1;
        for (int j = 0; j < dims; ++j) p *= 1.0 + 3.0 * (x[j] - 0.5) / (j + 1.0);
        return p;
    };
    double second = 1;
    for (int j = 0; j < dims; ++j) second *= 1.0 + 0.75 / ((j + 1.0) * (j + 1.0));
    const double sigma = std::sqrt(second - 1.0);

    const Index n = Index{1} << 14;
    SobolSequence seq(dims, 0);
    const MatrixXd P = seq.next(n);
    double sum = 0;
    for (Index i = 0; i < n; ++i) sum += f(P.row(i).transpose());
    const double qmcError = std::abs(sum / static_cast<double>(n) - 1.0);
    const double mcStandardError = sigma / std::sqrt(static_cast<double>(n));
    std::cout << "[ sobol ] QMC error " << qmcError << ", MC standard error " << mcStandardError << "\n";
    EXPECT_LT(qmcError, 0.1 * mcStandardError);  // measured ratio about 0.02
}

TEST(SobolSequence, RejectsBadArguments) {
    EXPECT_THROW(SobolSequence(0), trbc::InputError);
    EXPECT_THROW(SobolSequence(SobolSequence::kMaxDimensions + 1), trbc::InputError);
    EXPECT_THROW(SobolSequence(2, std::uint64_t{1} << 32), trbc::InputError);
    SobolSequence seq(2, (std::uint64_t{1} << 32) - 1);
    EXPECT_NO_THROW(seq.next());
    EXPECT_THROW(seq.next(), trbc::InputError);
    try {
        SobolSequence bad(30);
        FAIL();
    } catch (const trbc::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("dimensions = 30"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("1 to 21"), std::string::npos) << e.what();
    }
}

// ---------------------------------------------------------------------------------------------
// Sobol' indices
// ---------------------------------------------------------------------------------------------

// Ishigami function, a = 7, b = 0.1, X_i ~ U[-pi, pi].
MatrixXd ishigami(const MatrixXd& X) {
    MatrixXd Y(X.rows(), 1);
    for (Index k = 0; k < X.rows(); ++k) {
        const double s1 = std::sin(X(k, 0)), s2 = std::sin(X(k, 1));
        Y(k, 0) = s1 + 7.0 * s2 * s2 + 0.1 * std::pow(X(k, 2), 4) * s1;
    }
    return Y;
}
const VectorXd kIshigamiLo = VectorXd::Constant(3, -kPi);
const VectorXd kIshigamiHi = VectorXd::Constant(3, kPi);
constexpr std::array<double, 3> kS1 = {0.313905, 0.442411, 0.0};
constexpr std::array<double, 3> kST = {0.557589, 0.442411, 0.243684};
constexpr std::array<std::array<int, 2>, 3> kPairs = {{{0, 1}, {0, 2}, {1, 2}}};
constexpr std::array<double, 3> kS2 = {0.0, 0.243684, 0.0};  // S12, S13, S23

TEST(SobolIndices, AnalyticIshigamiValuesAreConsistent) {
    // V_1 = (1 + b pi^4/5)^2 / 2, V_2 = a^2/8, V_13 = b^2 pi^8 (1/18 - 1/50), V = sum.
    const double a = 7, b = 0.1, p4 = std::pow(kPi, 4), p8 = p4 * p4;
    const double V1 = 0.5 * std::pow(1 + b * p4 / 5, 2), V2 = a * a / 8, V13 = b * b * p8 * (1.0 / 18 - 1.0 / 50);
    const double V = a * a / 8 + b * p4 / 5 + b * b * p8 / 18 + 0.5;
    EXPECT_NEAR(V1 + V2 + V13, V, 1e-12);
    EXPECT_NEAR(V1 / V, kS1[0], 1e-6);
    EXPECT_NEAR(V2 / V, kS1[1], 1e-6);
    EXPECT_NEAR((V1 + V13) / V, kST[0], 1e-6);
    EXPECT_NEAR(V13 / V, kS2[1], 1e-6);
}

struct IshigamiErrors {
    double maxError = 0;
    std::string report;
};

IshigamiErrors ishigamiErrors(const SobolResult& r) {
    IshigamiErrors e;
    std::ostringstream os;
    os.precision(4);
    for (int i = 0; i < 3; ++i) {
        const double e1 = std::abs(r.S1(0, i) - kS1[i]), eT = std::abs(r.ST(0, i) - kST[i]);
        e.maxError = std::max({e.maxError, e1, eT});
        os << " S" << i + 1 << " " << r.S1(0, i) << " (err " << e1 << "), ST" << i + 1 << " " << r.ST(0, i) << " (err " << eT << ");";
    }
    for (int p = 0; p < 3; ++p) {
        const double v = r.S2[0](kPairs[p][0], kPairs[p][1]), err = std::abs(v - kS2[p]);
        e.maxError = std::max(e.maxError, err);
        os << " S" << kPairs[p][0] + 1 << kPairs[p][1] + 1 << " " << v << " (err " << err << ");";
    }
    e.report = os.str();
    return e;
}

SobolResult ishigamiAnalysis(Index n, SobolBase base, std::uint64_t seed, int resamples) {
    SobolOptions opt;
    opt.nBase = n;
    opt.base = base;
    opt.seed = seed;
    opt.resamples = resamples;
    return trbc::sobolAnalysis(ishigami, kIshigamiLo, kIshigamiHi, opt);
}

TEST(SobolIndices, IshigamiPseudoRandomTwoToTheSixteen) {
    const SobolResult r = ishigamiAnalysis(Index{1} << 16, SobolBase::PseudoRandom, 2024, 0);
    EXPECT_EQ(r.evaluations, (Index{1} << 16) * 8);
    const IshigamiErrors e = ishigamiErrors(r);
    std::cout << "[ sobol ] Ishigami, pseudo-random N = 2^16:" << e.report << " max error " << e.maxError << "\n";
    EXPECT_LT(e.maxError, 0.02) << e.report;
}

TEST(SobolIndices, IshigamiSobolDesignIsMoreAccurateAtEqualN) {
    const Index n = Index{1} << 14;
    const IshigamiErrors qmc = ishigamiErrors(ishigamiAnalysis(n, SobolBase::Sobol, 1, 0));
    const IshigamiErrors mc = ishigamiErrors(ishigamiAnalysis(n, SobolBase::PseudoRandom, 7, 0));
    std::cout << "[ sobol ] Ishigami N = 2^14, Sobol' base:" << qmc.report << " max error " << qmc.maxError << "\n";
    std::cout << "[ sobol ] Ishigami N = 2^14, pseudo-random base: max error " << mc.maxError << "\n";
    EXPECT_LT(qmc.maxError, 0.01) << qmc.report;
    EXPECT_LT(qmc.maxError, 0.25 * mc.maxError);
}

// 5.3.1: 100 independent analyses at N = 1024 (pseudo-random base, R = 100); count how often
// the bootstrap 95 % intervals cover the analytic S1, ST and S_ij (9 indices).
TEST(SobolIndices, IshigamiBootstrapCoverage) {
    const int reps = 100;
    std::array<int, 9> covered{};
    for (int rep = 0; rep < reps; ++rep) {
        const SobolResult r = ishigamiAnalysis(1024, SobolBase::PseudoRandom, 5000 + static_cast<std::uint64_t>(rep), 100);
        for (int i = 0; i < 3; ++i) {
            covered[i] += std::abs(r.S1(0, i) - kS1[i]) <= r.S1_ci(0, i);
            covered[3 + i] += std::abs(r.ST(0, i) - kST[i]) <= r.ST_ci(0, i);
            const auto [a, b] = kPairs[i];
            covered[6 + i] += std::abs(r.S2[0](a, b) - kS2[i]) <= r.S2_ci[0](a, b);
        }
    }
    const char* names[9] = {"S1", "S2", "S3", "ST1", "ST2", "ST3", "S12", "S13", "S23"};
    int total = 0;
    std::cout << "[ sobol ] bootstrap coverage (of " << reps << "):";
    for (int k = 0; k < 9; ++k) {
        std::cout << " " << names[k] << " " << covered[k];
        total += covered[k];
        EXPECT_GE(covered[k], 75) << names[k];
    }
    const double aggregate = total / (9.0 * reps);
    std::cout << "; aggregate " << aggregate << "\n";
    EXPECT_GE(aggregate, 0.85);
    EXPECT_LE(aggregate, 0.995);  // intervals not absurdly wide
}

// 5.3.2: Y = sum c_i X_i, X_i ~ U[0,1], c = (1,2,3,0): S = ST = (1,4,9,0)/14, S_ij = 0.
MatrixXd linearModel(const MatrixXd& X) { return X * Eigen::Vector4d(1, 2, 3, 0); }

TEST(SobolIndices, LinearModel) {
    const VectorXd lo = VectorXd::Zero(4), hi = VectorXd::Ones(4);
    const std::array<double, 4> exact = {1 / 14.0, 4 / 14.0, 9 / 14.0, 0.0};
    for (SobolBase base : {SobolBase::PseudoRandom, SobolBase::Sobol}) {
        SobolOptions opt;
        opt.nBase = 1 << 14;
        opt.base = base;
        opt.resamples = 0;
        const SobolResult r = trbc::sobolAnalysis(linearModel, lo, hi, opt);
        const double tol = base == SobolBase::Sobol ? 2e-3 : 0.02;
        double maxErr = 0;
        for (int i = 0; i < 4; ++i) {
            EXPECT_NEAR(r.S1(0, i), exact[i], tol) << "S" << i + 1;
            EXPECT_NEAR(r.ST(0, i), exact[i], tol) << "ST" << i + 1;
            maxErr = std::max({maxErr, std::abs(r.S1(0, i) - exact[i]), std::abs(r.ST(0, i) - exact[i])});
            for (int j = i + 1; j < 4; ++j) EXPECT_NEAR(r.S2[0](i, j), 0.0, tol) << "S" << i + 1 << j + 1;
        }
        std::cout << "[ sobol ] linear model, " << (base == SobolBase::Sobol ? "Sobol'" : "pseudo-random")
                  << " N = 2^14: max error of S1, ST " << maxErr << "\n";
        // X4 is ignored by the model: f_AB^(4) = f_A exactly, so both estimators are exactly 0.
        EXPECT_EQ(r.S1(0, 3), 0.0);
        EXPECT_EQ(r.ST(0, 3), 0.0);
    }
}

// Standardisation: indices of a + b Y (b < 0 too) equal those of Y; all outputs at once.
TEST(SobolIndices, InvariantUnderAffineChangeOfOutput) {
    auto model = [](const MatrixXd& X) {
        MatrixXd Y(X.rows(), 3);
        Y.col(0) = ishigami(X).col(0);
        Y.col(1) = (12.5 - 3.7 * Y.col(0).array()).matrix();
        Y.col(2) = (1e3 * Y.col(0).array() + 4e3).matrix();
        return Y;
    };
    SobolOptions opt;
    opt.nBase = 2048;
    opt.resamples = 20;
    const SobolResult r = trbc::sobolAnalysis(model, kIshigamiLo, kIshigamiHi, opt, {"x1", "x2", "x3"}, {"y", "affine", "scaled"});
    ASSERT_EQ(r.S1.rows(), 3);
    for (Index o = 1; o < 3; ++o) {
        EXPECT_LT((r.S1.row(o) - r.S1.row(0)).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((r.ST.row(o) - r.ST.row(0)).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((r.S1_ci.row(o) - r.S1_ci.row(0)).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((r.ST_ci.row(o) - r.ST_ci.row(0)).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((r.S2[o] - r.S2[0]).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((r.S2_ci[o] - r.S2_ci[0]).cwiseAbs().maxCoeff(), 1e-12);
    }
}

// The same model expressed on a rescaled input box gives the same indices: the design is built
// in [0,1]^D and mapped affinely to each box.
TEST(SobolIndices, InvariantUnderRescalingOfInputBoxes) {
    const VectorXd lo1 = VectorXd::Zero(4), hi1 = VectorXd::Ones(4);
    const VectorXd lo2 = (VectorXd(4) << -2, 10, 0.1, -1e3).finished();
    const VectorXd hi2 = (VectorXd(4) << 5, 1000, 0.2, -1e2).finished();
    auto unitModel = [](const MatrixXd& U) {
        MatrixXd Y(U.rows(), 2);
        for (Index k = 0; k < U.rows(); ++k) {
            Y(k, 0) = std::exp(U(k, 0)) * std::sin(3 * U(k, 1)) + U(k, 2) * U(k, 2);
            Y(k, 1) = U(k, 3) + U(k, 0) * U(k, 3);
        }
        return Y;
    };
    auto boxModel = [&](const MatrixXd& X) {
        const MatrixXd U = ((X.rowwise() - lo2.transpose()).array().rowwise() / (hi2 - lo2).transpose().array()).matrix();
        return unitModel(U);
    };
    for (SobolBase base : {SobolBase::Sobol, SobolBase::PseudoRandom}) {
        SobolOptions opt;
        opt.nBase = 1024;
        opt.base = base;
        opt.resamples = 10;
        const SobolResult a = trbc::sobolAnalysis(unitModel, lo1, hi1, opt);
        const SobolResult b = trbc::sobolAnalysis(boxModel, lo2, hi2, opt);
        EXPECT_LT((a.S1 - b.S1).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((a.ST - b.ST).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((a.S1_ci - b.S1_ci).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LT((a.ST_ci - b.ST_ci).cwiseAbs().maxCoeff(), 1e-12);
        for (std::size_t o = 0; o < 2; ++o) EXPECT_LT((a.S2[o] - b.S2[o]).cwiseAbs().maxCoeff(), 1e-12);
    }
}

// 5.3.3 (structure): an input the model ignores gets S1 = ST = 0 and S_ij = 0 with it; S_i <= ST_i
// up to noise and sum S_i <= 1.
TEST(SobolIndices, IgnoredInputHasZeroIndices) {
    auto model = [](const MatrixXd& X) {  // Ishigami in inputs 1, 2, 4; input 3 is ignored
        MatrixXd Xi(X.rows(), 3);
        Xi << X.col(0), X.col(1), X.col(3);
        return ishigami(Xi);
    };
    SobolOptions opt;
    opt.nBase = 4096;
    const SobolResult r = trbc::sobolAnalysis(model, VectorXd::Constant(4, -kPi), VectorXd::Constant(4, kPi), opt);
    EXPECT_EQ(r.S1(0, 2), 0.0);
    EXPECT_EQ(r.ST(0, 2), 0.0);
    EXPECT_EQ(r.S1_ci(0, 2), 0.0);
    EXPECT_EQ(r.ST_ci(0, 2), 0.0);
    // S_34 (pair i < j = input 4): f_BA^(3) = f_B, so V_34 reproduces the S_4 estimate exactly.
    // S_13, S_23: f_AB^(3) = f_A turns V_i3 into a second (A-based) estimate of S_i, so they are
    // zero only up to estimator noise.
    EXPECT_LT(std::abs(r.S2[0](2, 3)), 1e-12);
    for (int j : {0, 1}) EXPECT_LT(std::abs(r.S2[0](j, 2)), 0.02);
    for (int i = 0; i < 4; ++i) EXPECT_LE(r.S1(0, i), r.ST(0, i) + r.S1_ci(0, i) + r.ST_ci(0, i));
    EXPECT_LE(r.S1.row(0).sum(), 1.0 + 0.02);
}

TEST(SobolIndices, DeterministicWithSeedAndThreadCount) {
    for (SobolBase base : {SobolBase::PseudoRandom, SobolBase::Sobol}) {
        const SobolResult a = ishigamiAnalysis(512, base, 99, 50);
        const SobolResult b = ishigamiAnalysis(512, base, 99, 50);
        EXPECT_EQ(a.S1, b.S1);
        EXPECT_EQ(a.ST, b.ST);
        EXPECT_EQ(a.S1_ci, b.S1_ci);
        EXPECT_EQ(a.ST_ci, b.ST_ci);
        EXPECT_EQ(a.S2[0], b.S2[0]);
        EXPECT_EQ(a.S2_ci[0], b.S2_ci[0]);
        const SobolResult c = ishigamiAnalysis(512, base, 100, 50);
        EXPECT_NE(a.S1_ci, c.S1_ci);  // the bootstrap depends on the seed
        if (base == SobolBase::PseudoRandom) {
            EXPECT_NE(a.S1, c.S1);
        } else {
            EXPECT_EQ(a.S1, c.S1);  // the Sobol' design does not
        }
    }
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const SobolResult one = ishigamiAnalysis(512, SobolBase::PseudoRandom, 3, 40);
    omp_set_num_threads(2);
    const SobolResult two = ishigamiAnalysis(512, SobolBase::PseudoRandom, 3, 40);
    omp_set_num_threads(threads);
    EXPECT_EQ(one.S1_ci, two.S1_ci);
    EXPECT_EQ(one.ST_ci, two.ST_ci);
    EXPECT_EQ(one.S2_ci[0], two.S2_ci[0]);
}

TEST(SobolIndices, DesignLayoutAndBatching) {
    const VectorXd lo = (VectorXd(3) << 0.65, 1, 10).finished(), hi = (VectorXd(3) << 1.0, 10, 1000).finished();
    SobolOptions opt;
    opt.nBase = 256;
    const trbc::SaltelliDesign dsg = trbc::saltelliDesign(lo, hi, opt);
    const MatrixXd X = dsg.points();
    ASSERT_EQ(X.rows(), 256 * 8);
    for (Index i = 0; i < 3; ++i) {
        EXPECT_GE(X.col(i).minCoeff(), lo[i]);
        EXPECT_LT(X.col(i).maxCoeff(), hi[i]);
        for (Index j = 0; j < 3; ++j) {
            const auto AB = X.middleRows(dsg.blockAB(i) * 256, 256).col(j);
            const auto BA = X.middleRows(dsg.blockBA(i) * 256, 256).col(j);
            EXPECT_EQ(AB, (i == j ? dsg.B : dsg.A).col(j));
            EXPECT_EQ(BA, (i == j ? dsg.A : dsg.B).col(j));
        }
        // Default skip (a power of two >= N): every column of A is stratified in N intervals.
        std::vector<int> count(256, 0);
        for (Index k = 0; k < 256; ++k) ++count[static_cast<std::size_t>((dsg.A(k, i) - lo[i]) / (hi[i] - lo[i]) * 256)];
        EXPECT_TRUE(std::all_of(count.begin(), count.end(), [](int c) { return c == 1; }));
    }
    EXPECT_EQ(X.topRows(256), dsg.A);
    EXPECT_EQ(X.bottomRows(256), dsg.B);

    // Without second order: N (D + 2) rows. Batched evaluation gives identical results.
    opt.secondOrder = false;
    opt.resamples = 20;
    Index largest = 0, calls = 0;
    auto model = [&](const MatrixXd& P) {
        largest = std::max(largest, P.rows());
        ++calls;
        return linearModel((MatrixXd(P.rows(), 4) << P, P.col(0)).finished());
    };
    const SobolResult whole = trbc::sobolAnalysis(model, lo, hi, opt);
    EXPECT_EQ(whole.evaluations, 256 * 5);
    EXPECT_TRUE(whole.S2.empty());
    EXPECT_EQ(calls, 1);
    opt.batchSize = 300;
    largest = calls = 0;
    const SobolResult batched = trbc::sobolAnalysis(model, lo, hi, opt);
    EXPECT_EQ(largest, 300);
    EXPECT_EQ(calls, 5);
    EXPECT_EQ(whole.S1, batched.S1);
    EXPECT_EQ(whole.ST_ci, batched.ST_ci);
}

TEST(SobolIndices, ConstantOutputGivesNaN) {
    auto model = [](const MatrixXd& X) {
        MatrixXd Y(X.rows(), 2);
        Y.col(0) = X.col(0);
        Y.col(1).setConstant(3.0);
        return Y;
    };
    SobolOptions opt;
    opt.nBase = 64;
    const SobolResult r = trbc::sobolAnalysis(model, VectorXd::Zero(2), VectorXd::Ones(2), opt);
    EXPECT_NEAR(r.S1(0, 0), 1.0, 0.01);
    EXPECT_TRUE(std::isnan(r.S1(1, 0)));
    EXPECT_TRUE(std::isnan(r.ST(1, 1)));
}

template <class F>
void expectInputError(F&& f, const std::string& phrase) {
    try {
        f();
        ADD_FAILURE() << "no InputError, expected one mentioning '" << phrase << "'";
    } catch (const trbc::InputError& e) {
        EXPECT_NE(std::string(e.what()).find(phrase), std::string::npos) << e.what();
    }
}

TEST(SobolIndices, RejectsBadOptions) {
    const VectorXd lo = VectorXd::Zero(2), hi = VectorXd::Ones(2);
    auto with = [&](auto change) {
        SobolOptions opt;
        opt.nBase = 16;
        change(opt);
        return [=] { trbc::sobolAnalysis(linearModel, VectorXd::Zero(4), VectorXd::Ones(4), opt); };
    };
    expectInputError(with([](SobolOptions& o) { o.nBase = 1; }), "nBase = 1");
    expectInputError(with([](SobolOptions& o) { o.resamples = 1; }), "resamples = 1");
    expectInputError(with([](SobolOptions& o) { o.resamples = -3; }), "resamples");
    expectInputError(with([](SobolOptions& o) { o.z = 0; }), "option z");
    expectInputError(with([](SobolOptions& o) { o.batchSize = -1; }), "batchSize");
    expectInputError(with([](SobolOptions& o) { o.sobolSkip = -2; }), "sobolSkip");
    SobolOptions opt;
    opt.nBase = 16;
    expectInputError([&] { trbc::saltelliDesign((VectorXd(2) << 0, 1).finished(), (VectorXd(2) << 1, 1).finished(), opt); },
                     "input 2 is [1.000000, 1.000000]; valid: finite lo < hi");
    expectInputError([&] { trbc::saltelliDesign(lo, VectorXd::Ones(3), opt); }, "equal length");
    expectInputError([&] { trbc::saltelliDesign(VectorXd::Zero(11), VectorXd::Ones(11), opt); }, "D <= 10");
    opt.base = SobolBase::PseudoRandom;
    EXPECT_NO_THROW(trbc::saltelliDesign(VectorXd::Zero(11), VectorXd::Ones(11), opt));
    expectInputError([&] { trbc::sobolAnalysis(linearModel, VectorXd::Zero(4), VectorXd::Ones(4), opt, {"a", "b"}); },
                     "input names: got 2, expected 4");
    expectInputError([&] { trbc::sobolAnalysis([](const MatrixXd& X) { return MatrixXd(X.rows() - 1, 1); }, lo, hi, opt); },
                     "returned");
    const auto nanModel = [](const MatrixXd& X) {
        MatrixXd Y = X.col(0);
        Y(5, 0) = std::nan("");
        return Y;
    };
    EXPECT_THROW(trbc::sobolAnalysis(nanModel, lo, hi, opt, {}, {"D_um"}), trbc::NumericalError);
}

TEST(SobolIndices, CsvOutput) {
    auto model = [](const MatrixXd& X) {
        MatrixXd Y(X.rows(), 2);
        Y.col(0) = X.col(0) + 2 * X.col(1);
        Y.col(1) = X.col(1).array().square();
        return Y;
    };
    SobolOptions opt;
    opt.nBase = 128;
    const SobolResult r = trbc::sobolAnalysis(model, VectorXd::Zero(2), VectorXd::Ones(2), opt, {"v", "mu"}, {"D_um", "D0_um@100.0"});
    const auto dir = std::filesystem::temp_directory_path() / ("trbc_sobol_csv_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    trbc::writeSobolCsv(dir / "sobol_indices.csv", r);
    trbc::writeSobolSecondOrderCsv(dir / "sobol_second_order.csv", r);

    std::ifstream in(dir / "sobol_indices.csv");
    std::string line;
    std::getline(in, line);
    EXPECT_TRUE(line.starts_with("# trbc ")) << line;  // the provenance line
    std::getline(in, line);
    EXPECT_EQ(line, "output,input,S1,S1_ci,ST,ST_ci");
    std::vector<std::string> rows;
    while (std::getline(in, line)) rows.push_back(line);
    ASSERT_EQ(rows.size(), 4u);
    EXPECT_EQ(rows[2].substr(0, 14), "D0_um@100.0,v,");
    std::istringstream fields(rows[3]);
    std::string out, inp, s1, s1ci, st, stci;
    std::getline(fields, out, ',');
    std::getline(fields, inp, ',');
    std::getline(fields, s1, ',');
    std::getline(fields, s1ci, ',');
    std::getline(fields, st, ',');
    std::getline(fields, stci, ',');
    EXPECT_EQ(inp, "mu");
    EXPECT_EQ(std::stod(s1), r.S1(1, 1));  // 17 significant digits round-trip
    EXPECT_EQ(std::stod(stci), r.ST_ci(1, 1));

    std::ifstream in2(dir / "sobol_second_order.csv");
    std::getline(in2, line);
    EXPECT_TRUE(line.starts_with("# trbc ")) << line;  // the provenance line
    std::getline(in2, line);
    EXPECT_EQ(line, "output,input_i,input_j,S2,S2_ci");
    std::getline(in2, line);
    EXPECT_EQ(line.substr(0, 10), "D_um,v,mu,");

    SobolResult bad = r;
    bad.outputs[0] = "D,um";  // quoted, so that it stays one field
    trbc::writeSobolCsv(dir / "quoted.csv", bad);
    EXPECT_EQ(trbc::readCsvRecords(dir / "quoted.csv").at(1).at(0), "D,um");
    bad.outputs[0] = "";
    EXPECT_THROW(trbc::writeSobolCsv(dir / "bad.csv", bad), trbc::InputError);
    EXPECT_THROW(trbc::writeSobolCsv(dir / "missing_dir" / "x.csv", r), trbc::InputError);
    bad = r;
    bad.S2.clear();
    EXPECT_THROW(trbc::writeSobolSecondOrderCsv(dir / "s2.csv", bad), trbc::InputError);
    std::filesystem::remove_all(dir);
}

TEST(SurrogateSobol, ForcesNamesAndResolution) {
    const std::vector<double> forces = trbc::sobolForces(3);
    EXPECT_EQ(forces, (std::vector<double>{0.0, 100.0, 200.0}));
    const std::vector<std::string> names = trbc::surrogateSobolOutputs(forces);
    ASSERT_EQ(names.size(), 10u);
    EXPECT_EQ(names[3], "tc_s");
    EXPECT_EQ(names[4], "D0_um@0");
    EXPECT_EQ(names[9], "D1_um@200");
    trbc::SobolResult r;
    r.S1 = r.ST = MatrixXd::Constant(10, 5, 0.2);
    r.S1_ci = r.ST_ci = MatrixXd::Constant(10, 5, 0.05);
    EXPECT_TRUE(trbc::sobolResolution(r).resolved);
    r.ST_ci(9, 4) = 0.5;  // a force output: not one of the scalar outputs judged
    EXPECT_TRUE(trbc::sobolResolution(r).resolved);
    r.S1_ci(2, 1) = 0.2;
    trbc::SobolResolution res = trbc::sobolResolution(r);
    EXPECT_FALSE(res.resolved);
    EXPECT_DOUBLE_EQ(res.widestHalfWidth, 0.2);
    r.S1_ci(2, 1) = 0.05;
    r.ST(0, 0) = 1.15;  // an index outside [0, 1] by more than the tolerance
    res = trbc::sobolResolution(r);
    EXPECT_FALSE(res.resolved);
    EXPECT_NEAR(res.outside, 0.15, 1e-12);
}

}  // namespace
