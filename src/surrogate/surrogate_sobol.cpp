#include "surrogate/surrogate_sobol.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace trbc {

std::vector<double> sobolForces(int n) {
    std::vector<double> forces;
    for (int j = 0; j < n; ++j) forces.push_back(200.0 * j / (n - 1));
    return forces;
}

const std::vector<std::string>& surrogateSobolInputs() {
    static const std::vector<std::string> inputs = {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um"};
    return inputs;
}

std::vector<std::string> surrogateSobolOutputs(const std::vector<double>& forces) {
    std::vector<std::string> outputs = {"D_um", "hmin_um", "hmax_um", "tc_s"};
    for (double f : forces) outputs.push_back(fmt::format("D0_um@{:.4g}", f)), outputs.push_back(fmt::format("D1_um@{:.4g}", f));
    return outputs;
}

Eigen::MatrixXd surrogateSobolModel(const Surrogate& s, const Eigen::MatrixXd& X, const std::vector<double>& forces) {
    const Eigen::Index n = X.rows();
    const Eigen::MatrixXd x = X.transpose();  // 5 x n
    const std::size_t nF = forces.size();
    Eigen::MatrixXd Y(n, kSobolScalarOutputs + 2 * Eigen::Index(nF));
    Eigen::MatrixXd eqIn(2, n);
    eqIn << x.row(0), x.row(2);
    Y.leftCols(3) = s.equilibriumOutputs(eqIn).transpose();
    Y.col(3) = s.relaxationTime(x);
    Eigen::MatrixXd st(5, n);
    st.topRows(4) = x.topRows(4);
    for (std::size_t j = 0; j < nF; ++j) {
        st.row(4).setConstant(forces[j]);
        const Eigen::MatrixXd d = s.stretchingOutputs(st);
        Y.col(4 + 2 * Eigen::Index(j)) = d.row(0).transpose();
        Y.col(5 + 2 * Eigen::Index(j)) = d.row(1).transpose();
    }
    return Y;
}

SobolResolution sobolResolution(const SobolResult& r, int scalarOutputs, double tolerance) {
    SobolResolution res;
    for (int out = 0; out < scalarOutputs; ++out)
        for (Eigen::Index in = 0; in < r.S1.cols(); ++in) {
            res.widestHalfWidth = std::max({res.widestHalfWidth, r.S1_ci(out, in), r.ST_ci(out, in)});
            for (const double S : {r.S1(out, in), r.ST(out, in)}) res.outside = std::max({res.outside, S - 1.0, -S});
        }
    res.resolved = std::isfinite(res.widestHalfWidth) && res.widestHalfWidth < tolerance && res.outside < tolerance;
    return res;
}

}  // namespace trbc
