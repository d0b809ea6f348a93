// The flow data's likelihood (inference/flow_likelihood.hpp): the offset-normal density against
// the dense multivariate normal, the inputs the model receives, the regime term, the critical
// stresses, and the maximum of the likelihood at the cell that made the data.
#include "inference/flow_likelihood.hpp"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>
#include <random>

#include "core/error.hpp"
#include "inference/rbc_problem.hpp"
#include "surrogate/flow_surrogate.hpp"
#include "test_support.hpp"

using namespace trbc;

namespace {

/// log N(r; 0, C) by a Cholesky factor.
double denseNormalLogPdf(const Eigen::VectorXd& r, const Eigen::MatrixXd& C) {
    const Eigen::LLT<Eigen::MatrixXd> llt(C);
    const Eigen::VectorXd z = llt.matrixL().solve(r);
    const double logDet = 2.0 * llt.matrixL().toDenseMatrix().diagonal().array().log().sum();
    return -0.5 * (z.squaredNorm() + logDet + static_cast<double>(r.size()) * std::log(2.0 * std::numbers::pi));
}

/// An analytic flow model: the inclination falls linearly with eta_m and log Ca, the TTF is
/// 0.5 (1 + eta_m)^-1, the cell tank-treads above a stress of 0.1 Pa (p a logistic in log stress),
/// and the critical stress is 0.05 (1 + eta_m) Pa. Every column's input is recorded.
struct AnalyticFlow {
    Eigen::MatrixXd lastX;
    Eigen::VectorXd lastEtaIn;
    static double angle(const Eigen::VectorXd& c) {
        const double ca = c(5) * 1e-3 * c(6) * std::sqrt(kRbcAreaRadius2) / c(1);
        return 20.0 - 8.0 * c(4) - 2.0 * std::log(ca);
    }
    FlowModel model() {
        FlowModel m;
        m.tankTreading = [this](const Eigen::MatrixXd& x, const Eigen::VectorXd& etaIn) {
            lastX = x;
            lastEtaIn = etaIn;
            Eigen::MatrixXd y(3, x.cols());
            for (Eigen::Index k = 0; k < x.cols(); ++k) {
                const double stress = x(5, k) * 1e-3 * x(6, k);
                y(0, k) = 1.0 / (1.0 + std::pow(0.1 / stress, 4.0));
                y(1, k) = angle(x.col(k));
                y(2, k) = 0.5 / (1.0 + x(4, k));
            }
            return y;
        };
        m.criticalStressPa = [this](const Eigen::MatrixXd& x, const Eigen::VectorXd& etaIn) {
            lastX = x;
            lastEtaIn = etaIn;
            return Eigen::VectorXd((0.05 * (1.0 + x.row(4).array())).transpose());
        };
        return m;
    }
};

/// (v, mu, kb, b2, r, sigma) in inference units.
Eigen::VectorXd donorCell(double r, double sigma) {
    Eigen::VectorXd c(6);
    c << 0.93, 4.66, 0.226, 2.0, r, sigma;
    return c;
}

}  // namespace

TEST(FlowLikelihood, OffsetNormalIsTheDenseMultivariateNormal) {
    std::mt19937_64 rng(7);
    std::normal_distribution<double> z;
    for (int n : {1, 2, 5, 13}) {
        Eigen::VectorXd r(n);
        for (int k = 0; k < n; ++k) r[k] = 1.5 * z(rng) + 0.7;
        for (double s : {0.0, 0.3, 2.0}) {
            const double sigma = 0.4;
            const Eigen::MatrixXd C =
                sigma * sigma * Eigen::MatrixXd::Identity(n, n) + s * s * Eigen::MatrixXd::Ones(n, n);
            EXPECT_NEAR(offsetNormalLogPdf(r, sigma, s), denseNormalLogPdf(r, C), 1e-10) << "n " << n << " s " << s;
        }
        double independent = 0.0;
        for (int k = 0; k < n; ++k) independent += normalLogPdf(r[k], 0.0, 0.4);
        EXPECT_NEAR(offsetNormalLogPdf(r, 0.4, 0.0), independent, 1e-10);
    }
    EXPECT_EQ(offsetNormalLogPdf(Eigen::VectorXd::Ones(3), 0.0, 1.0), -std::numeric_limits<double>::infinity());
    // A common offset of the residuals costs less with s > 0: a curve that is off as a whole is what
    // the networks' error explains.
    const Eigen::VectorXd shifted = Eigen::VectorXd::Constant(8, 1.0);
    EXPECT_GT(offsetNormalLogPdf(shifted, 0.3, 1.0), offsetNormalLogPdf(shifted, 0.3, 0.0) + 10.0);
}

