// The red-cell hierarchical inference (docs/BAYESIAN_INFERENCE.md, data): data readers and their errors,
// the seven likelihoods against hand computations on analytic forward models, the ratio-uniform
// priors, the population density q(FvK | psi) against quadrature, phase-2 re-weighting on a toy
// problem with an analytic hyper-posterior, and small end-to-end runs of all phases (outputs,
// thread-count independence, phase-by-phase = all at once).
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <iostream>

#include <fmt/format.h>

#include "core/error.hpp"
#include "inference/hierarchical.hpp"
#include "inference/population.hpp"
#include "inference/rbc_pipeline.hpp"
#include "inference/rbc_problem.hpp"
#include "inference/statistics.hpp"
#include "inference/vector_math.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
constexpr double kInf = std::numeric_limits<double>::infinity();
const double kLog2Pi = std::log(2.0 * std::numbers::pi);

Eigen::VectorXd vec(std::initializer_list<double> v) {
    Eigen::VectorXd x(static_cast<Eigen::Index>(v.size()));
    Eigen::Index i = 0;
    for (double a : v) x[i++] = a;
    return x;
}

/// log N(y; m, s^2) written out independently of the library.
double gauss(double y, double m, double s) { return -0.5 * (y - m) * (y - m) / (s * s) - std::log(s) - 0.5 * kLog2Pi; }

// ------------------------------------------------------------------------------------------------
// Analytic forward models (stand-ins for the surrogate)

double eqD(double v, double fvk) { return 6.0 + 2.0 * v + 0.002 * fvk; }
double eqHmin(double v, double fvk) { return 0.8 + 3.0 * (0.95 - v) + 0.0005 * (fvk - 200.0); }
double eqHmax(double v, double fvk) { return 2.5 + 1.5 * (1.0 - v) + 0.0002 * fvk; }
double stretchShape(double mu, double F) { return 1.0 - std::exp(-F / (20.0 * mu)); }
double stD0(double v, double mu, double fvk, double b2, double F) {
    return 7.7 - 1.5 * stretchShape(mu, F) * (1.0 + 0.05 * b2) + 0.3 * (v - 0.95) + 1e-4 * fvk;
}
double stD1(double v, double mu, double fvk, double b2, double F) {
    return 7.7 + 4.0 * stretchShape(mu, F) * (1.0 - 0.05 * b2) + 2.0 * (v - 0.95) - 1e-4 * fvk;
}
double relaxTc(double v, double mu, double etam) { return etam / mu * (0.4 + 0.2 * v); }

RbcModel analyticModel() {
    RbcModel m;
    m.equilibrium = [](const Eigen::MatrixXd& x) {
        Eigen::MatrixXd y(3, x.cols());
        for (Eigen::Index i = 0; i < x.cols(); ++i) y.col(i) << eqD(x(0, i), x(1, i)), eqHmin(x(0, i), x(1, i)), eqHmax(x(0, i), x(1, i));
        return y;
    };
    m.stretching = [](const Eigen::MatrixXd& x) {
        Eigen::MatrixXd y(2, x.cols());
        for (Eigen::Index i = 0; i < x.cols(); ++i)
            y.col(i) << stD0(x(0, i), x(1, i), x(2, i), x(3, i), x(4, i)), stD1(x(0, i), x(1, i), x(2, i), x(3, i), x(4, i));
        return y;
    };
    m.relaxationTime = [](const Eigen::MatrixXd& x) {
        Eigen::VectorXd y(x.cols());
        for (Eigen::Index i = 0; i < x.cols(); ++i) y[i] = relaxTc(x(0, i), x(1, i), x(4, i));
        return y;
    };
    return m;
}

// ------------------------------------------------------------------------------------------------
// Synthetic data files made with the analytic model (the test does not need the shared data)

void writeFile(const fs::path& p, const std::string& text) {
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
}

/// A complete experiments/ directory: equilibrium at (v, FvK) = (0.95, 250); stretching at
/// (v, mu, kb, b2) = (0.95, 5, 0.3, 1.5) and (0.93, 6, 0.25, 2); relaxation with tc = 0.08..0.14 s.
fs::path writeSyntheticData(const fs::path& dir) {
    writeFile(dir / "equilibrium" / "evans_fung_1972.csv",
              fmt::format("quantity,mean_um,sd_um\nD,{:.4f},0.6\nhmin,{:.4f},0.3\nhmax,{:.4f},0.3\n", eqD(0.95, 250) * 1.01,
                          eqHmin(0.95, 250) * 0.98, eqHmax(0.95, 250)));
    const double truth[2][4] = {{0.95, 5.0, 0.3, 1.5}, {0.93, 6.0, 0.25, 2.0}};
    const char* files[2] = {"mills_2004/mills_2004.csv", "suresh_2005/suresh_2005.csv"};
    for (int s = 0; s < 2; ++s) {
        std::string text = "Fext,D0,D1\n";
        const double* t = truth[s];
        const double fvk = fvkFromModuli(t[1], t[2]);
        for (int j = 0; j < 8; ++j) {
            const double F = 25.0 * j, wiggle = 0.05 * std::sin(1.7 * j + s);
            text += fmt::format("{:.2f},{:.4f},{:.4f}\n", F, stD0(t[0], t[1], fvk, t[3], F) + wiggle, stD1(t[0], t[1], fvk, t[3], F) - wiggle);
        }
        writeFile(dir / "stretching" / files[s], text);
    }
    for (int c = 1; c <= 4; ++c) {
        const double tc = 0.06 + 0.02 * c, z0 = 2.0 + 0.05 * c, zinf = 1.15;
        std::string text = "t,L_W\n";
        for (int k = 0; k < 12; ++k) {
            const double t = 0.03 * k;
            text += fmt::format("{:.4f},{:.5f}\n", t, hochmuthAspect(t, tc, z0, zinf) + 0.01 * std::cos(2.3 * k + c));
        }
        writeFile(dir / "relaxation" / "hochmuth_1979" / fmt::format("{}.csv", c), text);
    }
    return dir;
}

// ------------------------------------------------------------------------------------------------
// Data readers

TEST(RbcInference, ReadsTheSevenDataSets) {
    test::TempDir tmp;
    const auto data = loadRbcDataSets(writeSyntheticData(tmp.path() / "experiments"));
    ASSERT_EQ(data.size(), 7u);
    EXPECT_EQ(data[0].name, "evans_fung_1972");
    EXPECT_EQ(data[1].name, "mills_2004");
    EXPECT_EQ(data[2].name, "suresh_2005");
    EXPECT_EQ(data[6].name, "hochmuth_1979_cell4");
    EXPECT_NEAR(data[0].shape[1], eqHmin(0.95, 250) * 0.98, 1e-4);
    EXPECT_EQ(data[1].force.size(), 8);
    EXPECT_EQ(data[3].time.size(), 12);
    EXPECT_EQ(data[3].experiment, RbcExperiment::Relaxation);
}

TEST(RbcInference, ReadsTheShippedExperimentalData) {
    const fs::path shipped = fs::path(TRBC_TEST_DATA) / ".." / ".." / "data" / "experiments";
    const auto data = loadRbcDataSets(shipped);
    ASSERT_EQ(data.size(), 7u);
    EXPECT_DOUBLE_EQ(data[0].shape[0], 7.82);  // docs/BAYESIAN_INFERENCE.md, data
    EXPECT_DOUBLE_EQ(data[0].shape[1], 0.81);
    EXPECT_DOUBLE_EQ(data[0].shape[2], 2.58);
    EXPECT_EQ(data[1].force.size(), 13);
    EXPECT_NEAR(data[1].force.maxCoeff(), 193.1, 1e-9);
    for (int c = 3; c < 7; ++c) EXPECT_EQ(data[static_cast<std::size_t>(c)].time.size(), 25);
}

