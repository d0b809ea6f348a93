#include "mesh/geometry.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

namespace trbc {

Eigen::VectorXd faceAreas(const Vertices& X, const Faces& F) {
    Eigen::VectorXd a(F.cols());
    for (Eigen::Index f = 0; f < F.cols(); ++f) {
        const auto xi = X.col(F(0, f));
        a[f] = 0.5 * (X.col(F(1, f)) - xi).cross(X.col(F(2, f)) - xi).norm();
    }
    return a;
}

double totalArea(const Vertices& X, const Faces& F) { return faceAreas(X, F).sum(); }

double enclosedVolume(const Vertices& X, const Faces& F) {
    // Translation invariant for a closed surface; evaluated about the centroid for round-off.
    const Eigen::Vector3d c = centroid(X);
    double v = 0.0;
    for (Eigen::Index f = 0; f < F.cols(); ++f)
        v += (X.col(F(0, f)) - c).dot((X.col(F(1, f)) - c).cross(X.col(F(2, f)) - c));
    return v / 6.0;
}

double reducedVolume(double area, double volume) {
    return 6.0 * std::sqrt(std::numbers::pi) * volume / std::pow(area, 1.5);
}

double reducedVolume(const Vertices& X, const Faces& F) {
    return reducedVolume(totalArea(X, F), enclosedVolume(X, F));
}

AreaVolume areaVolumeWithGradients(const Vertices& X, const Faces& F) {
    const Eigen::Vector3d o = centroid(X);
    AreaVolume r;
    r.areaGradient = Vertices::Zero(3, X.cols());
    r.volumeGradient = Vertices::Zero(3, X.cols());
    for (Eigen::Index f = 0; f < F.cols(); ++f) {
        const Eigen::Vector3d a = X.col(F(0, f)) - o, b = X.col(F(1, f)) - o, c = X.col(F(2, f)) - o;
        const Eigen::Vector3d m = (b - a).cross(c - a);
        const double twiceArea = m.norm();
        const Eigen::Vector3d n = m / twiceArea;
        r.area += 0.5 * twiceArea;
        r.volume += a.dot(b.cross(c)) / 6.0;
        r.areaGradient.col(F(0, f)) += 0.5 * n.cross(c - b);
        r.areaGradient.col(F(1, f)) += 0.5 * n.cross(a - c);
        r.areaGradient.col(F(2, f)) += 0.5 * n.cross(b - a);
        r.volumeGradient.col(F(0, f)) += b.cross(c) / 6.0;
        r.volumeGradient.col(F(1, f)) += c.cross(a) / 6.0;
        r.volumeGradient.col(F(2, f)) += a.cross(b) / 6.0;
    }
    return r;
}

Eigen::VectorXd vertexAreas(const Vertices& X, const Faces& F) {
    const Eigen::VectorXd af = faceAreas(X, F);
    Eigen::VectorXd av = Eigen::VectorXd::Zero(X.cols());
    for (Eigen::Index f = 0; f < F.cols(); ++f)
        for (int k = 0; k < 3; ++k) av[F(k, f)] += af[f] / 3.0;
    return av;
}

Eigen::Vector3d centroid(const Vertices& X) { return X.rowwise().mean(); }

Eigen::Matrix3d principalAxes(const Vertices& X) {
    const Eigen::Matrix3Xd Y = X.colwise() - centroid(X);
    const Eigen::Matrix3d cov = Y * Y.transpose() / static_cast<double>(X.cols());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);  // ascending eigenvalues
    Eigen::Matrix3d R;
    for (int k = 0; k < 3; ++k) R.row(k) = eig.eigenvectors().col(2 - k).transpose();
    if (R.determinant() < 0) R.row(2) *= -1.0;
    return R;
}

Vertices alignPrincipalAxes(const Vertices& X) {
    return principalAxes(X) * (X.colwise() - centroid(X));
}

Eigen::Vector3d extents(const Vertices& X) {
    return X.rowwise().maxCoeff() - X.rowwise().minCoeff();
}

Vertices scaleToArea(const Vertices& X, const Faces& F, double area) {
    const Eigen::Vector3d c = centroid(X);
    const double s = std::sqrt(area / totalArea(X, F));
    return ((X.colwise() - c) * s).colwise() + c;
}

}  // namespace trbc