TEST(FlowLikelihood, TheModelSeesTheCellsFlowInputsAndTheExperimentsCytosol) {
    AnalyticFlow a;
    FlowDataSet d;
    d.name = "donor";
    d.etaInMPaS = 12.0;
    d.curves = {{23.9, Eigen::Vector2d(10.0, 100.0), Eigen::Vector2d(14.0, 12.0)},
                {104.0, Eigen::Vector3d(2.0, 20.0, 200.0), Eigen::Vector3d(20.0, 17.0, 13.0)}};
    Eigen::MatrixXd cells(6, 2);
    cells.col(0) = donorCell(0.15, 0.5);
    cells.col(1) = donorCell(0.05, 0.5);
    flowLogLikelihood(a.model(), d, cells);
    ASSERT_EQ(a.lastX.cols(), 10);
    for (Eigen::Index i = 0; i < 2; ++i)
        for (Eigen::Index k = 0; k < 5; ++k) {
            const auto x = a.lastX.col(i * 5 + k);
            EXPECT_DOUBLE_EQ(x(0), 0.93);
            EXPECT_DOUBLE_EQ(x(1), 4.66);
            EXPECT_NEAR(x(2), 4.66 * kRbcAreaRadius2 / 0.226, 1e-9);  // FvK = mu R_A^2 / kb
            EXPECT_DOUBLE_EQ(x(3), 2.0);
            EXPECT_DOUBLE_EQ(x(4), 4.66 * cells(4, i));  // eta_m = mu r
            EXPECT_DOUBLE_EQ(x(5), k < 2 ? 23.9 : 104.0);
        }
    EXPECT_DOUBLE_EQ(a.lastX(6, 1), 100.0);
    EXPECT_DOUBLE_EQ(a.lastX(6, 9), 200.0);
    EXPECT_TRUE((a.lastEtaIn.array() == 12.0).all());
}

TEST(FlowLikelihood, InclinationIsTheOffsetNormalOfEachCurvePlusTheRegime) {
    AnalyticFlow a;
    FlowDataSet d;
    d.name = "donor";
    d.modelErrorSd = 1.0;
    d.regimeErrorRate = 0.1;
    d.curves = {{23.9, Eigen::Vector3d(1.0, 10.0, 100.0), Eigen::Vector3d(14.0, 12.0, 11.0)},
                {55.9, Eigen::Vector2d(5.0, 50.0), Eigen::Vector2d(17.0, 15.0)}};
    const Eigen::VectorXd c = donorCell(0.15, 0.4);
    double expected = 0.0;
    for (const FlowCurve& curve : d.curves) {
        Eigen::VectorXd r(curve.value.size());
        double pLeast = 1.0;
        for (Eigen::Index k = 0; k < r.size(); ++k) {
            Eigen::VectorXd x(7);
            x << c(0), c(1), 0.0, c(3), c(1) * c(4), curve.etaOutMPaS, curve.rate[k];
            r[k] = curve.value[k] - AnalyticFlow::angle(x);
            const double stress = curve.etaOutMPaS * 1e-3 * curve.rate[k];
            pLeast = std::min(pLeast, 1.0 / (1.0 + std::pow(0.1 / stress, 4.0)));
        }
        expected += offsetNormalLogPdf(r, 0.4, 1.0) + std::log(0.1 + 0.8 * pLeast);  // one regime term a curve
    }
    EXPECT_NEAR(flowLogLikelihood(a.model(), d, c)[0], expected, 1e-9);
    // The regime term: the point at 23.9 mPa s and 1 1/s (0.024 Pa, p 0.0033) is one the cell
    // tumbles at. Without the classifier's error rate its curve costs log p = -5.7; with e = 0.1 at
    // most log e = -2.3, and the other curve, which tank-treads, costs log(1 - e) at least.
    FlowDataSet exact = d;
    exact.regimeErrorRate = 0.0;
    const double p = 1.0 / (1.0 + std::pow(0.1 / 0.0239, 4.0));
    const double withE = flowLogLikelihood(a.model(), d, c)[0], withoutE = flowLogLikelihood(a.model(), exact, c)[0];
    EXPECT_GT(withE - withoutE, std::log(0.1 / p) + std::log(0.9));
    EXPECT_LT(withE - withoutE, std::log((0.1 + 0.8 * p) / p));
    // sigma <= 0: -inf.
    EXPECT_EQ(flowLogLikelihood(a.model(), d, donorCell(0.15, 0.0))[0], -std::numeric_limits<double>::infinity());
}