void expectInputError(const std::function<void()>& f, const std::vector<std::string>& fragments) {
    try {
        f();
        ADD_FAILURE() << "no InputError";
    } catch (const InputError& e) {
        for (const std::string& s : fragments) EXPECT_NE(std::string(e.what()).find(s), std::string::npos) << e.what() << " lacks " << s;
    }
}

TEST(RbcInference, BadDataFilesNameFileLineAndColumn) {
    test::TempDir tmp;
    const fs::path f = tmp.path() / "bad.csv";
    writeFile(f, "Fext,D0\n0,7.7\n10,7.1\n");
    expectInputError([&] { readStretchingData(f, "x"); }, {f.string(), "D1"});
    writeFile(f, "Fext,D0,D1\n0,7.7,7.7\n10,abc,8.0\n");
    expectInputError([&] { readStretchingData(f, "x"); }, {f.string() + ":3", "D0", "abc"});
    writeFile(f, "Fext,D0,D1\n0,7.7,7.7\n10,-1,8.0\n");
    expectInputError([&] { readStretchingData(f, "x"); }, {f.string() + ":3", "D0", "> 0"});
    writeFile(f, "t,L_W\n0,2.0\n0.1,x1.5\n");
    expectInputError([&] { readRelaxationData(f, "x"); }, {f.string() + ":3", "L_W"});
    writeFile(f, "t,LW\n0,2.0\n0.1,1.5\n");
    expectInputError([&] { readRelaxationData(f, "x"); }, {f.string(), "L_W"});
    writeFile(f, "quantity,mean_um\nD,7.8\nhmin,0.8\n");
    expectInputError([&] { readEquilibriumData(f); }, {f.string(), "hmax"});
    writeFile(f, "quantity,mean_um\nD,7.8\nhmin,0.8\nhmax,2..5\n");
    expectInputError([&] { readEquilibriumData(f); }, {f.string() + ":4", "mean_um"});
    writeFile(f, "quantity,mean_um,sd_um\nD,7.8,0.6\nhmin,0.8,-0.1\nhmax,2.5,0.3\n");
    expectInputError([&] { readEquilibriumData(f); }, {f.string() + ":3", "sd_um", ">= 0"});
    expectInputError([&] { loadRbcDataSets(tmp.path() / "nowhere"); }, {"nowhere", "does not exist"});
    // A name longer than any filesystem allows (ENAMETOOLONG): bad input, not a filesystem_error.
    expectInputError([&] { loadRbcDataSets(tmp.path() / std::string(300, 'x')); }, {"xxxx", "cannot be read"});
    // The same for a manifest's file, and a shipped layout that lacks one file names it.
    const fs::path manifestDir = tmp.path() / "manifest";
    fs::create_directories(manifestDir);
    for (const auto& [file, why] : {std::pair<std::string, std::string>{std::string(300, 'y'), "cannot be read"}, {"gone.csv", "does not exist"}}) {
        writeFile(manifestDir / "datasets.json", "[{\"name\": \"m\", \"experiment\": \"stretching\", \"file\": \"" + file + "\"}]");
        expectInputError([&] { loadRbcDataSets(manifestDir); }, {"datasets.json", "data set 'm'", why});
    }
    const fs::path partial = writeSyntheticData(tmp.path() / "partial");
    fs::remove(partial / "stretching" / "mills_2004" / "mills_2004.csv");
    expectInputError([&] { loadRbcDataSets(partial); }, {"mills_2004.csv does not exist"});
}

// The population SDs of the shape are read where the file gives them (a blank one is NaN), and the
// likelihood ignores them.
TEST(RbcInference, EquilibriumDataKeepTheirStandardDeviationsApartFromTheLikelihood) {
    test::TempDir tmp;
    const fs::path f = tmp.path() / "eq.csv";
    writeFile(f, "quantity,mean_um,sd_um\nhmax,2.58,0.27\nD,7.82,0.62\nhmin,0.81,\n");
    const RbcDataSet d = readEquilibriumData(f);
    EXPECT_EQ(d.shape, Eigen::Vector3d(7.82, 0.81, 2.58));
    EXPECT_EQ(d.shapeSd[0], 0.62);
    EXPECT_TRUE(std::isnan(d.shapeSd[1]));
    EXPECT_EQ(d.shapeSd[2], 0.27);
    writeFile(f, "quantity,mean_um\nD,7.82\nhmin,0.81\nhmax,2.58\n");
    const RbcDataSet without = readEquilibriumData(f);
    EXPECT_TRUE(without.shapeSd.array().isNaN().all());
    Eigen::MatrixXd theta(3, 1);
    theta << 0.9, 300.0, 0.05;
    EXPECT_EQ(equilibriumLogLikelihood(analyticModel(), d, theta)[0], equilibriumLogLikelihood(analyticModel(), without, theta)[0]);
}

// ------------------------------------------------------------------------------------------------
// Likelihoods against hand computations

TEST(RbcInference, EquilibriumLikelihoodIsRelativeError) {
    RbcDataSet d;
    d.name = "eq";
    d.experiment = RbcExperiment::Equilibrium;
    d.shape << 7.82, 0.81, 2.58;
    Eigen::MatrixXd theta(3, 2);
    theta.col(0) << 0.9, 300.0, 0.05;
    theta.col(1) << 0.97, 120.0, 0.2;
    const Eigen::VectorXd ll = equilibriumLogLikelihood(analyticModel(), d, theta);
    for (int i = 0; i < 2; ++i) {
        const double v = theta(0, i), fvk = theta(1, i), s = theta(2, i);
        const double f[3] = {eqD(v, fvk), eqHmin(v, fvk), eqHmax(v, fvk)};
        double expected = 0.0;  // sum_k log N(y_k; f_k, (sigma f_k)^2)  
        for (int k = 0; k < 3; ++k) expected += gauss(d.shape[k], f[k], s * f[k]);
        EXPECT_NEAR(ll[i], expected, 1e-12 * std::abs(expected));
    }
    // Hand numbers for the first candidate: f = (8.4, 1.0, 2.71).
    const double hand = gauss(7.82, 8.4, 0.42) + gauss(0.81, 1.0, 0.05) + gauss(2.58, 2.71, 0.1355);
    EXPECT_NEAR(ll[0], hand, 1e-10);
    theta(2, 0) = 0.0;  // sigma = 0: zero likelihood, not NaN
    EXPECT_EQ(equilibriumLogLikelihood(analyticModel(), d, theta)[0], -kInf);
}

