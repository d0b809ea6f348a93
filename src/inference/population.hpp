#pragma once
// Population model of the hierarchical red-cell inference (docs/BAYESIAN_INFERENCE.md): hyper-parameters
// psi, their prior, the population density p(theta | psi) of the pooled parameters
// theta = (v, mu, kb, b2, r) and the density q(FvK | psi) of FvK = mu R_A^2 / kb under it.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "inference/priors.hpp"

namespace trbc {

// ------------------------------------------------------------------------------------------------
// Parameters

/// Pooled parameters theta (4.1, used): v, mu (uN/m), kb (1e-18 J), b2, r = etam / mu (s).
enum PooledIndex { kPooledV = 0, kPooledMu = 1, kPooledKb = 2, kPooledB2 = 3, kPooledR = 4 };
inline constexpr int kPooledDimension = 5;
const std::vector<std::string>& pooledParameterNames();  ///< v, mu, kb, b2, r
const std::vector<std::string>& pooledOutputNames();     ///< v, mu_uN_per_m, kb_J, b2, etam_over_mu_s
Eigen::VectorXd pooledOutputScale();                     ///< 1 except kb: 1e-18 (to J)

/// Hyper-parameters psi = (mean, sd) of each pooled component, in that order:
/// (mu_v, sd_v, mu_mu, sd_mu, mu_kb, sd_kb, mu_b2, sd_b2, mu_r, sd_r).
inline constexpr int kHyperDimension = 10;
const std::vector<std::string>& hyperParameterNames();
const std::vector<std::string>& hyperOutputNames();  ///< mean_v, sd_v, mean_mu_uN_per_m, ..., sd_etam_over_mu_s
Eigen::VectorXd hyperOutputScale();

/// Hyper-prior of 4.2 (independent uniforms).
std::shared_ptr<const ProductPrior> hyperPrior();

/// Box of phase 3a: v in [0.65, 1], mu in [0, 20], kb in [kappa_lo, kappa_hi], b2 in [0, 10], r in [0, 2].
std::shared_ptr<const ProductPrior> newCellBoxPrior();

// ------------------------------------------------------------------------------------------------
// Population density

/// One factor of p(theta | psi): N(mean, sd^2), truncated to [lo, hi] (infinite bounds = not truncated).
/// log density = -((x - mean)/sd)^2 / 2 - logNorm on [lo, hi], logNorm = log sd + log(2 pi)/2 + log Z.
struct NormalFactor {
    double mean = 0.0, sd = 1.0, lo = 0.0, hi = 0.0, logNorm = 0.0;
    double logDensity(double x) const;
};
/// The factor of pooled component j: TN on [0, 1] for v, TN on [kappa_lo, kappa_hi] for kb,
/// untruncated normals for mu, b2, r. `psi` has kHyperDimension entries.
NormalFactor populationFactor(int pooled, const Eigen::Ref<const Eigen::VectorXd>& psi);

/// log p(theta | psi) for theta = (v, mu, kb, b2, r).
double populationLogDensity(const Eigen::Ref<const Eigen::VectorXd>& theta, const Eigen::Ref<const Eigen::VectorXd>& psi);

// ------------------------------------------------------------------------------------------------
// Density of FvK under the population

/// q(z) is the density of X / Y, X ~ N(muX, sdX^2) (= mu), Y ~ TN(muY, sdY, [a, b]) (= kb / R_A^2,
/// [a, b] = [0.01, 0.1]); logZy = log(Phi((b - muY)/sdY) - Phi((a - muY)/sdY)).
struct RatioDensityParameters {
    double muX = 0.0, sdX = 1.0, muY = 0.0, sdY = 1.0, logZy = 0.0;
    double a = 0.01, b = 0.1;
};
/// The parameters of q(FvK | psi): muX = mu_mu, sdX = sd_mu, muY = mu_kb / R_A^2, sdY = sd_kb / R_A^2.
RatioDensityParameters fvkDensityParameters(const Eigen::Ref<const Eigen::VectorXd>& psi);

enum class FvkDensityRule {
    ClosedForm,        ///< 4.3 closed form, mixed precision in the population sums (default; |d log q| < 1e-5)
    ClosedFormDouble,  ///< 4.3 closed form in double precision throughout (agrees with quadrature to 1e-8)
    Nodes50            ///< the reference's 50-node rule (compatibility)
};

/// log q(z) by the closed form of 4.3:
///   q = exp(-(muX - z muY)^2 / (2 (sdX^2 + z^2 sdY^2))) s [m (Phi(beta) - Phi(alpha)) + s (phi(alpha) - phi(beta))]
///       / (sqrt(2 pi) sdX sdY Zy),
///   P = z^2/sdX^2 + 1/sdY^2, s = P^-1/2, m = (z muX/sdX^2 + muY/sdY^2)/P, alpha = (a-m)/s, beta = (b-m)/s,
/// with the normal tails in log form (no underflow for z far out). z > 0.
double logFvkDensity(double z, const RatioDensityParameters& p);
/// log q(z) by the 50-node rule: y_j = a + j D, D = (b - a)/49, q = D sum_j y_j phi((z y_j - muX)/sdX)/sdX TN(y_j).
double logFvkDensityNodes50(double z, const RatioDensityParameters& p);
/// The closed form in the mixed precision of the population sums (FvkDensityRule::ClosedForm).
double logFvkDensityMixed(double z, const RatioDensityParameters& p);
/// By rule: ClosedForm -> logFvkDensityMixed, ClosedFormDouble -> logFvkDensity, Nodes50 -> the 50-node rule.
double logFvkDensity(double z, const RatioDensityParameters& p, FvkDensityRule rule);

/// The double-precision closed form element by element (all arrays of length n):
/// out_k = log q(z_k | muX_k, sdX_k, muY_k, sdY_k, logZy_k), [a, b] = [0.01, 0.1].
void logFvkDensityArray(const Eigen::Ref<const Eigen::ArrayXd>& z, const Eigen::Ref<const Eigen::ArrayXd>& muX,
                        const Eigen::Ref<const Eigen::ArrayXd>& sdX, const Eigen::Ref<const Eigen::ArrayXd>& muY,
                        const Eigen::Ref<const Eigen::ArrayXd>& sdY, const Eigen::Ref<const Eigen::ArrayXd>& logZy,
                        Eigen::Ref<Eigen::ArrayXd> out);

/// Q(x) e^{x^2/2} for x >= 0, Q(x) = 1 - Phi(x) (scaled upper normal tail): (t/2) h(t) with
/// t = 2 / (2 + x/sqrt 2) and h a 28-term Chebyshev series of erfcx(z)/t in 2t - 1 (relative error
/// < 1e-15). Vectorisable (no branches, no library calls).
double scaledNormalTail(double x);

}  // namespace trbc