TEST(FlowLikelihood, TtfAndCriticalStressAreRelativeOnTheLogScale) {
    AnalyticFlow a;
    FlowDataSet ttf;
    ttf.name = "ttf";
    ttf.observable = FlowObservable::Ttf;
    ttf.modelErrorSd = 0.06;
    ttf.curves = {{28.9, Eigen::Vector2d(10.0, 50.0), Eigen::Vector2d(0.45, 0.40)}};
    const Eigen::VectorXd c = donorCell(0.15, 0.05);
    const double f = 0.5 / (1.0 + 4.66 * 0.15);
    // The curve's regime term at its least likely point, the lower rate.
    const double expected = offsetNormalLogPdf(Eigen::Vector2d(std::log(0.45 / f), std::log(0.40 / f)), 0.05, 0.06) +
                            std::log(1.0 / (1.0 + std::pow(0.1 / (28.9e-3 * 10.0), 4.0)));
    EXPECT_NEAR(flowLogLikelihood(a.model(), ttf, c)[0], expected, 1e-9);

    FlowDataSet tau;
    tau.name = "critical";
    tau.observable = FlowObservable::CriticalStress;
    tau.modelErrorSd = 0.3;
    tau.curves = {{10.7, {}, Eigen::Vector3d(0.9, 0.8, 0.6)}, {31.0, {}, Eigen::Vector2d(0.058, 0.047)}};
    const double t = 0.05 * (1.0 + 4.66 * 0.15);
    const double want = offsetNormalLogPdf(Eigen::Vector3d(std::log(0.9 / t), std::log(0.8 / t), std::log(0.6 / t)), 0.05, 0.3) +
                        offsetNormalLogPdf(Eigen::Vector2d(std::log(0.058 / t), std::log(0.047 / t)), 0.05, 0.3);
    EXPECT_NEAR(flowLogLikelihood(a.model(), tau, c)[0], want, 1e-9);
    // One model column per viscosity: a critical stress depends on the cell and eta_out only.
    ASSERT_EQ(a.lastX.cols(), 2);
    EXPECT_DOUBLE_EQ(a.lastX(5, 0), 10.7);
    EXPECT_DOUBLE_EQ(a.lastX(5, 1), 31.0);
}

TEST(FlowLikelihood, ABatchOfCellsIsEachCellAlone) {
    // The column layout of a batch (cell-major, one column a point or, for stresses, a curve)
    // against one call per cell, for the three observables.
    AnalyticFlow a;
    FlowDataSet angle;
    angle.name = "angle";
    angle.regimeErrorRate = 0.05;
    angle.modelErrorSd = 0.8;
    angle.curves = {{23.9, Eigen::Vector3d(5.0, 20.0, 80.0), Eigen::Vector3d(14.0, 13.0, 12.0)},
                    {104.0, Eigen::Vector2d(2.0, 30.0), Eigen::Vector2d(19.0, 16.0)}};
    FlowDataSet ttf = angle;
    ttf.name = "ttf";
    ttf.observable = FlowObservable::Ttf;
    ttf.curves = {{28.9, Eigen::Vector3d(8.0, 30.0, 100.0), Eigen::Vector3d(0.5, 0.45, 0.4)}};
    FlowDataSet tau = angle;
    tau.name = "tau";
    tau.observable = FlowObservable::CriticalStress;
    tau.curves = {{10.7, {}, Eigen::Vector2d(0.8, 0.6)}, {23.9, {}, Eigen::Vector3d(0.2, 0.1, 0.15)}, {31.0, {}, Eigen::VectorXd::Constant(1, 0.05)}};
    Eigen::MatrixXd cells(6, 4);
    for (int i = 0; i < 4; ++i) cells.col(i) = donorCell(0.03 + 0.04 * i, 0.3 + 0.1 * i);
    for (const FlowDataSet* d : {&angle, &ttf, &tau}) {
        const Eigen::VectorXd batch = flowLogLikelihood(a.model(), *d, cells);
        for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(batch[i], flowLogLikelihood(a.model(), *d, cells.col(i))[0]) << d->name << " cell " << i;
        EXPECT_NE(batch[0], batch[3]) << d->name;
    }
}