TEST(RbcInference, StretchingLikelihoodIsAbsoluteErrorWithFvKFromModuli) {
    RbcDataSet d;
    d.name = "st";
    d.experiment = RbcExperiment::Stretching;
    d.force = vec({0.0, 50.0, 150.0});
    d.d0 = vec({7.6, 6.9, 6.4});
    d.d1 = vec({7.7, 9.5, 11.0});
    RbcModel model = analyticModel();
    Eigen::MatrixXd seen;
    model.stretching = [inner = model.stretching, &seen](const Eigen::MatrixXd& x) {
        seen = x;
        return inner(x);
    };
    Eigen::MatrixXd theta(6, 1);
    theta << 0.95, 5.0, 0.4, 1.2, 0.1, 0.3;  // v, mu, kb (1e-18 J), b2, sigma0, sigma1
    const double ll = stretchingLogLikelihood(model, d, theta)[0];
    const double fvk = 5.0 * 10.742958658 / 0.4;  // FvK = mu R_A^2 / kb  
    ASSERT_EQ(seen.cols(), 3);
    for (int j = 0; j < 3; ++j) {
        EXPECT_NEAR(seen(2, j), fvk, 1e-9);
        EXPECT_EQ(seen(4, j), d.force[j]);  // the force enters only as a network input
    }
    double expected = 0.0;
    for (int j = 0; j < 3; ++j)
        expected += gauss(d.d0[j], stD0(0.95, 5.0, fvk, 1.2, d.force[j]), 0.1) + gauss(d.d1[j], stD1(0.95, 5.0, fvk, 1.2, d.force[j]), 0.3);
    EXPECT_NEAR(ll, expected, 1e-10 * std::abs(expected));
}

TEST(RbcInference, RelaxationLikelihoodUsesLatentTcAndInertParameters) {
    RbcDataSet d;
    d.name = "re";
    d.experiment = RbcExperiment::Relaxation;
    d.time = vec({0.0, 0.1, 0.3});
    d.aspect = vec({2.0, 1.5, 1.2});
    RbcModel model = analyticModel();
    Eigen::MatrixXd seen;
    model.relaxationTime = [inner = model.relaxationTime, &seen](const Eigen::MatrixXd& x) {
        seen = x;
        return inner(x);
    };
    Eigen::MatrixXd theta(6, 1);
    const double r = 0.2, sTc = 0.03, tc = 0.11, z0 = 2.05, zinf = 1.15, sZ = 0.04;
    theta << r, sTc, tc, z0, zinf, sZ;
    const double ll = relaxationLogLikelihood(model, d, theta)[0];
    ASSERT_EQ(seen.cols(), 1);
    EXPECT_EQ(seen(0, 0), 0.95);
    EXPECT_EQ(seen(1, 0), 4.0);
    EXPECT_EQ(seen(2, 0), 250.0);
    EXPECT_EQ(seen(3, 0), 1.6);
    EXPECT_DOUBLE_EQ(seen(4, 0), 4.0 * r);  // etam = 4 r  
    const double tcSim = relaxTc(0.95, 4.0, 4.0 * r);  // = r g
    const double lambda = (z0 + zinf) / (z0 - zinf);
    double expected = gauss(tc, tcSim, sTc * tc);  // relative error with the latent tc
    for (int k = 0; k < 3; ++k) {
        const double e = std::exp(-d.time[k] / tc);
        expected += gauss(d.aspect[k], zinf * (lambda + e) / (lambda - e), sZ);
    }
    EXPECT_NEAR(ll, expected, 1e-10 * std::abs(expected));
    EXPECT_NEAR(hochmuthAspect(0.0, tc, z0, zinf), z0, 1e-14);  // z(0) = z0, z(inf) = zinf
    EXPECT_NEAR(hochmuthAspect(100.0, tc, z0, zinf), zinf, 1e-12);
}

// ------------------------------------------------------------------------------------------------
// Priors

TEST(RbcInference, PhaseOnePriorsUseRatioUniformDensities) {
    RbcDataSet eq;
    eq.experiment = RbcExperiment::Equilibrium;
    const auto pe = phase1Prior(eq);
    ASSERT_EQ(pe->dimension(), 3);
    const ScalarPrior& fvk = pe->component(1);
    EXPECT_NEAR(fvk.lower(), 10.0, 1e-12);  // X = mu in [1, 10], Y = kb/R_A^2 in [0.01, 0.1]  
    EXPECT_NEAR(fvk.upper(), 1000.0, 1e-9);
    for (double z : {12.0, 100.0, 250.0, 900.0}) {
        const double hi = std::min(0.1, 10.0 / z), lo = std::max(0.01, 1.0 / z);
        EXPECT_NEAR(fvk.logDensity(z), std::log((hi * hi - lo * lo) / (2.0 * 9.0 * 0.09)), 1e-12);
    }
    RbcDataSet re;
    re.experiment = RbcExperiment::Relaxation;
    re.aspect = vec({2.1, 1.9});
    const auto pr = phase1Prior(re);
    EXPECT_NEAR(pr->component(0).lower(), 0.01, 1e-15);  // r = etam/mu: [0.1, 1] / [1, 10]
    EXPECT_NEAR(pr->component(0).upper(), 1.0, 1e-15);
    EXPECT_NEAR(pr->component(3).lower(), 1.9, 1e-12);  // z0 ~ U[y1 - 0.2, y1 + 0.2]
    EXPECT_NEAR(pr->component(3).upper(), 2.3, 1e-12);
    // Draws of r match the ratio-uniform mean (a+b)/2 log(e/c)/(e-c).
    Rng rng(7);
    double s = 0.0;
    const int n = 200000;
    for (int k = 0; k < n; ++k) s += pr->component(0).sample(rng);
    EXPECT_NEAR(s / n, ratioUniformMean(0.1, 1.0, 1.0, 10.0), 0.003);
    // Phase 3b: the derivation's prior is the indicator of the same support.
    const auto p3 = phase3bPrior(re, Phase3bOptions{});
    EXPECT_NEAR(p3->component(0).logDensity(0.02) - p3->component(0).logDensity(0.5), 0.0, 1e-15);
    Phase3bOptions ref;
    ref.referencePrior = true;
    EXPECT_NEAR(phase3bPrior(re, ref)->component(0).logDensity(0.3), pr->component(0).logDensity(0.3), 1e-15);
    EXPECT_EQ(phase3bPrior(eq, ref)->component(2).lower(), 1e-4);  // reference: sigma ~ U[1e-4, 0.5]
}

TEST(RbcInference, NarrowedPriorBoxReachesEveryPhaseOnePrior) {
    RbcPriorBox box;
    box.set("v", 0.8, 0.95);
    box.set("mu_uN_per_m", 2.0, 8.0);
    box.set("kb_J", 2e-19, 5e-19);
    box.set("b2", 1.0, 3.0);
    box.set("etam_Pa_s_um", 0.2, 0.9);
    EXPECT_NEAR(box.bounds("kb_J").first, 2e-19, 1e-33);
    RbcDataSet st;
    st.experiment = RbcExperiment::Stretching;
    st.prior = box;
    const auto ps = phase1Prior(st);
    EXPECT_DOUBLE_EQ(ps->component(0).lower(), 0.8);
    EXPECT_DOUBLE_EQ(ps->component(1).upper(), 8.0);
    EXPECT_NEAR(ps->component(2).lower(), 0.2, 1e-14);  // kb in 1e-18 J
    EXPECT_DOUBLE_EQ(ps->component(3).upper(), 3.0);
    RbcDataSet eq;
    eq.experiment = RbcExperiment::Equilibrium;
    eq.prior = box;
    // FvK = mu R_A^2 / kb over [2, 8] x [0.2, 0.5] 1e-18 J.
    EXPECT_NEAR(phase1Prior(eq)->component(1).lower(), 2.0 * kRbcAreaRadius2 / 0.5, 1e-6);  // constants agree to 2e-10
    EXPECT_NEAR(phase1Prior(eq)->component(1).upper(), 8.0 * kRbcAreaRadius2 / 0.2, 1e-5);
    RbcDataSet re;
    re.experiment = RbcExperiment::Relaxation;
    re.aspect = vec({2.1, 1.9});
    re.prior = box;
    EXPECT_NEAR(phase1Prior(re)->component(0).lower(), 0.2 / 8.0, 1e-15);  // r = etam / mu
    EXPECT_NEAR(phase1Prior(re)->component(0).upper(), 0.9 / 2.0, 1e-15);
}

