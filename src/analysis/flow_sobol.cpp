#include "analysis/flow_sobol.hpp"

#include <fmt/format.h>

#include <cmath>

namespace trbc {

std::vector<FlowSobolOutput> flowSobolOutputs(const ValidationConfig& cfg) {
    std::vector<FlowSobolOutput> out;
    for (const char* kind : {"angle", "ttf"})
        for (const ShearSweep& s : cfg.sweeps)
            if (s.kind == kind) {
                const double rate = std::sqrt(s.rateMin * s.rateMax);
                out.push_back({fmt::format("{}@eta{:g}_rate{:.3g}", s.kind == "angle" ? "inclination_deg" : "ttf_4pi_f_over_rate",
                                           s.etaOut, rate),
                               s.kind, s.etaOut, rate});
            }
    for (double eta : thresholdViscosities(cfg)) out.push_back({fmt::format("log10_critical_stress_Pa@eta{:g}", eta), "threshold", eta, 1.0});
    return out;
}

Eigen::MatrixXd flowSobolModel(const FlowSurrogate& model, const std::vector<FlowSobolOutput>& outputs, double etaIn,
                               const Eigen::MatrixXd& X) {
    const Eigen::Index n = X.rows();
    Eigen::MatrixXd Y(n, Eigen::Index(outputs.size()));
    Eigen::MatrixXd x(7, n);
    x.topRows(5) = X.transpose();
    const Eigen::VectorXd eta = Eigen::VectorXd::Constant(n, etaIn);
    for (std::size_t k = 0; k < outputs.size(); ++k) {
        const FlowSobolOutput& o = outputs[k];
        x.row(5).setConstant(o.etaOut);
        x.row(6).setConstant(o.rate);
        if (o.kind == "threshold") {
            Y.col(Eigen::Index(k)) = model.criticalStressPa(x, eta, 0.5, true).array().log10().matrix();
        } else {
            const FlowPrediction p = model.predict(x, eta);
            Y.col(Eigen::Index(k)) = o.kind == "angle" ? p.inclinationDeg : p.ttf;
        }
    }
    return Y;
}

}  // namespace trbc
