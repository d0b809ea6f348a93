// The population sums vectorise only if floating-point operations may be executed speculatively
// (if-conversion of the branch-free selects in population_kernels.hpp); nothing here relies on
// floating-point traps.
#pragma GCC optimize("no-trapping-math")
#include "inference/population.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/error.hpp"
#include "inference/population_kernels.hpp"
#include "inference/rbc_problem.hpp"

namespace trbc {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
const double kHalfLog2Pi = 0.5 * std::log(2.0 * std::numbers::pi);
}  // namespace

// ------------------------------------------------------------------------------------------------
// Parameters

const std::vector<std::string>& pooledParameterNames() {
    static const std::vector<std::string> n = {"v", "mu", "kb", "b2", "r"};
    return n;
}

const std::vector<std::string>& pooledOutputNames() {
    static const std::vector<std::string> n = {"v", "mu_uN_per_m", "kb_J", "b2", "etam_over_mu_s"};
    return n;
}

Eigen::VectorXd pooledOutputScale() {
    Eigen::VectorXd s = Eigen::VectorXd::Ones(kPooledDimension);
    s[kPooledKb] = kJoulePerKbUnit;
    return s;
}

const std::vector<std::string>& hyperParameterNames() {
    static const std::vector<std::string> n = {"mu_v", "sd_v", "mu_mu", "sd_mu", "mu_kb", "sd_kb", "mu_b2", "sd_b2", "mu_r", "sd_r"};
    return n;
}

const std::vector<std::string>& hyperOutputNames() {
    static const std::vector<std::string> n = {"mean_v",  "sd_v",    "mean_mu_uN_per_m",    "sd_mu_uN_per_m",
                                               "mean_kb_J", "sd_kb_J", "mean_b2",            "sd_b2",
                                               "mean_etam_over_mu_s", "sd_etam_over_mu_s"};
    return n;
}

Eigen::VectorXd hyperOutputScale() {
    Eigen::VectorXd s = Eigen::VectorXd::Ones(kHyperDimension);
    s[4] = s[5] = kJoulePerKbUnit;
    return s;
}

std::shared_ptr<const ProductPrior> hyperPrior() {
    // 4.2 table: (mean, sd) per pooled component.
    return std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{
        uniformPrior(0.65, 1.0), uniformPrior(0.01, 0.5),      // v
        uniformPrior(1.0, 10.0), uniformPrior(0.01, 10.0),     // mu, uN/m
        uniformPrior(kKbLow, kKbHigh), uniformPrior(0.01, 0.5),  // kb, 1e-18 J
        uniformPrior(0.0, 4.0), uniformPrior(0.01, 10.0),      // b2
        uniformPrior(0.01, 0.4), uniformPrior(0.01, 0.5)});    // r, s
}

std::shared_ptr<const ProductPrior> newCellBoxPrior() {
    return std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{uniformPrior(0.65, 1.0), uniformPrior(0.0, 20.0),
                                                                      uniformPrior(kKbLow, kKbHigh), uniformPrior(0.0, 10.0),
                                                                      uniformPrior(0.0, 2.0)});
}

// ------------------------------------------------------------------------------------------------
// Population density

double NormalFactor::logDensity(double x) const {
    if (!(x >= lo && x <= hi)) return -kInf;
    const double z = (x - mean) / sd;
    return -0.5 * z * z - logNorm;
}

NormalFactor populationFactor(int j, const Eigen::Ref<const Eigen::VectorXd>& psi) {
    if (psi.size() != kHyperDimension)
        throw InputError(fmt::format("population density: psi needs {} entries, got {}", kHyperDimension, psi.size()));
    if (j < 0 || j >= kPooledDimension) throw InputError(fmt::format("population density: no pooled component {}", j));
    NormalFactor f;
    f.mean = psi[2 * j];
    f.sd = psi[2 * j + 1];
    f.lo = -kInf;
    f.hi = kInf;
    if (j == kPooledV) f.lo = 0.0, f.hi = 1.0;           // TN(v; mu_v, sd_v, [0, 1])
    if (j == kPooledKb) f.lo = kKbLow, f.hi = kKbHigh;   // TN(kb; mu_kb, sd_kb, [kappa_lo, kappa_hi])
    double logZ = 0.0;
    if (std::isfinite(f.lo)) logZ = logNormalMass((f.lo - f.mean) / f.sd, (f.hi - f.mean) / f.sd);
    f.logNorm = std::log(f.sd) + kHalfLog2Pi + logZ;
    return f;
}