TEST(RbcInference, PriorOutsideTheTrainingBoxIsRejectedWithTheValidRange) {
    RbcPriorBox box;
    auto message = [&](const std::string& name, double lo, double hi) { return test::inputError([&] { box.set(name, lo, hi); }); };
    std::string e = message("v", 0.5, 1.0);
    EXPECT_NE(e.find("prior of v: [0.5, 1] is out of range"), std::string::npos) << e;
    EXPECT_NE(e.find("[0.65, 1]"), std::string::npos) << e;
    e = message("mu_uN_per_m", 5.0, 12.0);
    EXPECT_NE(e.find("[1, 10]"), std::string::npos) << e;
    EXPECT_NE(message("b2", 3.0, 2.0), "");  // lo >= hi
    EXPECT_NE(message("etam_Pa_s_um", 0.1, std::nan("")), "");
    e = message("kappa", 0.0, 1.0);
    EXPECT_NE(e.find("unknown prior parameter 'kappa'"), std::string::npos) << e;
    EXPECT_EQ(message("kb_J", 1.074295866e-19, 1.074295866e-18), "");  // the full box itself is fine
}

// ------------------------------------------------------------------------------------------------
// Population densities

TEST(RbcInference, ScaledNormalTailMatchesErfc) {
    // Q(x) = erfc(x / sqrt 2) / 2 = scaledNormalTail(x) e^{-x^2/2}. Beyond x = 8 the comparison is
    // limited by the rounding of x^2/2 inside exp (relative x^2 eps).
    double worst = 0.0, worstFar = 0.0;
    for (double x = 0.0; x < 37.0; x += 0.0137) {
        const double exact = 0.5 * std::erfc(x / std::numbers::sqrt2);
        const double e = std::abs(scaledNormalTail(x) * std::exp(-0.5 * x * x) / exact - 1.0);
        (x < 8.0 ? worst : worstFar) = std::max(x < 8.0 ? worst : worstFar, e);
    }
    EXPECT_LT(worst, 2e-14);
    EXPECT_LT(worstFar, 1e-12);
}

TEST(RbcInference, VectorisableExpLogRsqrtMatchTheLibrary) {
    double worstExp = 0.0, worstLog = 0.0, worstRsqrt = 0.0, worstExpF = 0.0, worstLogF = 0.0;
    for (double x = -700.0; x <= 0.0; x += 0.0731) worstExp = std::max(worstExp, std::abs(detail::fastExp(x) / std::exp(x) - 1.0));
    for (double x = 1e-300; x < 1e300; x *= 1.37) {
        worstLog = std::max(worstLog, std::abs(detail::fastLog(x) - std::log(x)) / std::max(1.0, std::abs(std::log(x))));
        worstRsqrt = std::max(worstRsqrt, std::abs(detail::fastRsqrt(x) * std::sqrt(x) - 1.0));
    }
    for (float x = -80.0f; x <= 0.0f; x += 0.0173f)
        worstExpF = std::max(worstExpF, std::abs(static_cast<double>(detail::fastExpF(x)) / std::exp(static_cast<double>(x)) - 1.0));
    for (float x = 1e-30f; x < 1e30f; x *= 1.37f)
        worstLogF = std::max(worstLogF, std::abs(static_cast<double>(detail::fastLogF(x)) - std::log(static_cast<double>(x))) /
                                            std::max(1.0, std::abs(std::log(static_cast<double>(x)))));
    EXPECT_LT(worstExp, 1e-15);
    EXPECT_LT(worstLog, 1e-15);
    EXPECT_LT(worstRsqrt, 1e-15);
    EXPECT_LT(worstExpF, 5e-7);
    EXPECT_LT(worstLogF, 5e-7);
    EXPECT_EQ(detail::fastExp(-1e6), detail::fastExp(-708.0));  // clamped: no subnormal results
}

/// q(z) = int_a^b y phi((z y - muX)/sdX)/sdX TN(y) dy by composite Simpson on 20001 nodes.
double fvkDensityQuadrature(double z, const RatioDensityParameters& p) {
    const int n = 20000;
    const double h = (p.b - p.a) / n;
    double s = 0.0;
    for (int i = 0; i <= n; ++i) {
        const double y = p.a + i * h, w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
        const double ux = (z * y - p.muX) / p.sdX, uy = (y - p.muY) / p.sdY;
        s += w * y * std::exp(-0.5 * ux * ux - 0.5 * uy * uy) / (2.0 * std::numbers::pi * p.sdX * p.sdY);
    }
    return s * h / 3.0 / std::exp(p.logZy);
}

TEST(RbcInference, FvkDensityClosedFormMatchesQuadrature) {
    Eigen::VectorXd psi(10);
    double worstQuad = 0.0, worstArray = 0.0, worst50 = 0.0;
    const double cases[][4] = {{4.0, 2.0, 0.3, 0.1}, {8.0, 0.5, 0.9, 0.05}, {2.0, 5.0, 0.15, 0.3}, {5.0, 0.05, 0.5, 0.02}};
    for (const auto& c : cases) {
        psi << 0.9, 0.1, c[0], c[1], c[2], c[3], 2.0, 1.0, 0.1, 0.1;
        const RatioDensityParameters p = fvkDensityParameters(psi);
        Eigen::ArrayXd z = Eigen::ArrayXd::LinSpaced(41, 15.0, 900.0), out(41);
        logFvkDensityArray(z, Eigen::ArrayXd::Constant(41, p.muX), Eigen::ArrayXd::Constant(41, p.sdX), Eigen::ArrayXd::Constant(41, p.muY),
                           Eigen::ArrayXd::Constant(41, p.sdY), Eigen::ArrayXd::Constant(41, p.logZy), out);
        for (Eigen::Index i = 0; i < z.size(); ++i) {
            const double lq = logFvkDensity(z[i], p), quad = fvkDensityQuadrature(z[i], p);
            // (far in the tails the integrand is a boundary layer narrower than the Simpson step)
            if (quad > 1e-80) worstQuad = std::max(worstQuad, std::abs(std::exp(lq) / quad - 1.0));
            worstArray = std::max(worstArray, std::abs(out[i] - lq));
            if (quad > 1e-2 * std::exp(logFvkDensity(p.muX / p.muY, p)))
                worst50 = std::max(worst50, std::abs(std::exp(logFvkDensityNodes50(z[i], p)) / quad - 1.0));
        }
    }
    EXPECT_LT(worstQuad, 1e-8);    // docs/BAYESIAN_INFERENCE.md: closed form = quadrature
    EXPECT_LT(worstArray, 1e-11);  // vectorised = scalar
    EXPECT_GT(worst50, 1e-4);      // the 50-node rule is only approximate ...
    EXPECT_LT(worst50, 1.0);       // ... (per cents, more for narrow populations: the nodes are 0.0018 apart)
    // q integrates to one over FvK (mass outside [0.5, 5000] is negligible here).
    psi << 0.9, 0.1, 5.0, 1.0, 0.4, 0.1, 2.0, 1.0, 0.1, 0.1;
    const RatioDensityParameters p = fvkDensityParameters(psi);
    double mass = 0.0;
    for (double z = 0.5; z < 5000.0; z += 0.05) mass += std::exp(logFvkDensity(z + 0.025, p)) * 0.05;
    EXPECT_NEAR(mass, 1.0, 1e-4);
}

