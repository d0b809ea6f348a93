#pragma once
// The verification problems of TMCMC / BASIS with known answers (docs/BAYESIAN_INFERENCE.md), the
// paper's sampler settings and the errors of a run against the exact answers: one definition for
// the tests (tests/inference/test_tmcmc.cpp) and for the seed sweep behind their Monte-Carlo
// tolerances (bench/tmcmc_seed_sweep.cpp).
#include <Eigen/Core>
#include <cstdint>
#include <string>

#include "inference/tmcmc.hpp"

namespace trbc::tmcmc_verification {

struct Verification {
    std::string name;
    TmcmcProblem problem;
    Eigen::VectorXd mean;  // exact posterior mean
    Eigen::MatrixXd cov;   // exact posterior covariance
    double logZ;           // exact log-evidence
};

/// T1: prior U[-10, 10], l = log N(theta; 1, 0.5^2). Posterior N(1, 0.25), log Z = -log 20.
Verification gaussian1D();

/// T2: prior U[-10, 10]^5, l = -(theta - m)^T Sigma^-1 (theta - m) / 2, Sigma_ij = 0.5^|i-j|.
/// log Z = 5/2 log 2 pi + 1/2 log det Sigma - 5 log 20 = -10.959333.
Verification gaussian5D();

/// T3: prior U[-10, 10]^2, l = log[0.3 N((-3,-3), 0.25 I) + 0.7 N((3,3), 0.25 I)], log Z = -log 400.
/// `cov` is empty: the checks are the weight of each mode (fractionNegative) and log Z.
Verification bimodal();

/// T4: y_k = b0 + b1 x_k + N(0, 0.2^2), prior b ~ N(0, 4 I). Closed form (9):
/// Sigma_n = (Lambda_0 + X^T X / s^2)^-1, mu_n = Sigma_n X^T y / s^2, Z = N(y; 0, s^2 I + 4 X X^T).
Verification regression();

/// Half-normal: l = -inf for theta < 0, log N(theta; 0, 1) otherwise, prior U[-10, 10].
Verification halfNormal();

/// T5: as T4 with unknown noise s ~ U[0.05, 1] sampled jointly; only log Z = -4.068997 and
/// E[s] = 0.221746 are known (9, 1-D quadrature), so mean/cov hold E[s] and a unit "sd" only.
Verification unknownNoise();

enum class Variant { Basis, Tmcmc };
const char* variantName(Variant v);

/// The paper's phase-1 settings (5): CoV 0.4, beta^2 = 0.06. BASIS: chains of length 1;
/// TMCMC: one chain of length n_k per selected sample; both with `burnIn` unrecorded steps.
TmcmcOptions settings(Variant v, int N, std::uint64_t seed, int burnIn = 0);

struct Errors {
    double logZ = 0;     // log Z-hat - log Z
    double mean = 0;     // max_i |mean_i - exact_i| / exact sd_i
    double cov = 0;      // max_ij |cov_ij - exact_ij| / sqrt(exact_ii exact_jj)
    double seconds = 0;  // wall time of runTmcmc
    int stages = 0;
};

/// Runs `o` on `v` and measures the result (kept in `*result` when given) against the exact
/// answers, with the population's mean and covariance (divisor N). Whether the run completed
/// (r.completed, r.exponent == 1) is the caller's check.
Errors runAndCompare(const Verification& v, const TmcmcOptions& o, TmcmcResult* result = nullptr);

/// Fraction of the samples with theta_0 < 0: the weight of T3's mode at (-3, -3), exactly 0.3.
double fractionNegative(const TmcmcResult& r);

}  // namespace trbc::tmcmc_verification