double populationLogDensity(const Eigen::Ref<const Eigen::VectorXd>& theta, const Eigen::Ref<const Eigen::VectorXd>& psi) {
    if (theta.size() != kPooledDimension)
        throw InputError(fmt::format("population density: theta needs {} entries, got {}", kPooledDimension, theta.size()));
    double s = 0.0;
    for (int j = 0; j < kPooledDimension; ++j) s += populationFactor(j, psi).logDensity(theta[j]);
    return s;
}

// ------------------------------------------------------------------------------------------------
// q(FvK | psi)

RatioDensityParameters fvkDensityParameters(const Eigen::Ref<const Eigen::VectorXd>& psi) {
    RatioDensityParameters p;
    p.muX = psi[2];
    p.sdX = psi[3];
    p.muY = psi[4] / kRbcAreaRadius2;
    p.sdY = psi[5] / kRbcAreaRadius2;
    p.a = 0.01;
    p.b = 0.1;
    p.logZy = logNormalMass((p.a - p.muY) / p.sdY, (p.b - p.muY) / p.sdY);
    return p;
}

double scaledNormalTail(double x) { return detail::scaledNormalTail(x); }

double logFvkDensity(double z, const RatioDensityParameters& p) {
    if (p.a != detail::kFvkYLow || p.b != detail::kFvkYHigh)
        throw InputError(fmt::format("q(FvK): the closed form is implemented for Y on [{}, {}], got [{}, {}]", detail::kFvkYLow,
                                     detail::kFvkYHigh, p.a, p.b));
    return detail::logFvkDensityCore(z, detail::fvkCoefficients(p.muX, p.sdX, p.muY, p.sdY, p.logZy));
}

double logFvkDensityNodes50(double z, const RatioDensityParameters& p) {
    // Reference rule: y_j = a + j D, j = 0..49, all nodes with full weight D.
    const double D = (p.b - p.a) / 49.0;
    double terms[50], mx = -kInf;
    for (int j = 0; j < 50; ++j) {
        const double y = p.a + j * D;
        const double ux = (z * y - p.muX) / p.sdX, uy = (y - p.muY) / p.sdY;
        // log[ y phi(ux) / sdX * phi(uy) / (sdY Zy) ]
        terms[j] = std::log(y) - 0.5 * ux * ux - 0.5 * uy * uy - 2.0 * kHalfLog2Pi - std::log(p.sdX) - std::log(p.sdY) - p.logZy;
        mx = std::max(mx, terms[j]);
    }
    if (!(mx > -kInf)) return -kInf;
    double s = 0.0;
    for (double t : terms) s += std::exp(t - mx);
    return std::log(D * s) + mx;
}

double logFvkDensityMixed(double z, const RatioDensityParameters& p) {
    if (p.a != detail::kFvkYLow || p.b != detail::kFvkYHigh)
        throw InputError(fmt::format("q(FvK): the closed form is implemented for Y on [{}, {}], got [{}, {}]", detail::kFvkYLow,
                                     detail::kFvkYHigh, p.a, p.b));
    return detail::logFvkDensityCoreMixed(z, detail::fvkCoefficients(p.muX, p.sdX, p.muY, p.sdY, p.logZy));
}

double logFvkDensity(double z, const RatioDensityParameters& p, FvkDensityRule rule) {
    switch (rule) {
        case FvkDensityRule::ClosedForm: return logFvkDensityMixed(z, p);
        case FvkDensityRule::ClosedFormDouble: return logFvkDensity(z, p);
        case FvkDensityRule::Nodes50: return logFvkDensityNodes50(z, p);
    }
    return logFvkDensity(z, p);
}

void logFvkDensityArray(const Eigen::Ref<const Eigen::ArrayXd>& z, const Eigen::Ref<const Eigen::ArrayXd>& muX,
                        const Eigen::Ref<const Eigen::ArrayXd>& sdX, const Eigen::Ref<const Eigen::ArrayXd>& muY,
                        const Eigen::Ref<const Eigen::ArrayXd>& sdY, const Eigen::Ref<const Eigen::ArrayXd>& logZy,
                        Eigen::Ref<Eigen::ArrayXd> out) {
    const Eigen::Index n = z.size();
    if (muX.size() != n || sdX.size() != n || muY.size() != n || sdY.size() != n || logZy.size() != n || out.size() != n)
        throw InputError("logFvkDensityArray: all arrays must have the same length");
    std::vector<detail::FvkCoefficients> c(static_cast<std::size_t>(n));
    for (Eigen::Index i = 0; i < n; ++i) c[static_cast<std::size_t>(i)] = detail::fvkCoefficients(muX[i], sdX[i], muY[i], sdY[i], logZy[i]);
    for (Eigen::Index i = 0; i < n; ++i) out[i] = detail::logFvkDensityCore(z[i], c[static_cast<std::size_t>(i)]);
}

}  // namespace trbc