TEST(RbcInference, FvkDensityMixedPrecisionAgreesWithDouble) {
    // The population sums use the closed form in mixed precision (FvkDensityRule::ClosedForm):
    // within 1e-5 of the double-precision closed form wherever log q is within 40 of its maximum,
    // over hyper-parameters drawn from the hyper-prior and FvK over the ratio-uniform support.
    Rng rng(17);
    const auto prior = hyperPrior();
    double worst = 0.0;
    for (int t = 0; t < 300; ++t) {
        const RatioDensityParameters p = fvkDensityParameters(prior->sample(rng));
        std::vector<double> z(400), exact(400);
        double top = -kInf;
        for (int i = 0; i < 400; ++i) {
            z[static_cast<std::size_t>(i)] = 10.0 * std::pow(100.0, rng.uniform());
            top = std::max(top, exact[static_cast<std::size_t>(i)] = logFvkDensity(z[static_cast<std::size_t>(i)], p));
        }
        for (int i = 0; i < 400; ++i)
            if (exact[static_cast<std::size_t>(i)] > top - 40.0)
                worst = std::max(worst, std::abs(logFvkDensityMixed(z[static_cast<std::size_t>(i)], p) - exact[static_cast<std::size_t>(i)]));
    }
    EXPECT_LT(worst, 1e-5);
    EXPECT_GT(worst, 0.0);  // it is a different evaluation
}

TEST(RbcInference, PopulationDensityTruncatesVAndKbOnly) {
    Eigen::VectorXd psi(10), theta(5);
    psi << 0.95, 0.1, 5.0, 2.0, 0.5, 0.2, 1.5, 1.0, 0.2, 0.05;
    theta << 0.9, 4.0, 0.3, 1.0, 0.15;
    const double zv = normalCdf((1.0 - 0.95) / 0.1) - normalCdf((0.0 - 0.95) / 0.1);
    const double zk = normalCdf((kKbHigh - 0.5) / 0.2) - normalCdf((kKbLow - 0.5) / 0.2);
    const double expected = gauss(0.9, 0.95, 0.1) - std::log(zv) + gauss(4.0, 5.0, 2.0) + gauss(0.3, 0.5, 0.2) - std::log(zk) +
                            gauss(1.0, 1.5, 1.0) + gauss(0.15, 0.2, 0.05);
    EXPECT_NEAR(populationLogDensity(theta, psi), expected, 1e-12);
    theta[0] = 1.01;
    EXPECT_EQ(populationLogDensity(theta, psi), -kInf);
}

// ------------------------------------------------------------------------------------------------
// Phase 2 on a toy problem with a known answer

/// Phase-1 "posterior" of r for a relaxation-like data set: p(r) ∝ N(r; rbar, s^2) pi_RU(r), drawn by
/// rejection. Then b(psi) ∝ N(rbar; mu_r, sd_r^2 + s^2) exactly (up to a constant), 4.4.
Eigen::MatrixXd toyPhase1Samples(const RbcDataSet& d, double rbar, double s, int n, std::uint64_t seed) {
    const auto prior = phase1Prior(d);
    const ScalarPrior& ru = prior->component(0);
    Rng rng(seed);
    Eigen::MatrixXd x = Eigen::MatrixXd::Zero(6, n);
    const double maxDensity = std::exp(ru.logDensity(0.1)) * 1.01;  // p_RU peaks at r = 0.1
    for (int k = 0; k < n;) {
        const double r = rbar + s * rng.normal();
        if (rng.uniform() * maxDensity < std::exp(ru.logDensity(r))) {
            x.col(k++) << r, 0.02, 0.1, d.aspect[0], 1.1, 0.1;
            if (k < n && rng.uniform() < 0.3) x.col(k) = x.col(k - 1), ++k;  // BASIS-like repeats
        }
    }
    return x;
}

TEST(RbcInference, PhaseTwoReweightingMatchesTheAnalyticHyperPosterior) {
    const double rbar[4] = {0.18, 0.24, 0.21, 0.30}, s = 0.02;
    std::vector<ReweightingSamples> sets;
    RbcDataSet d;
    d.experiment = RbcExperiment::Relaxation;
    d.aspect = vec({2.0, 1.5});
    for (int i = 0; i < 4; ++i) sets.push_back(reweightingSamples(d, toyPhase1Samples(d, rbar[i], s, 4000, 11 + i)));
    EXPECT_LT(sets[0].x.cols(), 4000);  // repeats merged

    // b_i(psi) / b_i(psi_ref) against N(rbar; mu, sd^2 + s^2) ratios, within 4 Monte-Carlo standard
    // errors of the estimator (relative SE of a mean of t_k = N(r_k; mu, sd) / pi(r_k), from the draws).
    Eigen::MatrixXd psi(10, 3);
    const Eigen::VectorXd base = (Eigen::VectorXd(10) << 0.9, 0.1, 5, 2, 0.5, 0.2, 2, 1, 0.2, 0.05).finished();
    for (int c = 0; c < 3; ++c) psi.col(c) = base;
    psi(8, 1) = 0.25, psi(9, 1) = 0.03;
    psi(8, 2) = 0.15, psi(9, 2) = 0.1;
    const ScalarPrior& ru = phase1Prior(d)->component(0);
    for (int i = 0; i < 4; ++i) {
        const Eigen::MatrixXd draws = toyPhase1Samples(d, rbar[i], s, 4000, 11 + i);
        auto relativeSe = [&](int col) {
            double m1 = 0, m2 = 0;
            for (Eigen::Index k = 0; k < draws.cols(); ++k) {
                const double t = std::exp(gauss(draws(0, k), psi(8, col), psi(9, col)) - ru.logDensity(draws(0, k)));
                m1 += t, m2 += t * t;
            }
            m1 /= draws.cols(), m2 /= draws.cols();
            return std::sqrt((m2 - m1 * m1) / draws.cols()) / m1;
        };
        const Eigen::VectorXd lb = logReweightingFactors(sets[static_cast<std::size_t>(i)], psi);
        for (int c = 1; c < 3; ++c) {
            auto exact = [&](int col) { return gauss(rbar[i], psi(8, col), std::sqrt(psi(9, col) * psi(9, col) + s * s)); };
            EXPECT_NEAR(lb[c] - lb[0], exact(c) - exact(0), 4.0 * (relativeSe(c) + relativeSe(0))) << "set " << i << " psi " << c;
        }
    }

    // Phase 2 with TMCMC against the (mu_r, sd_r) posterior on a grid; the other hyper-parameters
    // are not informed by these data sets.
    TmcmcOptions opt;
    opt.populationSize = 2000;
    opt.targetCoV = 0.4;
    opt.covarianceScaling = 0.06;
    opt.seed = 5;
    const TmcmcResult r = runTmcmc(phase2Problem(sets), opt);
    double w = 0, mMu = 0, mSd = 0;
    for (double mu = 0.01 + 0.0005; mu < 0.4; mu += 0.001)
        for (double sd = 0.01 + 0.0005; sd < 0.5; sd += 0.001) {
            double l = 0.0;
            for (double rb : rbar) l += gauss(rb, mu, std::sqrt(sd * sd + s * s));
            const double p = std::exp(l);
            w += p, mMu += p * mu, mSd += p * sd;
        }
    mMu /= w, mSd /= w;
    const Eigen::VectorXd mean = r.samples.rowwise().mean();
    EXPECT_NEAR(mean[8], mMu, 0.01);
    EXPECT_NEAR(mean[9], mSd, 0.015);
    EXPECT_NEAR(mean[0], 0.825, 0.03);  // mu_v: prior U[0.65, 1]
}

