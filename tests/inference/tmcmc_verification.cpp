#include "tmcmc_verification.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <vector>

#include "inference/priors.hpp"

namespace trbc::tmcmc_verification {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
const double kLog2Pi = std::log(2 * std::numbers::pi);

Eigen::VectorXd sampleMean(const Eigen::MatrixXd& s) { return s.rowwise().mean(); }
Eigen::MatrixXd sampleCov(const Eigen::MatrixXd& s) {
    const Eigen::MatrixXd d = s.colwise() - sampleMean(s);
    return d * d.transpose() / static_cast<double>(s.cols());
}

}  // namespace

Verification gaussian1D() {
    Verification v{"T1", {}, Eigen::VectorXd::Constant(1, 1.0), Eigen::MatrixXd::Constant(1, 1, 0.25), -std::log(20.0)};
    v.problem.prior = uniformBoxPrior(Eigen::VectorXd::Constant(1, -10), Eigen::VectorXd::Constant(1, 10));
    v.problem.logLikelihood = [](const Eigen::VectorXd& t) {
        const double z = (t[0] - 1.0) / 0.5;
        return -0.5 * z * z - std::log(0.5) - 0.5 * kLog2Pi;
    };
    return v;
}

Verification gaussian5D() {
    Eigen::VectorXd m(5);
    m << -2, -1, 0, 1, 2;
    Eigen::MatrixXd S(5, 5);
    for (int i = 0; i < 5; ++i)
        for (int j = 0; j < 5; ++j) S(i, j) = std::pow(0.5, std::abs(i - j));
    const Eigen::MatrixXd P = S.inverse();
    Verification v{"T2", {}, m, S, 2.5 * kLog2Pi + 0.5 * std::log(std::pow(0.75, 4)) - 5 * std::log(20.0)};
    v.problem.prior = uniformBoxPrior(Eigen::VectorXd::Constant(5, -10), Eigen::VectorXd::Constant(5, 10));
    v.problem.logLikelihood = [m, P](const Eigen::VectorXd& t) {
        const Eigen::VectorXd d = t - m;
        return -0.5 * d.dot(P * d);
    };
    return v;
}

Verification bimodal() {
    Verification v{"T3", {}, Eigen::VectorXd::Constant(2, 0.3 * -3 + 0.7 * 3), Eigen::MatrixXd(), -std::log(400.0)};
    v.problem.prior = uniformBoxPrior(Eigen::VectorXd::Constant(2, -10), Eigen::VectorXd::Constant(2, 10));
    v.problem.logLikelihood = [](const Eigen::VectorXd& t) {
        auto logN = [&](double c) { return -((t.array() - c).square().sum()) / (2 * 0.25) - std::log(2 * std::numbers::pi * 0.25); };
        const double a = std::log(0.3) + logN(-3.0), b = std::log(0.7) + logN(3.0);
        const double mx = std::max(a, b);
        return mx + std::log(std::exp(a - mx) + std::exp(b - mx));
    };
    return v;
}

Verification regression() {
    Eigen::VectorXd x(5), y(5);
    x << 0, 0.25, 0.5, 0.75, 1;
    y << 0.9, 1.6, 2.1, 2.4, 3.1;
    const double s = 0.2;
    Eigen::MatrixXd X(5, 2);
    X.col(0).setOnes();
    X.col(1) = x;
    const Eigen::MatrixXd Sn = (Eigen::Matrix2d::Identity() / 4.0 + X.transpose() * X / (s * s)).inverse();
    const Eigen::VectorXd mn = Sn * X.transpose() * y / (s * s);
    const Eigen::MatrixXd C = s * s * Eigen::MatrixXd::Identity(5, 5) + 4.0 * X * X.transpose();
    const double logZ = -0.5 * (5 * kLog2Pi + std::log(C.determinant()) + y.dot(C.ldlt().solve(y)));
    Verification v{"T4", {}, mn, Sn, logZ};
    v.problem.prior = std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{normalPrior(0, 2), normalPrior(0, 2)});
    v.problem.logLikelihood = [X, y, s](const Eigen::VectorXd& b) {
        const Eigen::VectorXd r = y - X * b;
        return -0.5 * r.squaredNorm() / (s * s) - 5 * (std::log(s) + 0.5 * kLog2Pi);
    };
    return v;
}

Verification halfNormal() {
    Verification v{"half-normal", {}, Eigen::VectorXd::Constant(1, std::sqrt(2 / std::numbers::pi)),
                   Eigen::MatrixXd::Constant(1, 1, 1 - 2 / std::numbers::pi), std::log(0.5 / 20)};
    v.problem.prior = uniformBoxPrior(Eigen::VectorXd::Constant(1, -10), Eigen::VectorXd::Constant(1, 10));
    v.problem.logLikelihood = [](const Eigen::VectorXd& t) { return t[0] < 0 ? -kInf : -0.5 * t[0] * t[0] - 0.5 * kLog2Pi; };
    return v;
}

Verification unknownNoise() {
    Eigen::VectorXd x(5), y(5);
    x << 0, 0.25, 0.5, 0.75, 1;
    y << 0.9, 1.6, 2.1, 2.4, 3.1;
    Eigen::VectorXd mean = Eigen::VectorXd::Zero(3);
    mean[2] = 0.221746;
    Verification v{"T5", {}, mean, Eigen::MatrixXd::Identity(3, 3), -4.068997};
    v.problem.prior = std::make_shared<ProductPrior>(
        std::vector<ScalarPriorPtr>{normalPrior(0, 2), normalPrior(0, 2), uniformPrior(0.05, 1.0)});
    v.problem.logLikelihood = [x, y](const Eigen::VectorXd& t) {
        const double s = t[2];
        const Eigen::VectorXd r = y - (t[0] + t[1] * x.array()).matrix();
        return -0.5 * r.squaredNorm() / (s * s) - 5 * (std::log(s) + 0.5 * kLog2Pi);
    };
    return v;
}

const char* variantName(Variant v) { return v == Variant::Basis ? "BASIS" : "TMCMC"; }

TmcmcOptions settings(Variant v, int N, std::uint64_t seed, int burnIn) {
    TmcmcOptions o;
    o.populationSize = N;
    o.targetCoV = 0.4;
    o.covarianceScaling = 0.06;
    o.seed = seed;
    o.maxChainLength = v == Variant::Basis ? 1 : 0;
    if (burnIn > 0) o.burnIn = {burnIn};
    return o;
}

Errors runAndCompare(const Verification& v, const TmcmcOptions& o, TmcmcResult* result) {
    const auto t0 = std::chrono::steady_clock::now();
    TmcmcResult local;
    TmcmcResult& r = result ? *result : local;
    r = runTmcmc(v.problem, o);
    Errors e;
    e.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    e.stages = static_cast<int>(r.stages.size());
    e.logZ = r.logEvidence - v.logZ;
    const Eigen::VectorXd m = sampleMean(r.samples);
    const Eigen::MatrixXd C = sampleCov(r.samples);
    const Eigen::VectorXd sd = v.cov.diagonal().cwiseSqrt();
    e.mean = ((m - v.mean).array() / sd.array()).abs().maxCoeff();
    e.cov = ((C - v.cov).array() / (sd * sd.transpose()).array()).abs().maxCoeff();
    return e;
}

double fractionNegative(const TmcmcResult& r) { return (r.samples.row(0).array() < 0).cast<double>().mean(); }

}  // namespace trbc::tmcmc_verification
