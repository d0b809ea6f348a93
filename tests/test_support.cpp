#include "test_support.hpp"

#include <Eigen/Geometry>

#include "mesh/icosphere.hpp"
#include "mesh/topology.hpp"

namespace trbc::test {

double meanEdgeLength(const Mesh& m) {
    const Topology t = buildTopology(m.F, m.numVertices());
    double s = 0.0;
    for (Eigen::Index e = 0; e < t.numEdges(); ++e) s += (m.X.col(t.edges(1, e)) - m.X.col(t.edges(0, e))).norm();
    return s / static_cast<double>(t.numEdges());
}

Mesh perturbedIcosphere(int level, double amplitude, unsigned seed) {
    Mesh m = icosphere(level);
    const double h = meanEdgeLength(m);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (Eigen::Index i = 0; i < m.numVertices(); ++i)
        for (int k = 0; k < 3; ++k) m.X(k, i) += amplitude * h * u(rng);
    return m;
}

Vertices finiteDifferenceGradient(const MembraneModel& model, const Vertices& X, double h) {
    Vertices g(3, X.cols());
    Vertices Y = X;
    for (Eigen::Index i = 0; i < X.cols(); ++i)
        for (int k = 0; k < 3; ++k) {
            const double x0 = Y(k, i);
            Y(k, i) = x0 + h;
            const double ep = model.evaluate(Y);
            Y(k, i) = x0 - h;
            const double em = model.evaluate(Y);
            Y(k, i) = x0;
            g(k, i) = (ep - em) / (2.0 * h);
        }
    return g;
}

double relativeMaxError(const Vertices& a, const Vertices& b) {
    return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

Eigen::Matrix3d randomRotation(unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n;
    Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
    return q.normalized().toRotationMatrix();
}

}  // namespace trbc::test