TEST(RbcInference, HermiteSumsAndTabulatedMixturesMatchDirectSums) {
    // Phase 2, relaxation: the binned Hermite expansion against the direct sum.
    RbcDataSet d;
    d.experiment = RbcExperiment::Relaxation;
    d.aspect = vec({2.0, 1.5});
    const ReweightingSamples s = reweightingSamples(d, toyPhase1Samples(d, 0.2, 0.03, 3000, 21));
    ASSERT_GT(s.bins.size(), 10u);
    Eigen::MatrixXd psi(10, 5);
    const double mr[5] = {0.2, 0.05, 0.39, 0.21, 0.15}, sr[5] = {0.01, 0.01, 0.5, 0.2, 0.013};
    for (int c = 0; c < 5; ++c) psi.col(c) << 0.9, 0.1, 5, 2, 0.5, 0.2, 2, 1, mr[c], sr[c];
    const Eigen::VectorXd fast = logReweightingFactors(s, psi);
    for (int c = 0; c < 5; ++c) {
        long double sum = 0.0L;
        for (Eigen::Index k = 0; k < s.x.cols(); ++k)
            sum += std::exp(static_cast<long double>(s.logWeight[k] + gauss(s.x(0, k), mr[c], sr[c])));
        EXPECT_NEAR(fast[c], static_cast<double>(std::log(sum)), 1e-11) << "psi " << c;
    }
    // Phase 3b, relaxation: the tabulated 1-D mixture against the exact sum.
    Rng rng(8);
    const auto prior = hyperPrior();
    Eigen::MatrixXd cloud(10, 400);
    for (int m = 0; m < 400; ++m) cloud.col(m) = prior->sample(rng);
    Eigen::VectorXd offset = Eigen::VectorXd::LinSpaced(400, -1.0, 1.0);
    PopulationMixture exact(PopulationMixture::Layout::Relaxation, cloud, offset), table = exact;
    EXPECT_LT(table.tabulate(0.01, 1.0), 1e-9);
    ASSERT_TRUE(table.tabulated());
    double worst = 0.0;
    for (int k = 0; k < 2000; ++k) {
        Eigen::VectorXd r = Eigen::VectorXd::Constant(1, 0.01 + 0.99 * rng.uniform());
        worst = std::max(worst, std::abs(table.logMeanAt(r) - exact.logMeanAt(r)));
    }
    EXPECT_LT(worst, 1e-8);
}

TEST(RbcInference, NewCellMixtureMatchesAncestralSampling) {
    // Phase-2 samples: a fixed cloud of hyper-parameters.
    Rng rng(3);
    const auto prior = hyperPrior();
    Eigen::MatrixXd psi(10, 300);
    for (int m = 0; m < 300; ++m) {
        psi.col(m) = prior->sample(rng);
        psi(1, m) = 0.03 + 0.02 * rng.uniform();  // keep v inside the box often
    }
    psi.col(299) = psi.col(0);  // a repeat (merged)
    const PopulationMixture mix(PopulationMixture::Layout::NewCell, psi);
    EXPECT_EQ(mix.distinctComponents(), 299);
    Eigen::VectorXd theta(5);
    theta << 0.9, 5.0, 0.5, 2.0, 0.2;
    double direct = 0.0;
    for (int m = 0; m < 300; ++m) direct += std::exp(populationLogDensity(theta, psi.col(m)));
    EXPECT_NEAR(mix.logMeanAt(theta), std::log(direct / 300.0), 1e-10);

    TmcmcOptions opt;
    opt.populationSize = 3000;
    opt.targetCoV = 0.4;
    opt.covarianceScaling = 0.06;
    opt.seed = 9;
    const TmcmcResult r = runTmcmc(phase3aProblem(psi), opt);
    const Eigen::MatrixXd a = sampleNewCellAncestral(psi, 20000, 4);
    for (int j = 0; j < 5; ++j) {
        const Eigen::VectorXd x = r.samples.row(j).transpose(), y = a.row(j).transpose();
        EXPECT_NEAR(mean(x), mean(y), 0.12 * populationSd(y)) << "coordinate " << j;
        EXPECT_NEAR(populationSd(x), populationSd(y), 0.12 * populationSd(y)) << "coordinate " << j;
    }
}

// ------------------------------------------------------------------------------------------------
// End to end

RbcInferenceOptions smallRun(const fs::path& out, int n) {
    RbcInferenceOptions o;
    o.outputDirectory = out;
    o.populationSize = n;
    o.seed = 42;
    o.chains = 4;
    o.warmup = 100;
    o.draws = 100;
    o.thin = 1;
    return o;
}

TEST(RbcInference, AllPhasesEndToEndOnAnalyticModel) {
    test::TempDir tmp;
    const auto data = loadRbcDataSets(writeSyntheticData(tmp.path() / "experiments"));
    const fs::path out = tmp.path() / "out";
    omp_set_num_threads(2);
    RbcInferenceOptions options = smallRun(out, 500);
    options.method = HierarchicalMethod::Reweighting;
    const RbcInferenceResult r = runRbcInference(analyticModel(), data, options);
    omp_set_num_threads(1);
    ASSERT_EQ(r.phase1.size(), 7u);
    ASSERT_EQ(r.phase3b.size(), 7u);
    for (const TmcmcResult& x : r.phase1) EXPECT_TRUE(x.completed);
    EXPECT_TRUE(r.phase2.completed && r.phase3a.completed);
    for (const char* f : {"posterior_stats.csv", "posterior_table.md", "infer.json", "phase1/posterior_stats.csv",
                          "phase2/posterior_stats.csv", "phase1/mills_2004/samples.csv", "phase1/mills_2004/stages.csv",
                          "phase1/mills_2004/run.json", "phase2/hyper/samples.csv", "phase3/theta_new/samples.csv",
                          "phase3/theta_new/ancestral_check.csv", "phase3/hochmuth_1979_cell2/samples.csv"})
        EXPECT_TRUE(fs::exists(out / f)) << f;
    const std::string stats = test::slurp(out / "posterior_stats.csv");
    EXPECT_EQ(stats.rfind("# trbc ", 0), 0u);  // the provenance line, then the header
    EXPECT_EQ(stats.find("\nposterior,parameter,mean,median,ml,map,sd,q05,q95,mcse_mean,mcse_median,mcse_sd,mcse_q05,mcse_q95,rhat,"
                          "ess_bulk,ess_tail\n"), stats.find('\n'));
    for (const char* row : {"theta_new,v,", "theta_new,mu_uN_per_m,", "theta_new,kb_J,", "theta_new,b2,", "theta_new,etam_Pa_s_um,",
                            "evans_fung_1972,FvK,", "mills_2004,kb_J,", "suresh_2005,mu_uN_per_m,", "hochmuth_1979_cell1,etam_over_mu_s,",
                            "hochmuth_1979_cell4,tc_s,"})
        EXPECT_NE(stats.find(row), std::string::npos) << row;
    // kb in joules, theta_new inside the box, the stretching posteriors near the synthetic truth.
    for (const PosteriorStatsRow& s : r.stats) {
        if (s.parameter == "kb_J") {
            EXPECT_GT(s.mean, 0.9 * kKbLow * 1e-18);
            EXPECT_LT(s.mean, 1.1 * kKbHigh * 1e-18);
        }
        if (s.posterior == "mills_2004" && s.parameter == "mu_uN_per_m") {
            EXPECT_NEAR(s.mean, 5.0, 1.5);
        }
        if (s.posterior == "hochmuth_1979_cell1" && s.parameter == "tc_s") {
            EXPECT_NEAR(s.mean, 0.08, 0.04);  // N = 500 is coarse (N = 4000 gives 0.080 +- 0.006)
        }
        if (s.posterior == "theta_new" && s.parameter == "v") {
            EXPECT_GE(s.q05, 0.65);
        }
    }
    {
        const TmcmcResult& c1 = r.phase1[3];  // hochmuth_1979_cell1 alone: tc = 0.08 s in the synthetic data
        EXPECT_NEAR(c1.samples.row(2).mean(), 0.08, 0.015);
    }
    const std::string table = test::slurp(out / "posterior_table.md");
    EXPECT_NE(table.find("| $\\kappa_b$ |"), std::string::npos);
    EXPECT_NE(table.find("| mean | median | ML | MAP | standard deviation |"), std::string::npos);
    const std::string info = test::slurp(out / "infer.json");
    for (const char* key : {"\"phases\"", "\"surrogate_s\"", "\"population_s\"", "\"sampler_s\"", "\"seed\": 42", "\"relaxation_extrapolation\""})
        EXPECT_NE(info.find(key), std::string::npos) << key;
    EXPECT_TRUE(r.timing[0].ran && r.timing[1].ran && r.timing[2].ran);
    EXPECT_GT(r.timing[0].surrogateEvaluations, 0);
    EXPECT_GT(r.timing[1].populationTerms, 0);
}

