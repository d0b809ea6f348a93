// Dense forms of the boundary-integral operators: the on-surface single and double layers as
// symmetric 3x3 block matrices, and the single layer at points off the surface (with adaptive
// subdivision of the faces near a point).
#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <numbers>
#include <vector>

#include "core/error.hpp"
#include "flow/boundary_integral.hpp"
#include "flow/far_sum.hpp"
#include "flow/quadrature_rules.hpp"
#include "flow/stokes_kernels.hpp"

namespace trbc {
namespace {

using Eigen::Index;
using stokes::Mat3;
using stokes::Vec3;
using bie::faceCorners;
using bie::inverseSqrt;

constexpr double kPi = std::numbers::pi;

}  // namespace

// Dense assembly, one target (block row) at a time: the kernel at every quadrature point,
// vectorised, as the six components of its symmetric 3x3 block (w G = a I + b d d^T for the single
// layer, w K = c d d^T for the double layer); then the rule's barycentric weights scatter them into
// one symmetric block per vertex of a row buffer, which is copied into the matrix once. Far fewer
// strided writes into the 3 Nv x 3 Nv matrix than a block update per quadrature point.
namespace {

/// Kernel components at the quadrature points, for one target.
struct KernelRow {
    std::vector<double> dx, dy, dz, a, b;  ///< separation; w G = a I + b d d^T (b alone: w K = b d d^T)
    explicit KernelRow(std::size_t n) : dx(n), dy(n), dz(n), a(n), b(n) {}
};

/// Row buffer of symmetric blocks (nv vertices): sum over the points of phi_m(q) (a I + b d d^T),
/// components (xx, xy, xz, yy, yz, zz) per vertex. The first `corners` points sit on the vertices (phi = 1
/// there); the rest are `bary.rows()` points per face, face-major. Faces with skip[f] set (if
/// given; only without corner points) are left out.
void scatterSymmetricBlocks(const KernelRow& k, Index corners, const Eigen::MatrixX3d& bary, const Faces& F,
                            Index nv, double* buf, const std::vector<char>* skip = nullptr) {
    std::fill(buf, buf + 6 * nv, 0.0);
    const auto block = [&](std::size_t i, double (&c)[6]) {
        const double dx = k.dx[i], dy = k.dy[i], dz = k.dz[i], a = k.a[i], b = k.b[i];
        const double bx = b * dx, by = b * dy, bz = b * dz;
        c[0] = a + bx * dx, c[1] = bx * dy, c[2] = bx * dz, c[3] = a + by * dy, c[4] = by * dz, c[5] = a + bz * dz;
    };
    double c[6];
    for (Index j = 0; j < corners; ++j) {
        block(static_cast<std::size_t>(j), c);
        for (int e = 0; e < 6; ++e) buf[6 * static_cast<std::size_t>(j) + e] += c[e];
    }
    const Index nf = F.cols(), nq = bary.rows();
    for (Index f = 0; f < nf; ++f) {
        if (skip && (*skip)[static_cast<std::size_t>(f)]) continue;
        for (Index q = 0; q < nq; ++q) {
            block(static_cast<std::size_t>(corners + f * nq + q), c);
            for (int m = 0; m < 3; ++m) {
                const double w = bary(q, m);
                double* o = &buf[6 * static_cast<std::size_t>(F(m, f))];
                for (int e = 0; e < 6; ++e) o[e] += w * c[e];
            }
        }
    }
}

/// w G(y_q - x0) = a I + b d d^T at every point (a = w / r, b = w / r^3; 0 at a point at x0).
void singleLayerKernelRow(double x0, double y0, double z0, const std::vector<double>& qx, const std::vector<double>& qy,
                          const std::vector<double>& qz, const std::vector<double>& qw, KernelRow& k) {
    const std::size_t n = qx.size();
#pragma omp simd
    for (std::size_t q = 0; q < n; ++q) {
        const double dx = qx[q] - x0, dy = qy[q] - y0, dz = qz[q] - z0;
        k.dx[q] = dx, k.dy[q] = dy, k.dz[q] = dz;
        k.b[q] = dx * dx + dy * dy + dz * dz;
    }
    inverseSqrt(k.b.data(), static_cast<Index>(n));
#pragma omp simd
    for (std::size_t q = 0; q < n; ++q) {
        const double rinv = k.b[q];
        k.a[q] = qw[q] * rinv;
        k.b[q] = k.a[q] * rinv * rinv;
    }
}

/// buf (symmetric blocks per vertex) += the corner blocks of face f.
void addFaceBlocks(const Mat3 (&blocks)[3], const Faces& F, Index f, std::vector<double>& buf) {
    for (int m = 0; m < 3; ++m) {
        double* o = &buf[6 * static_cast<std::size_t>(F(m, f))];
        const Mat3& b = blocks[m];
        o[0] += b(0, 0), o[1] += b(0, 1), o[2] += b(0, 2), o[3] += b(1, 1), o[4] += b(1, 2), o[5] += b(2, 2);
    }
}

/// A.block<3, 3>(3 i, 3 j) = the symmetric block j of the buffer, for every vertex j.
void storeBlockRow(const std::vector<double>& buf, Index i, Eigen::MatrixXd& A) {
    const Index nv = A.cols() / 3;
    for (Index j = 0; j < nv; ++j) {
        const double* o = &buf[6 * static_cast<std::size_t>(j)];
        double* c0 = &A(3 * i, 3 * j);
        double* c1 = &A(3 * i, 3 * j + 1);
        double* c2 = &A(3 * i, 3 * j + 2);
        c0[0] = o[0], c0[1] = o[1], c0[2] = o[2];
        c1[0] = o[1], c1[1] = o[3], c1[2] = o[4];
        c2[0] = o[2], c2[1] = o[4], c2[2] = o[5];
    }
}

}  // namespace

SymmetricBlockMatrix::SymmetricBlockMatrix(Index blocks)
    : n_(blocks), a_(static_cast<std::size_t>(6 * blocks * blocks), 0.0) {}

Eigen::Matrix3d SymmetricBlockMatrix::block(Index i, Index j) const {
    const double* o = row(i) + 6 * j;
    Mat3 b;
    b << o[0], o[1], o[2], o[1], o[3], o[4], o[2], o[4], o[5];
    return b;
}

void SymmetricBlockMatrix::addToBlock(Index i, Index j, const Mat3& b) {
    double* o = row(i) + 6 * j;
    o[0] += b(0, 0), o[1] += b(0, 1), o[2] += b(0, 2), o[3] += b(1, 1), o[4] += b(1, 2), o[5] += b(2, 2);
}

void SymmetricBlockMatrix::multiply(const double* x, double* y) const {
#pragma omp parallel for schedule(static)
    for (Index i = 0; i < n_; ++i) {
        const double* o = row(i);
        double y0 = 0.0, y1 = 0.0, y2 = 0.0;
#pragma omp simd reduction(+ : y0, y1, y2)
        for (Index j = 0; j < n_; ++j) {
            const double* b = o + 6 * j;
            const double x0 = x[3 * j], x1 = x[3 * j + 1], x2 = x[3 * j + 2];
            y0 += b[0] * x0 + b[1] * x1 + b[2] * x2;
            y1 += b[1] * x0 + b[3] * x1 + b[4] * x2;
            y2 += b[2] * x0 + b[4] * x1 + b[5] * x2;
        }
        y[3 * i] = y0, y[3 * i + 1] = y1, y[3 * i + 2] = y2;
    }
}

Eigen::MatrixXd SymmetricBlockMatrix::toDense() const {
    Eigen::MatrixXd A(3 * n_, 3 * n_);
    for (Index j = 0; j < n_; ++j)
        for (Index i = 0; i < n_; ++i) A.block<3, 3>(3 * i, 3 * j) = block(i, j);
    return A;
}

SymmetricBlockMatrix BoundaryIntegralOperators::assembleSingleLayerBlocks() const {
    const Index nv = numVertices(), n = static_cast<Index>(qx_.size());
    SymmetricBlockMatrix A(nv);
#pragma omp parallel
    {
        KernelRow k(static_cast<std::size_t>(n));
#pragma omp for schedule(static)
        for (Index i = 0; i < nv; ++i) {
            singleLayerKernelRow(mesh_.X(0, i), mesh_.X(1, i), mesh_.X(2, i), qx_, qy_, qz_, qw_, k);
            scatterSymmetricBlocks(k, cornerPoints_, farBary_, mesh_.F, nv, A.row(i));
            for (int p = corrStart_[i]; p < corrStart_[i + 1]; ++p)
                A.addToBlock(i, corrCol_[p], Eigen::Map<const Mat3>(&corrS_[9 * static_cast<std::size_t>(p)]));
        }
    }
    return A;
}

SymmetricBlockMatrix BoundaryIntegralOperators::assembleDoubleLayerBlocks() const {
    const Index nv = numVertices(), n = static_cast<Index>(qx_.size());
    SymmetricBlockMatrix A(nv);
#pragma omp parallel
    {
        KernelRow k(static_cast<std::size_t>(n));
        std::fill(k.a.begin(), k.a.end(), 0.0);  // w K(d, n) = c d d^T: no identity part
#pragma omp for schedule(static)
        for (Index i = 0; i < nv; ++i) {
            const double x0 = mesh_.X(0, i), y0 = mesh_.X(1, i), z0 = mesh_.X(2, i);
            double s[6] = {0, 0, 0, 0, 0, 0};  // sum of w K over all points (singularity subtraction)
#pragma omp simd
            for (Index q = 0; q < n; ++q) {
                const double dx = qx_[q] - x0, dy = qy_[q] - y0, dz = qz_[q] - z0;
                k.dx[q] = dx, k.dy[q] = dy, k.dz[q] = dz;
                k.b[q] = dx * dx + dy * dy + dz * dz;
            }
            inverseSqrt(k.b.data(), n);
#pragma omp simd reduction(+ : s[:6])
            for (Index q = 0; q < n; ++q) {
                const double dx = k.dx[q], dy = k.dy[q], dz = k.dz[q];
                const double c = stokes::doubleLayerCoefficient(dx, dy, dz, k.b[q], qnx_[q], qny_[q], qnz_[q]);
                k.b[q] = c;
                s[0] += c * dx * dx, s[1] += c * dx * dy, s[2] += c * dx * dz;
                s[3] += c * dy * dy, s[4] += c * dy * dz, s[5] += c * dz * dz;
            }
            scatterSymmetricBlocks(k, cornerPoints_, farBary_, mesh_.F, nv, A.row(i));
            Mat3 ksum;
            ksum << s[0], s[1], s[2], s[1], s[3], s[4], s[2], s[4], s[5];
            A.addToBlock(i, i, -(ksum + 4.0 * kPi * Mat3::Identity()));
            for (int p = corrStart_[i]; p < corrStart_[i + 1]; ++p)
                A.addToBlock(i, corrCol_[p], Eigen::Map<const Mat3>(&corrD_[9 * static_cast<std::size_t>(p)]));
        }
    }
    return A;
}

void BoundaryIntegralOperators::offSurfaceBlocks(const Vec3& x0, Index f, int maxDepth, Mat3 (&blocks)[3]) const {
    for (auto& b : blocks) b.setZero();
    const Eigen::Matrix3d c = faceCorners(mesh_, f);
    // Far face: the face's own rule (the precomputed quadrature points).
    if (!isNearFace(x0, f)) {
        const Index nq = ruleWeight_.size();
        for (Index q = 0; q < nq; ++q) {
            const Index k = f * nq + q;
            const Mat3 g = fw_[k] * stokes::stokeslet(Vec3(fx_[k], fy_[k], fz_[k]) - x0);
            for (int m = 0; m < 3; ++m) blocks[m] += ruleBary_(q, m) * g;
        }
        return;
    }
    // Near face: recursive midpoint subdivision; a piece is integrated with the rule once its
    // centroid is nearFactor x its longest edge away (or at the depth limit). Pieces are
    // carried as barycentric corners (rows) with respect to the face.
    const double area = faceArea_[f];
    const auto recurse = [&](const auto& self, const Eigen::Matrix3d& b, double subArea, int depth) -> void {
        const Eigen::Matrix3d p = c * b.transpose();  // columns: corners of the piece in space
        const Vec3 centre = p.rowwise().mean();
        const double edge = std::max({(p.col(1) - p.col(0)).norm(), (p.col(2) - p.col(1)).norm(),
                                      (p.col(0) - p.col(2)).norm()});
        if (depth >= maxDepth || (centre - x0).norm() >= options_.nearFactor * edge) {
            for (Index q = 0; q < ruleWeight_.size(); ++q) {
                const Eigen::RowVector3d bq = ruleBary_.row(q) * b;  // barycentric w.r.t. the face
                const Mat3 g = (subArea * ruleWeight_[q]) * stokes::stokeslet(c * bq.transpose() - x0);
                for (int m = 0; m < 3; ++m) blocks[m] += bq[m] * g;
            }
            return;
        }
        const Eigen::RowVector3d a0 = b.row(0), a1 = b.row(1), a2 = b.row(2);
        const Eigen::RowVector3d m01 = 0.5 * (a0 + a1), m12 = 0.5 * (a1 + a2), m20 = 0.5 * (a2 + a0);
        for (const auto& [u, v, w] : {std::array{a0, m01, m20}, std::array{m01, a1, m12},
                                      std::array{m20, m12, a2}, std::array{m01, m12, m20}}) {
            Eigen::Matrix3d s;
            s << u, v, w;
            self(self, s, 0.25 * subArea, depth + 1);
        }
    };
    recurse(recurse, Eigen::Matrix3d::Identity(), area, 0);
}

Eigen::MatrixXd BoundaryIntegralOperators::assembleSingleLayerAt(const Eigen::Matrix3Xd& targets, int maxDepth) const {
    Eigen::MatrixXd A;
    assembleSingleLayerAt(targets, A, maxDepth);
    return A;
}

void BoundaryIntegralOperators::assembleSingleLayerAt(const Eigen::Matrix3Xd& targets, Eigen::MatrixXd& A,
                                                      int maxDepth) const {
    // The far faces with the symmetric face rule (vectorised over all its points);
    // the near faces of a target by offSurfaceBlocks' subdivision. Every entry is written.
    const Index nt = targets.cols(), nv = numVertices(), nf = mesh_.numFaces();
    A.resize(3 * nt, 3 * nv);
#pragma omp parallel
    {
        KernelRow k(fx_.size());
        std::vector<double> buf(6 * static_cast<std::size_t>(nv));
        std::vector<char> near(static_cast<std::size_t>(nf));
        Mat3 blocks[3];
#pragma omp for schedule(dynamic, 8)
        for (Index t = 0; t < nt; ++t) {
            const Vec3 x0 = targets.col(t);
            singleLayerKernelRow(x0.x(), x0.y(), x0.z(), fx_, fy_, fz_, fw_, k);
            markNearFaces(x0, near);
            scatterSymmetricBlocks(k, 0, ruleBary_, mesh_.F, nv, buf.data(), &near);
            for (Index f = 0; f < nf; ++f)
                if (near[static_cast<std::size_t>(f)]) {
                    offSurfaceBlocks(x0, f, maxDepth, blocks);
                    addFaceBlocks(blocks, mesh_.F, f, buf);
                }
            storeBlockRow(buf, t, A);
        }
    }
}

Eigen::Matrix3Xd BoundaryIntegralOperators::singleLayerAt(const Eigen::Matrix3Xd& targets, const Eigen::Matrix3Xd& f,
                                                          int maxDepth) const {
    if (f.cols() != numVertices())
        throw InputError(fmt::format("single-layer density: {} columns given, the mesh has {} vertices", f.cols(),
                                     numVertices()));
    const Index nt = targets.cols(), nf = mesh_.numFaces();
    Eigen::Matrix3Xd out(3, nt);
#pragma omp parallel for schedule(dynamic, 8)
    for (Index t = 0; t < nt; ++t) {
        const Vec3 x0 = targets.col(t);
        Mat3 blocks[3];
        Vec3 u = Vec3::Zero();
        for (Index g = 0; g < nf; ++g) {
            offSurfaceBlocks(x0, g, maxDepth, blocks);
            for (int m = 0; m < 3; ++m) u += blocks[m] * f.col(mesh_.F(m, g));
        }
        out.col(t) = u;
    }
    return out;
}

}  // namespace trbc
