#pragma once
// z-score standardisation of network inputs and outputs (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training).
//
// Data are column-major with one sample per column (rows = variables), as in mlp.hpp. For each
// variable j the mean m_j and the population standard deviation s_j (divisor n, not n - 1) are
// taken over all n samples given to fit() (SURROGATE: all rows of the data file, training and
// validation together):  x^_j = (x_j - m_j) / s_j,  x_j = s_j x^_j + m_j.
#include <Eigen/Core>
#include <string>
#include <vector>

namespace trbc {

struct Standardisation {
    Eigen::VectorXd mean;  ///< m, one entry per variable
    Eigen::VectorXd sd;    ///< s > 0, population standard deviation

    /// Mean and population SD of every row of `data` (variables x samples), two-pass.
    /// Throws InputError if there are no samples, a value is not finite, or a variable is constant
    /// (s = 0); the message names the variable (names[j] if given, else its index).
    static Standardisation fit(const Eigen::Ref<const Eigen::MatrixXd>& data,
                               const std::vector<std::string>& names = {});

    Eigen::Index size() const { return mean.size(); }
    /// (x - m) ./ s, column by column.
    Eigen::MatrixXd apply(const Eigen::Ref<const Eigen::MatrixXd>& x) const;
    /// s .* z + m, the inverse of apply().
    Eigen::MatrixXd invert(const Eigen::Ref<const Eigen::MatrixXd>& z) const;
    void applyInPlace(Eigen::Ref<Eigen::MatrixXd> x) const;
    void invertInPlace(Eigen::Ref<Eigen::MatrixXd> z) const;
};

}  // namespace trbc