TEST(RbcInference, JointMethodEndToEndOnAnalyticModelWithDiagnostics) {
    test::TempDir tmp;
    const auto data = loadRbcDataSets(writeSyntheticData(tmp.path() / "experiments"));
    const fs::path out = tmp.path() / "out";
    RbcInferenceOptions o = smallRun(out, 1000);
    o.chains = 4, o.warmup = 400, o.draws = 500, o.thin = 2;
    const RbcInferenceResult r = runRbcInference(analyticModel(), data, o);
    ASSERT_EQ(r.joint.hyper.size(), 4u);
    ASSERT_EQ(r.phase3b.size(), 7u);
    for (const char* f : {"posterior_stats.csv", "posterior_table.md", "phase2/joint/draws.bin", "phase2/hyper/samples.csv",
                          "phase3/theta_new/samples.csv", "phase3/mills_2004/samples.csv", "phase3/evans_fung_1972/run.json"})
        EXPECT_TRUE(fs::exists(out / f)) << f;
    int theta = 0;
    for (const PosteriorStatsRow& s : r.stats) {
        EXPECT_TRUE(std::isfinite(s.mcseMean) && s.mcseMean > 0.0) << s.posterior << " " << s.parameter;
        EXPECT_TRUE(std::isfinite(s.rhat) && s.rhat < 1.2) << s.posterior << " " << s.parameter;
        EXPECT_GT(s.essBulk, 20.0) << s.posterior << " " << s.parameter;
        EXPECT_LE(s.q05, s.median);
        EXPECT_LE(s.median, s.q95);
        if (s.posterior == "theta_new") {
            ++theta;
            EXPECT_LT(s.mcseMean, 0.5 * s.sd) << s.parameter;
        }
        if (s.posterior == "mills_2004" && s.parameter == "mu_uN_per_m") {
            EXPECT_NEAR(s.mean, 5.0, 1.5);
        }
        if (s.posterior == "hochmuth_1979_cell1" && s.parameter == "tc_s") {
            EXPECT_NEAR(s.mean, 0.08, 0.01);
        }
    }
    EXPECT_EQ(theta, 6);  // v, mu, kb, b2, r and eta_m
    // The equilibrium draws are stored as (v, FvK, sigma) with FvK = mu R_A^2 / kb inside the prior support.
    for (Eigen::Index k = 0; k < r.phase3b[0].samples.cols(); ++k) {
        EXPECT_GE(r.phase3b[0].samples(1, k), 10.0);
        EXPECT_LE(r.phase3b[0].samples(1, k), 1000.0);
    }
}

