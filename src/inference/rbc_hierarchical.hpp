#pragma once
// The red-cell hierarchical model as one joint distribution (hierarchical_mcmc.hpp) and the
// distribution of a new cell, theta_new, estimated from hyper-parameter draws by
// Rao-Blackwellisation.
//
// Groups (one per data set):
//   equilibrium: (v, mu, kb, sigma), the likelihood at FvK = mu R_A^2 / kb; support v in the
//     phase-1 box, FvK in the support of its phase-1 prior. Sampling mu and kb themselves, where the
//     three-phase route integrates them into q(FvK | psi), is exact and independent of q;
//   stretching: (v, mu, kb, b2, sigma0, sigma1) on the phase-1 box;
//   relaxation: (r, sigma_tc, tc, z0, zinf, sigma_z), r on the support of its phase-1 prior.
// The error-model variables keep their phase-1 priors; the pooled variables have the population
// density instead of the phase-1 prior (the joint density that phase 2 marginalises).
//
// theta_new: the mixture (1/M) sum_m p(theta | psi_m) restricted to the box B of
// newCellBoxPrior, sum_m w_m p(theta | psi_m, B) / sum_m w_m with w_m = P(theta in B | psi_m). The
// components are independent given psi, so for each coordinate
//   E[theta_j] = sum_m w_m E[theta_j | psi_m, B_j] / sum_m w_m, and the same for E[theta_j^2] and
//   the CDF F(x) = sum_m w_m F_m(x) / sum_m w_m (quantiles by bisection);
// all three are exact given the draws (truncated-normal moments and CDFs), so the only Monte
// Carlo error left is that of the psi draws, stated by the delta method with the multi-chain
// ESS (mcmc_diagnostics.hpp). eta_m = mu r: E[mu r | psi] = E[mu | psi] E[r | psi] (independent),
// and its CDF sum_m w_m int F_r(x / mu) dP(mu | psi_m) by 24-point Gauss-Legendre in the
// probability of mu.
#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "inference/hierarchical_mcmc.hpp"
#include "inference/mcmc_diagnostics.hpp"
#include "inference/rbc_problem.hpp"

namespace trbc {

/// Choices of the population model that a sensitivity study varies; the defaults are the model
/// of the three-phase route.
struct PopulationVariant {
    double sdUpperScale = 1.0;  ///< multiplies the upper bound of every population-SD hyper-prior
    bool truncate = true;       ///< v TN on [0, 1] and kb TN on [kappa_lo, kappa_hi]; false: untruncated normals
    /// theta_new restricted to the box of newCellBoxPrior (v >= 0.65, mu <= 20, b2 <= 10, r <= 2);
    /// false: to v in [0, 1], kb in [kappa_lo, kappa_hi] and mu, b2, r >= 0 only.
    bool newCellBox = true;
};

/// The population: v TN on [0, 1], mu, b2, r normal, kb TN on [kappa_lo, kappa_hi]; the
/// hyper-prior bounds of hyperPrior() (changed as `variant` says).
std::vector<PopulationComponent> rbcPopulationComponents(const PopulationVariant& variant = {});

/// The joint model of the data sets. `phase1Samples[i]` (phase-1 variables x N) are the starting
/// points and first proposal covariances of group i; the equilibrium group splits each (v, FvK,
/// sigma) into (v, mu, kb, sigma) with kb drawn uniformly (seeded) from [kappa_lo, kappa_hi].
HierarchicalModel rbcHierarchicalModel(const RbcModel& model, const std::vector<RbcDataSet>& data,
                                       const std::vector<Eigen::MatrixXd>& phase1Samples, std::uint64_t seed,
                                       const PopulationVariant& variant = {});

/// A group's draws in the phase-1 variables of its data set (equilibrium: (v, mu, kb, sigma) ->
/// (v, FvK, sigma); the others unchanged).
Eigen::MatrixXd rbcGroupToPhase1(RbcExperiment e, const Eigen::MatrixXd& groupDraws);

/// One statistic of theta_new with its Monte Carlo standard error.
struct NewCellStatistic {
    std::string name;  ///< output name (v, mu_uN_per_m, kb_J, b2, etam_over_mu_s, etam_Pa_s_um)
    McEstimate mean, sd, median, q05, q95;
    /// Diagnostics of the chains of E[theta | psi_t, B] (NaN with one chain).
    double rhat = std::numeric_limits<double>::quiet_NaN(), essBulk = rhat, essTail = rhat;
};

/// theta_new statistics (physical units, kb in J) from hyper-parameter draws: psiChains[c] is
/// 10 x draws (rows as hyperParameterNames, inference units).
std::vector<NewCellStatistic> newCellStatistics(const std::vector<Eigen::MatrixXd>& psiChains, const PopulationVariant& variant = {});

}  // namespace trbc
