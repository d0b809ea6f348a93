#include "surrogate/scaling.hpp"

#include <cmath>
#include <stdexcept>

#include "core/error.hpp"

namespace trbc {

namespace {

std::string variableName(const std::vector<std::string>& names, Eigen::Index j) {
    return j < static_cast<Eigen::Index>(names.size()) ? "'" + names[j] + "'" : "#" + std::to_string(j);
}

void checkRows(const char* what, Eigen::Index rows, Eigen::Index want) {
    if (rows != want)
        throw std::invalid_argument(std::string("Standardisation::") + what + ": data have " +
                                    std::to_string(rows) + " variables, the scaling " + std::to_string(want));
}

}  // namespace

Standardisation Standardisation::fit(const Eigen::Ref<const Eigen::MatrixXd>& data,
                                     const std::vector<std::string>& names) {
    const Eigen::Index n = data.cols();
    if (n == 0) throw InputError("standardisation: no samples to compute the mean and SD from");
    Standardisation s;
    s.mean.resize(data.rows());
    s.sd.resize(data.rows());
    for (Eigen::Index j = 0; j < data.rows(); ++j) {
        const auto row = data.row(j);
        if (!row.allFinite())
            throw InputError("standardisation: variable " + variableName(names, j) + " has non-finite values");
        const double m = row.mean();                                             // m = sum x / n
        const double var = (row.array() - m).square().sum() / static_cast<double>(n);  // divisor n
        if (!(var > 0.0))
            throw InputError("standardisation: variable " + variableName(names, j) +
                             " is constant (standard deviation 0)");
        s.mean[j] = m;
        s.sd[j] = std::sqrt(var);
    }
    return s;
}

void Standardisation::applyInPlace(Eigen::Ref<Eigen::MatrixXd> x) const {
    checkRows("apply", x.rows(), size());
    x.colwise() -= mean;
    x.array().colwise() /= sd.array();
}

void Standardisation::invertInPlace(Eigen::Ref<Eigen::MatrixXd> z) const {
    checkRows("invert", z.rows(), size());
    z.array().colwise() *= sd.array();
    z.colwise() += mean;
}

Eigen::MatrixXd Standardisation::apply(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    Eigen::MatrixXd out = x;
    applyInPlace(out);
    return out;
}

Eigen::MatrixXd Standardisation::invert(const Eigen::Ref<const Eigen::MatrixXd>& z) const {
    Eigen::MatrixXd out = z;
    invertInPlace(out);
    return out;
}

}  // namespace trbc
