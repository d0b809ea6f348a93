#pragma once
// Quadrature rules of the boundary-integral operators (flow/boundary_integral.hpp): the symmetric
// triangle rules, their midpoint-subdivided versions for near faces, Gauss-Legendre on [0, 1] for
// the singular (Duffy) integrals, and the corners of a face, the points a rule maps from. Shared
// by the operators' files only.
#include <Eigen/Core>

#include "mesh/mesh.hpp"

namespace trbc::bie {

/// A rule on the reference triangle: barycentric coordinates (points x 3), weights summing to 1.
struct TriangleRule {
    Eigen::MatrixX3d bary;
    Eigen::VectorXd weight;
};

/// Symmetric rules (Strang & Fix 1973; Dunavant 1985): degree 1, 2, 4, 5 for 1, 3, 6, 7 points.
TriangleRule symmetricRule(int points);

/// The rule applied on the 4^levels sub-triangles of midpoint subdivision.
TriangleRule subdividedRule(const TriangleRule& base, int levels);

/// Gauss-Legendre nodes and weights on [0, 1] (Newton on P_n).
void gaussLegendre01(int n, Eigen::VectorXd& x, Eigen::VectorXd& w);

/// The corners of face f as the columns of a 3 x 3 matrix.
inline Eigen::Matrix3d faceCorners(const Mesh& m, Eigen::Index f) {
    Eigen::Matrix3d c;
    for (int k = 0; k < 3; ++k) c.col(k) = m.X.col(m.F(k, f));
    return c;
}

}  // namespace trbc::bie
