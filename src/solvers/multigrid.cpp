#include "solvers/multigrid.hpp"

#include <Eigen/Cholesky>
#include <Eigen/SparseCore>
#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

#include "mesh/icosphere.hpp"

namespace trbc {
namespace {

using Triplet = Eigen::Triplet<double>;

// Graph Laplacian (degree - adjacency) of a closed manifold mesh: every edge lies in two faces,
// so each face contributes half of its three edges.
Eigen::SparseMatrix<double> graphLaplacian(const Faces& F, Eigen::Index nv) {
    std::vector<Triplet> t;
    t.reserve(std::size_t(F.cols()) * 12);
    for (Eigen::Index f = 0; f < F.cols(); ++f)
        for (int k = 0; k < 3; ++k) {
            const int a = F(k, f), b = F((k + 1) % 3, f);
            t.emplace_back(a, b, -0.5);
            t.emplace_back(b, a, -0.5);
            t.emplace_back(a, a, 0.5);
            t.emplace_back(b, b, 0.5);
        }
    Eigen::SparseMatrix<double> L(nv, nv);
    L.setFromTriplets(t.begin(), t.end());
    return L;
}

// Midpoint prolongation from level l-1 (nc vertices) to level l: coarse vertices keep their
// value, a midpoint vertex takes the mean of the edge's two ends (its only coarse neighbours).
Eigen::SparseMatrix<double> midpointProlongation(const Eigen::SparseMatrix<double>& fineLaplacian, Eigen::Index nc) {
    const Eigen::Index nf = fineLaplacian.rows();
    std::vector<Triplet> t;
    t.reserve(std::size_t(2 * nf));
    for (Eigen::Index i = 0; i < nc; ++i) t.emplace_back(i, i, 1.0);
    for (Eigen::Index i = nc; i < nf; ++i)  // column i of the symmetric L = row i
        for (Eigen::SparseMatrix<double>::InnerIterator it(fineLaplacian, i); it; ++it)
            if (it.row() < nc) t.emplace_back(i, it.row(), 0.5);
    Eigen::SparseMatrix<double> P(nf, nc);
    P.setFromTriplets(t.begin(), t.end());
    return P;
}

}  // namespace

StiffnessModel membraneStiffness(double Kalpha, double mu, double kb, double areaPerVertex, double meanEdgeLength,
                                 double curvatureRadius) {
    return {(Kalpha + mu) * areaPerVertex / (curvatureRadius * curvatureRadius), mu,
            kb / (meanEdgeLength * meanEdgeLength)};
}

bool admissible(const StiffnessModel& s) { return s.a0 > 0 && s.a1 >= 0 && s.a2 >= 0 && std::isfinite(s.a0 + s.a1 + s.a2); }

std::optional<IcosphereMultigrid> IcosphereMultigrid::build(const Faces& F, const StiffnessModel& s) {
    if (!admissible(s)) return std::nullopt;
    int level = -1;
    for (int l = 1; l <= 8; ++l)
        if (F.cols() == 20 * (Eigen::Index(1) << (2 * l))) level = l;
    if (level < 1) return std::nullopt;
    std::vector<Mesh> meshes;
    for (int l = 0; l <= level; ++l) meshes.push_back(icosphere(l));
    if (meshes.back().F != F) return std::nullopt;

    // Fine I, L, L^2, then Galerkin coarsening R X P with R = P^T, finest first.
    const std::size_t nl = std::size_t(level) + 1;
    std::vector<Eigen::SparseMatrix<double>> I(nl), L(nl), B(nl), P(nl);
    {
        const Eigen::Index nv = meshes.back().X.cols();
        L[nl - 1] = graphLaplacian(F, nv);
        I[nl - 1].resize(nv, nv);
        I[nl - 1].setIdentity();
        B[nl - 1] = L[nl - 1] * L[nl - 1];
    }
    for (std::size_t l = nl - 1; l >= 1; --l) {
        const Eigen::Index nc = meshes[l - 1].X.cols();
        P[l] = midpointProlongation(graphLaplacian(meshes[l].F, meshes[l].X.cols()), nc);
        const Eigen::SparseMatrix<double> R = P[l].transpose();
        I[l - 1] = R * (I[l] * P[l]);
        L[l - 1] = R * (L[l] * P[l]);
        B[l - 1] = R * (B[l] * P[l]);
    }
    IcosphereMultigrid mg;
    for (std::size_t l = 0; l < nl; ++l) {
        mg.identity_.emplace_back(I[l]);
        mg.laplacian_.emplace_back(L[l]);
        mg.bilaplacian_.emplace_back(B[l]);
        Eigen::Matrix2Xi par(2, l == 0 ? 0 : P[l].rows() - P[l].cols());
        if (l > 0) {
            std::vector<int> count(std::size_t(par.cols()), 0);
            for (Eigen::Index c = 0; c < P[l].outerSize(); ++c)
                for (Eigen::SparseMatrix<double>::InnerIterator it(P[l], c); it; ++it) {
                    const Eigen::Index m = it.row() - P[l].cols();
                    if (m >= 0) par(count[std::size_t(m)]++, m) = int(c);
                }
        }
        mg.parents_.push_back(par);
        const Eigen::Index nv = I[l].rows();
        mg.b_.push_back(Padded::Zero(4, nv));
        mg.x_.push_back(Padded::Zero(4, nv));
        mg.r_.push_back(Padded::Zero(4, nv));
    }
    mg.setStiffness(s);
    return mg;
}

void IcosphereMultigrid::setStiffness(const StiffnessModel& s) {
    if (!admissible(s))
        throw std::invalid_argument(fmt::format("multigrid stiffness needs a0 > 0, a1 >= 0, a2 >= 0 (got {}, {}, {})",
                                                s.a0, s.a1, s.a2));
    A_.resize(identity_.size());
    invDiag_.resize(identity_.size());
    for (std::size_t l = 0; l < identity_.size(); ++l) {
        A_[l] = s.a0 * identity_[l] + s.a1 * laplacian_[l] + s.a2 * bilaplacian_[l];
        A_[l].makeCompressed();
        invDiag_[l] = A_[l].diagonal().cwiseInverse();
    }
    coarseInverse_ = Eigen::MatrixXd(A_[0]).llt().solve(Eigen::MatrixXd::Identity(A_[0].rows(), A_[0].cols()));
}

void IcosphereMultigrid::vcycle(std::size_t l) const {
    Padded& x = x_[l];
    const Padded& b = b_[l];
    if (l == 0) {
        x.noalias() = b * coarseInverse_;  // A_0 symmetric: (A_0^-1 b^T)^T
        return;
    }
    const RowMatrix& A = A_[l];
    const double* dinv = invDiag_[l].data();
    const int* start = A.outerIndexPtr();
    const int* col = A.innerIndexPtr();
    const double* val = A.valuePtr();
    const Eigen::Index n = A.rows();
    // (A x)_i over the whole row (the diagonal included).
    // Four independent sums hide the latency of the multiply-adds.
    const auto rowProduct = [&](Eigen::Index i) {
        Eigen::Vector4d s0 = Eigen::Vector4d::Zero(), s1 = s0, s2 = s0, s3 = s0;
        int k = start[i];
        const int end = start[i + 1];
        for (; k + 3 < end; k += 4) {
            s0.noalias() += val[k] * x.col(col[k]);
            s1.noalias() += val[k + 1] * x.col(col[k + 1]);
            s2.noalias() += val[k + 2] * x.col(col[k + 2]);
            s3.noalias() += val[k + 3] * x.col(col[k + 3]);
        }
        for (; k < end; ++k) s0.noalias() += val[k] * x.col(col[k]);
        return Eigen::Vector4d((s0 + s1) + (s2 + s3));
    };
    // Gauss-Seidel in correction form: x_i += (b_i - (A x)_i) / a_ii.
    const auto relax = [&](Eigen::Index i) { x.col(i) += dinv[i] * (b.col(i) - rowProduct(i)); };
    x.setZero();
    for (Eigen::Index i = 0; i < n; ++i) relax(i);
    Padded& r = r_[l];
    for (Eigen::Index i = 0; i < n; ++i) r.col(i) = b.col(i) - rowProduct(i);
    // Restriction R = P^T: coarse vertices keep their residual, each midpoint gives half to each end.
    const Eigen::Matrix2Xi& par = parents_[l];
    const Eigen::Index nc = A_[l - 1].rows();
    Padded& bc = b_[l - 1];
    bc = r.leftCols(nc);
    for (Eigen::Index m = 0; m < par.cols(); ++m) {
        bc.col(par(0, m)) += 0.5 * r.col(nc + m);
        bc.col(par(1, m)) += 0.5 * r.col(nc + m);
    }
    vcycle(l - 1);
    const Padded& xc = x_[l - 1];
    x.leftCols(nc) += xc;
    for (Eigen::Index m = 0; m < par.cols(); ++m) x.col(nc + m) += 0.5 * (xc.col(par(0, m)) + xc.col(par(1, m)));
    for (Eigen::Index i = n - 1; i >= 0; --i) relax(i);
}

Vertices IcosphereMultigrid::apply(const Vertices& b) const {
    const std::size_t top = A_.size() - 1;
    b_[top].topRows<3>() = b;
    vcycle(top);
    return x_[top].topRows<3>();
}

void IcosphereMultigrid::apply(Eigen::VectorXd& v) const {
    const Eigen::Index n = numVertices();
    const std::size_t top = A_.size() - 1;
    b_[top].topRows<3>() = Eigen::Map<const Vertices>(v.data(), 3, n);
    vcycle(top);
    Eigen::Map<Vertices>(v.data(), 3, n) = x_[top].topRows<3>();
}

Vertices IcosphereMultigrid::multiply(const Vertices& x) const { return x * A_.back(); }

Preconditioner asPreconditioner(const std::optional<IcosphereMultigrid>& mg) {
    if (!mg) return {};
    return [&mg](Eigen::VectorXd& v) { mg->apply(v); };
}

}  // namespace trbc
