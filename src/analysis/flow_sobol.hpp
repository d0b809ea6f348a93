#pragma once
// Which cell parameter drives which flow observable (docs/FLOW_NETWORKS.md, Sobol' indices): the
// Sobol' indices (surrogate/sobol.hpp) of the flow networks' outputs with respect to
// (v, mu, FvK, b2, eta_m), uniform on the prior box, at every validation viscosity of a config:
//  * per angle sweep: the tank-treading inclination at the sweep's central rate sqrt(rate_min rate_max);
//  * per TTF sweep: 4 pi f / rate at its central rate;
//  * per threshold viscosity: log10 of the critical stress, held at the ends of the campaign's
//    stress range where the probability does not cross 1/2 inside it.
// The angle and TTF are those of the tank-treading state, a smooth function of the parameters also
// where a cell tumbles; the regime's dependence is the critical stress's.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "analysis/validation.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {

struct FlowSobolOutput {
    std::string name;  ///< e.g. inclination_deg@eta23.9_rate55.4
    std::string kind;  ///< angle | ttf | threshold
    double etaOut = 0.0, rate = 0.0;
};

/// The outputs of a config, in its order: angle sweeps, TTF sweeps, threshold viscosities.
std::vector<FlowSobolOutput> flowSobolOutputs(const ValidationConfig& cfg);

/// The model: rows of X are cells (v, mu, FvK, b2, eta_m), the columns of the result the outputs.
Eigen::MatrixXd flowSobolModel(const FlowSurrogate& model, const std::vector<FlowSobolOutput>& outputs, double etaIn,
                               const Eigen::MatrixXd& X);

}  // namespace trbc