TEST(FlowLikelihood, OutsideTheNetworksEtamRangeTheLikelihoodIsZero) {
    AnalyticFlow a;
    FlowDataSet d;
    d.name = "donor";
    d.etamRange = {0.03, 3.0};
    d.curves = {{23.9, Eigen::Vector2d(10.0, 100.0), Eigen::Vector2d(14.0, 12.0)}};
    Eigen::MatrixXd cells(6, 3);
    cells.col(0) = donorCell(0.15, 0.5);          // eta_m 0.70
    cells.col(1) = donorCell(3.1 / 4.66, 0.5);    // 3.1
    cells.col(2) = donorCell(0.02 / 4.66, 0.5);   // 0.02
    const Eigen::VectorXd ll = flowLogLikelihood(a.model(), d, cells);
    EXPECT_TRUE(std::isfinite(ll[0]));
    EXPECT_EQ(ll[1], -std::numeric_limits<double>::infinity());
    EXPECT_EQ(ll[2], -std::numeric_limits<double>::infinity());
    EXPECT_EQ(a.lastX.cols(), 2) << "only the cell inside the range is evaluated";

    // An in-range cell between two outside it keeps its value; a batch of cells all outside the
    // range never calls the networks.
    Eigen::MatrixXd mixed(6, 3);
    mixed << cells.col(1), cells.col(0), cells.col(2);
    EXPECT_EQ(flowLogLikelihood(a.model(), d, mixed)[1], ll[0]);
    a.lastX = Eigen::MatrixXd::Constant(1, 1, 42.0);  // a call, even with no columns, replaces it
    const Eigen::VectorXd none = flowLogLikelihood(a.model(), d, cells.rightCols(2));
    EXPECT_EQ(none[0], -std::numeric_limits<double>::infinity());
    EXPECT_EQ(a.lastX.size(), 1);
}

TEST(FlowLikelihood, PeaksAtTheMembraneViscosityThatMadeTheData) {
    // Curves of a cell with r = 0.12 s plus a common offset of 0.5 deg and noise of 0.2 deg: the
    // likelihood over r peaks within the offset's reach of the truth (8 deg per Pa s um of eta_m:
    // 0.5 deg is 0.0134 s of r at mu 4.66), and the networks' error widens the peak.
    AnalyticFlow a;
    std::mt19937_64 rng(3);
    std::normal_distribution<double> z;
    FlowDataSet d;
    d.name = "synthetic";
    d.regimeErrorRate = 0.1;
    const double rTrue = 0.12;
    for (double eta : {23.9, 55.9, 104.0}) {
        FlowCurve c{eta, Eigen::VectorXd(6), Eigen::VectorXd(6)};
        for (int k = 0; k < 6; ++k) {
            c.rate[k] = 20.0 * std::pow(1.6, k);
            Eigen::VectorXd x(7);
            x << 0.93, 4.66, 0.0, 2.0, 4.66 * rTrue, eta, c.rate[k];
            c.value[k] = AnalyticFlow::angle(x) + 0.5 + 0.2 * z(rng);
        }
        d.curves.push_back(c);
    }
    const int grid = 401;
    Eigen::MatrixXd cells(6, grid);
    for (int j = 0; j < grid; ++j) cells.col(j) = donorCell(0.02 + 0.2 * j / (grid - 1), 0.2);
    auto peakAndWidth = [&](double s) {
        d.modelErrorSd = s;
        const Eigen::VectorXd ll = flowLogLikelihood(a.model(), d, cells);
        Eigen::Index best;
        const double top = ll.maxCoeff(&best);
        int within = 0;  // grid points within 2 log units of the top
        for (int j = 0; j < grid; ++j) within += ll[j] > top - 2.0;
        return std::pair<double, int>(cells(4, best), within);
    };
    const auto [rExact, widthExact] = peakAndWidth(0.0);
    const auto [rOffset, widthOffset] = peakAndWidth(1.0);
    EXPECT_NEAR(rExact, rTrue, 0.02);
    EXPECT_NEAR(rOffset, rTrue, 0.02);
    EXPECT_GT(widthOffset, 3 * widthExact);
}