TEST(RbcInference, TheJointMethodTakesAFlowDataSetAndTheReweightingRouteRefusesIt) {
    // A flow set whose inclination is 20 - 8 eta_m deg at every rate, made by a cell with
    // eta_m = 0.5 Pa s um: its block of the joint draws must put mu r near 0.5, with the networks'
    // error of 0.3 deg as a common offset of each of its three curves.
    test::TempDir tmp;
    std::vector<RbcDataSet> data = loadRbcDataSets(writeSyntheticData(tmp.path() / "experiments"));
    FlowDataSet f;
    f.name = "donor";
    f.modelErrorSd = 0.3;
    f.regimeErrorRate = 0.1;
    for (double eta : {23.9, 55.9, 104.0}) {
        FlowCurve c{eta, Eigen::VectorXd(5), Eigen::VectorXd(5)};
        for (int k = 0; k < 5; ++k) c.rate[k] = 10.0 * (k + 1), c.value[k] = 20.0 - 8.0 * 0.5 + 0.1 * std::sin(3.0 * k + eta);
        f.curves.push_back(c);
    }
    data.push_back(flowRbcDataSet(f));
    RbcModel model = analyticModel();
    model.flow.tankTreading = [](const Eigen::MatrixXd& x, const Eigen::VectorXd&) {
        Eigen::MatrixXd y(3, x.cols());
        for (Eigen::Index k = 0; k < x.cols(); ++k) y.col(k) << 0.95, 20.0 - 8.0 * x(4, k), 0.4;
        return y;
    };
    model.flow.criticalStressPa = [](const Eigen::MatrixXd& x, const Eigen::VectorXd&) { return Eigen::VectorXd::Constant(x.cols(), 0.1); };
    const fs::path out = tmp.path() / "out";
    RbcInferenceOptions o = smallRun(out, 1000);
    o.chains = 4, o.warmup = 300, o.draws = 300, o.thin = 2;
    const RbcInferenceResult r = runRbcInference(model, data, o);
    ASSERT_EQ(r.phase3b.size(), 8u);
    const Eigen::MatrixXd& y = r.phase3b[7].samples;  // v, mu, kb, b2, r, sigma
    ASSERT_EQ(y.rows(), 6);
    const double etam = (y.row(1).array() * y.row(4).array()).mean();
    EXPECT_NEAR(etam, 0.5, 0.06);
    std::ifstream samples(out / "phase3" / "donor" / "samples.csv");
    std::string header;
    while (std::getline(samples, header) && header.starts_with("#")) {}
    EXPECT_TRUE(header.starts_with("v,mu_uN_per_m,kb_J,b2,etam_over_mu_s,sigma_deg,etam_Pa_s_um,")) << header;
    bool etamRow = false;  // the flow set's eta_m = mu r in posterior_stats.csv, as theta_new's
    for (const PosteriorStatsRow& row : r.stats)
        if (row.posterior == "donor" && row.parameter == "etam_Pa_s_um") {
            etamRow = true;
            EXPECT_NEAR(row.mean, etam, 1e-9);
        }
    EXPECT_TRUE(etamRow);
    std::ifstream table(out / "posterior_table.md");
    const std::string text((std::istreambuf_iterator<char>(table)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("1000 samples per TMCMC/BASIS run, 1000 in a flow data set's phase 1"), std::string::npos);
    // Phase 1 of a flow set is capped: it only starts the joint chains.
    EXPECT_EQ(r.phase1[7].samples.cols(), 1000);
    RbcInferenceOptions capped = smallRun(tmp.path() / "capped", 5000);
    capped.lastPhase = 1;
    const RbcInferenceResult c = runRbcInference(model, {data[1], data[7]}, capped);
    EXPECT_EQ(c.phase1[0].samples.cols(), 5000);
    EXPECT_EQ(c.phase1[1].samples.cols(), 4000);

    // The joint draws belong to their data sets: phase 3 of the seven single-cell sets does not take
    // the draws of eight.
    RbcInferenceOptions phase3 = o;
    phase3.firstPhase = 3;
    const std::vector<RbcDataSet> seven(data.begin(), data.begin() + 7);
    expectInputError([&] { runRbcInference(model, seven, phase3); }, {"no joint-MCMC draws made with these settings"});

    RbcInferenceOptions rw = smallRun(tmp.path() / "rw", 500);
    rw.method = HierarchicalMethod::Reweighting;
    expectInputError([&] { runRbcInference(model, data, rw); }, {"donor", "--method joint"});
    // Without flow networks in the model the flow set is named, before anything is written.
    expectInputError([&] { runRbcInference(analyticModel(), data, smallRun(tmp.path() / "none", 500)); }, {"donor", "flow networks"});
    EXPECT_FALSE(fs::exists(tmp.path() / "none"));
}

TEST(RbcInference, ResultsDoNotDependOnThreadsOrOnPhaseByPhaseRuns) {
    test::TempDir tmp;
    const auto data = loadRbcDataSets(writeSyntheticData(tmp.path() / "experiments"));
    omp_set_num_threads(1);
    runRbcInference(analyticModel(), data, smallRun(tmp.path() / "one", 300));
    omp_set_num_threads(2);
    runRbcInference(analyticModel(), data, smallRun(tmp.path() / "two", 300));
    // Phase by phase into a third directory (phases 2 and 3 load the earlier ones from disk).
    for (int ph = 1; ph <= 3; ++ph) {
        RbcInferenceOptions o = smallRun(tmp.path() / "steps", 300);
        o.firstPhase = o.lastPhase = ph;
        runRbcInference(analyticModel(), data, o);
    }
    // A run stopped inside phase 3, after its theta_new samples were written, leaves no statistics
    // of the earlier samples; the next run writes them again (the paper's route, whose phase 3a
    // reports when its samples are on disk).
    {
        RbcInferenceOptions o = smallRun(tmp.path() / "stopped", 300);
        o.method = HierarchicalMethod::Reweighting;
        runRbcInference(analyticModel(), data, o);
        const std::string whole = test::slurp(tmp.path() / "stopped" / "posterior_stats.csv");
        o.firstPhase = o.lastPhase = 3;
        o.progress = [](const std::string& line) {
            if (line.starts_with("infer phase3/theta_new: done")) throw std::runtime_error("stopped");
        };
        fs::remove(tmp.path() / "stopped" / "phase3" / "theta_new" / "samples.csv");  // seen written again by the stopped run
        EXPECT_THROW(runRbcInference(analyticModel(), data, o), std::runtime_error);
        EXPECT_TRUE(fs::exists(tmp.path() / "stopped" / "phase3" / "theta_new" / "samples.csv"));
        EXPECT_FALSE(fs::exists(tmp.path() / "stopped" / "posterior_stats.csv"));
        EXPECT_FALSE(fs::exists(tmp.path() / "stopped" / "posterior_table.md"));
        o.progress = nullptr;
        runRbcInference(analyticModel(), data, o);
        EXPECT_EQ(test::slurp(tmp.path() / "stopped" / "posterior_stats.csv"), whole);
    }
    // --resume on a finished directory reuses every run.
    RbcInferenceOptions again = smallRun(tmp.path() / "two", 300);
    again.resume = true;
    runRbcInference(analyticModel(), data, again);
    omp_set_num_threads(1);
    const std::string one = test::slurp(tmp.path() / "one" / "posterior_stats.csv");
    EXPECT_FALSE(one.empty());
    std::cerr << one << test::slurp(tmp.path() / "one" / "phase1" / "posterior_stats.csv") << test::slurp(tmp.path() / "one" / "phase2" / "posterior_stats.csv");
    EXPECT_EQ(one, test::slurp(tmp.path() / "two" / "posterior_stats.csv"));
    EXPECT_EQ(one, test::slurp(tmp.path() / "steps" / "posterior_stats.csv"));
    EXPECT_EQ(test::slurp(tmp.path() / "one" / "phase1" / "posterior_stats.csv"),
              test::slurp(tmp.path() / "two" / "phase1" / "posterior_stats.csv"));
    // Phase 2 without phase 1 in a fresh directory: a clear error.
    RbcInferenceOptions missing = smallRun(tmp.path() / "empty", 300);
    missing.firstPhase = missing.lastPhase = 2;
    expectInputError([&] { runRbcInference(analyticModel(), data, missing); }, {"phase1/evans_fung_1972", "--phase 1"});
}

TEST(RbcPriorBox, JsonNamesEveryParameterWithItsBounds) {
    RbcPriorBox box;
    box.set("v", 0.8, 0.95);
    const nlohmann::json j = priorBoxJson(box);
    ASSERT_EQ(j.size(), RbcPriorBox::parameterNames().size());
    EXPECT_EQ(j["v"], nlohmann::json({0.8, 0.95}));
    const auto [lo, hi] = RbcPriorBox{}.bounds("b2");
    EXPECT_EQ(j["b2"], nlohmann::json({lo, hi}));
}

// Reused phase-1 posteriors must have been made with the same record (prior box, flow networks);
// phase 1 writes it.
TEST(RbcPriorBox, PhaseOneRecordIsWrittenByPhaseOneAndCheckedOnReuse) {
    test::TempDir tmp;
    const nlohmann::json box = priorBoxJson(RbcPriorBox{});
    nlohmann::json withFlow = box;
    withFlow["flow_model"] = "0123abcd";
    checkPhase1Record(tmp.path(), withFlow, false, false);
    EXPECT_FALSE(std::filesystem::exists(tmp.path() / kPhase1PriorBoxFile));
    checkPhase1Record(tmp.path(), box, true, false);  // nothing recorded yet: nothing to compare
    checkPhase1Record(tmp.path(), withFlow, false, true);
    ASSERT_TRUE(std::filesystem::exists(tmp.path() / kPhase1PriorBoxFile));
    checkPhase1Record(tmp.path(), withFlow, true, false);
    expectInputError([&] { checkPhase1Record(tmp.path(), box, true, false); },
                     {kPhase1PriorBoxFile, "0123abcd", "--flow-model"});
    nlohmann::json otherNetworks = withFlow;
    otherNetworks["flow_model"] = "fedc9876";
    expectInputError([&] { checkPhase1Record(tmp.path(), otherNetworks, true, true); }, {"fedc9876"});
    EXPECT_EQ(nlohmann::json::parse(test::slurp(tmp.path() / kPhase1PriorBoxFile)), withFlow);  // compared before written
    checkPhase1Record(tmp.path(), otherNetworks, false, true);  // a fresh phase 1 replaces the record
    EXPECT_EQ(nlohmann::json::parse(test::slurp(tmp.path() / kPhase1PriorBoxFile)), otherNetworks);
}

}  // namespace
}  // namespace trbc
