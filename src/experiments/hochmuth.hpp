#pragma once
// Fit of the Hochmuth et al. (1979) recovery law to a deformation-index time series (docs/FORWARD_MODEL.md, relaxation).
#include <string>
#include <vector>

namespace trbc {

struct HochmuthFit {
    double tc = 0, zInf = 0, z0 = 0;  ///< tc in the units of t
    double t0 = 0;                    ///< the time of the first sample, where z = z0 (elapsed time t - t0)
    bool converged = false;
    int iterations = 0;
    double rms = 0;                   ///< sqrt(mean_k (z(t_k) - z_k)^2) at the returned parameters
    std::string message;
};

/// z(t) = zInf (Lambda + e^{-t/tc}) / (Lambda - e^{-t/tc}), Lambda = (z0 + zInf)/(z0 - zInf), z0 fixed
/// to z[0] at t[0] (t - t[0] is the elapsed time). Unknowns tc, zInf by non-linear least squares on
/// z(t_k) (Levenberg-Marquardt), initial guess tc = tcGuess, zInf = zInfGuess.
/// Throws InputError on bad data (sizes differ, < 3 points, non-finite values, t not strictly
/// increasing, z[0] == zInfGuess, tcGuess <= 0); a fit that does not converge returns
/// converged = false with the reason in `message` and the last finite parameters.
HochmuthFit fitHochmuth(const std::vector<double>& t, const std::vector<double>& z, double tcGuess = 0.015,
                        double zInfGuess = 1.0);

/// The law itself at elapsed time t, for plotting and tests.
double hochmuthLaw(double t, double z0, double zInf, double tc);

}  // namespace trbc
