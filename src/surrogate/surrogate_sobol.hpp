#pragma once
// Sobol' indices of the surrogates (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices): the outputs
// D, hmin, hmax, tc and D0, D1 at each force of a grid over [0, 200] pN, with respect to
// (v, mu, FvK, b2, etam) uniform on the prior box.
#include <Eigen/Core>

#include <string>
#include <vector>

#include "surrogate/sobol.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc {

/// The scalar outputs D_um, hmin_um, hmax_um, tc_s come first.
inline constexpr int kSobolScalarOutputs = 4;

/// n forces F_j = 200 j / (n - 1) pN, j = 0..n-1 (n >= 2).
std::vector<double> sobolForces(int n);
/// v, mu_uN_per_m, FvK, b2, etam_Pa_s_um.
const std::vector<std::string>& surrogateSobolInputs();
/// D_um, hmin_um, hmax_um, tc_s, then D0_um@F_j and D1_um@F_j for every force.
std::vector<std::string> surrogateSobolOutputs(const std::vector<double>& forces);

/// The Sobol' model: rows of X are points (v, mu, FvK, b2, etam); columns of the result are
/// D, hmin, hmax, tc, then D0@F_j and D1@F_j for every force.
Eigen::MatrixXd surrogateSobolModel(const Surrogate& s, const Eigen::MatrixXd& X, const std::vector<double>& forces);

/// Whether the indices of the scalar outputs are resolved: every 95 % CI half-width below
/// `tolerance` and every index in [0, 1] up to it; otherwise they are sampling noise.
struct SobolResolution {
    bool resolved = false;
    double widestHalfWidth = 0.0;  ///< largest CI half-width of S1 and ST
    double outside = 0.0;          ///< farthest distance of an index outside [0, 1]
};
SobolResolution sobolResolution(const SobolResult& r, int scalarOutputs = kSobolScalarOutputs, double tolerance = 0.1);

}  // namespace trbc