TEST(FlowLikelihood, BadDataSetsAndCellsAreRefusedByName) {
    AnalyticFlow a;
    FlowDataSet d;
    d.name = "donor_7";
    EXPECT_THROW(
        {
            try {
                flowLogLikelihood(a.model(), d, donorCell(0.1, 0.3));
            } catch (const InputError& e) {
                EXPECT_NE(std::string(e.what()).find("donor_7"), std::string::npos);
                throw;
            }
        },
        InputError);
    d.curves = {{23.9, Eigen::Vector2d(1.0, 2.0), Eigen::Vector3d(1.0, 2.0, 3.0)}};
    EXPECT_THROW(flowLogLikelihood(a.model(), d, donorCell(0.1, 0.3)), InputError);
    d.curves = {{23.9, Eigen::Vector2d(1.0, 2.0), Eigen::Vector2d(10.0, 12.0)}};
    EXPECT_THROW(flowLogLikelihood(a.model(), d, Eigen::MatrixXd::Ones(5, 2)), InputError);
    d.regimeErrorRate = 0.6;
    EXPECT_THROW(flowLogLikelihood(a.model(), d, donorCell(0.1, 0.3)), InputError);
    // A TTF or critical stress is compared on the log scale: a value <= 0 is named, not a silent -inf.
    FlowDataSet tau;
    tau.name = "stresses";
    tau.observable = FlowObservable::CriticalStress;
    tau.curves = {{10.7, {}, Eigen::Vector2d(0.8, 0.0)}};
    try {
        flowLogLikelihood(a.model(), tau, donorCell(0.1, 0.3));
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("'stresses': a critical_stress_Pa at 10.7 mPa s is not > 0"), std::string::npos) << e.what();
    }
}

TEST(FlowLikelihood, TheShippedNetworksAsAFlowModelAreTheirPredictions) {
    const auto s = std::make_shared<FlowSurrogate>(FlowSurrogate::load(std::filesystem::path(TRBC_SOURCE_DIR) / "data/surrogates/flow"));
    const FlowModel m = surrogateFlowModel(s);
    Eigen::MatrixXd x(7, 2);
    x.col(0) << 0.93, 4.66, 221.0, 2.0, 0.70, 55.9, 20.0;
    x.col(1) << 0.85, 3.0, 100.0, 1.0, 0.30, 23.9, 1.0;
    const Eigen::VectorXd etaIn = Eigen::Vector2d(10.0, 6.0);
    const FlowPrediction p = s->predict(x, etaIn);
    const Eigen::MatrixXd y = m.tankTreading(x, etaIn);
    for (int k = 0; k < 2; ++k) {
        EXPECT_DOUBLE_EQ(y(0, k), p.pTankTreading[k]);
        EXPECT_DOUBLE_EQ(y(1, k), p.inclinationDeg[k]);
        EXPECT_DOUBLE_EQ(y(2, k), p.ttf[k]);
    }
    const Eigen::VectorXd tau = m.criticalStressPa(x, etaIn);
    const Eigen::VectorXd want = s->criticalStressPa(x, etaIn, 0.5, true);
    EXPECT_DOUBLE_EQ(tau[0], want[0]);
    EXPECT_DOUBLE_EQ(tau[1], want[1]);
    EXPECT_TRUE(std::isfinite(tau[0]) && tau[0] > 0.0);
}
