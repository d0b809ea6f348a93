#pragma once
// The shear-flow observations as data of the red-cell model: the likelihood of a cell
// (v, mu, kb, b2, r = etam / mu) given a donor's inclination curves, the tank-treading frequency or
// critical stresses, through the flow networks (surrogate/flow_surrogate.hpp), whose error enters
// the likelihood instead of being ignored.
//
// Error model of one data set, per curve j (the observations at one outer viscosity):
//   y_jk = f(theta, eta_j, rate_k) + delta_j + eps_jk,  eps ~ N(0, sigma^2),  delta_j ~ N(0, s^2),
// on the scale of the observable (degrees for the inclination; the logarithm for the TTF and the
// critical stress, where sigma and s are relative). sigma is the data set's own noise, sampled as
// the other error models are; s is the networks' cross-validated error, fixed. The networks' error
// is smooth in their inputs, so along one curve (only the rate changes) it is taken as one common
// offset: n points of a curve then weigh like n points with respect to the noise but like one with
// respect to the networks' error, and the curve cannot claim a precision the networks do not have.
// delta_j is integrated out: the residuals of a curve are N(0, sigma^2 I + s^2 1 1^T)
// (offsetNormalLogPdf).
//
// A curve of inclinations or TTFs is also an observation that the cell tank-treads at each of its
// rates. The classifier's error is as smooth along a curve as the regressors', so the curve counts
// once, at the point the classifier finds least likely: with that probability p and the
// classifier's error rate e (the share of cases it misclassifies away from the boundary),
// P(tank-treading observed | theta) = e + (1 - 2e) p. A cell the classifier calls tumbling is
// penalised by at most log e per curve, never excluded by a classifier that is wrong one time in 1/e.
//
// The networks answer inside their training box; a cell whose eta_m = mu r lies outside the
// box's eta_m range has likelihood 0 (etamRange), so that no posterior rests on extrapolation.
#include <Eigen/Core>
#include <array>
#include <cmath>
#include <limits>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace trbc {

struct FlowSurrogate;

enum class FlowObservable { Inclination, Ttf, CriticalStress };
/// inclination_deg, ttf_4pi_f_over_rate, critical_stress_Pa
const char* flowObservableName(FlowObservable o);

/// The observations of a data set at one outer viscosity.
struct FlowCurve {
    double etaOutMPaS = NAN;
    Eigen::VectorXd rate;   ///< shear rate (1/s) of each point; empty for critical stresses
    Eigen::VectorXd value;  ///< degrees, 4 pi f / rate, or Pa
};

/// One flow data set: a donor's inclination curves at several viscosities, a TTF set, or the
/// critical stresses of one source.
struct FlowDataSet {
    std::string name;
    FlowObservable observable = FlowObservable::Inclination;
    std::vector<FlowCurve> curves;
    double etaInMPaS = 10.0;  ///< the cytosol viscosity of the experiment
    /// s: the networks' error as the SD of a curve's common offset (degrees; relative for the TTF
    /// and the critical stress).
    double modelErrorSd = 0.0;
    /// e: the classifier's error rate in the regime term of inclination and TTF points, in [0, 1/2].
    double regimeErrorRate = 0.0;
    std::vector<std::filesystem::path> files;  ///< the files its points were read from (provenance)
    /// eta_m (Pa s um) where the networks answer: their campaign's range; outside it the likelihood is 0.
    std::array<double, 2> etamRange{0.0, std::numeric_limits<double>::infinity()};
};

/// The flow networks as batched callbacks; tests inject analytic models. x: 7 x n physical
/// inputs (v, mu_uN_per_m, FvK, b2, etam_Pa_s_um, eta_out_mPa_s, shear_rate_per_s), etaIn: the
/// cytosol viscosity of each column (mPa s).
struct FlowModel {
    /// 3 x n: the probability of tank-treading, the inclination (deg) and 4 pi f / rate.
    std::function<Eigen::MatrixXd(const Eigen::MatrixXd& x, const Eigen::VectorXd& etaIn)> tankTreading;
    /// n: the critical stress (Pa) at each column's cell and eta_out (its rate is not used), held
    /// at the networks' range's end where the probability does not cross 1/2 inside it.
    std::function<Eigen::VectorXd(const Eigen::MatrixXd& x, const Eigen::VectorXd& etaIn)> criticalStressPa;
};

/// The networks as a FlowModel (the object is shared, not copied).
FlowModel surrogateFlowModel(std::shared_ptr<const FlowSurrogate> surrogate);

/// log N(r; 0, sigma^2 I + s^2 1 1^T) of n residuals: independent noise of SD sigma plus a common
/// offset of SD s. With c = sigma^2 + n s^2 (Sherman-Morrison):
///   quadratic form (sum r^2 - s^2 (sum r)^2 / c) / sigma^2, log det (n - 1) log sigma^2 + log c.
/// -inf for sigma <= 0; s = 0 gives the sum of independent normal log densities.
double offsetNormalLogPdf(const Eigen::Ref<const Eigen::VectorXd>& r, double sigma, double offsetSd);

/// Sampled variables of a flow data set, in inference units: v, mu (uN/m), kb (1e-18 J), b2,
/// r = etam / mu (s) and the data set's noise sigma.
const std::vector<std::string>& flowParameterNames();

/// The batched log-likelihood: cells is 6 x n (flowParameterNames), one network call for all
/// cells and points. InputError for a data set without points, a value <= 0 on the log scale or a
/// cell matrix of other rows.
Eigen::VectorXd flowLogLikelihood(const FlowModel& model, const FlowDataSet& data, const Eigen::MatrixXd& cells);

}  // namespace trbc
