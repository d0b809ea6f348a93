// Near and singular corrections of the boundary-integral operators: for each target, the accurate
// integral over its adjacent faces (Duffy coordinates) and its near faces (subdivided rule) minus
// what the far rule gives for them, stored as sparse 3x3 blocks (docs/flow_verification.md).
#include <Eigen/Core>
#include <vector>

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

/// Accumulator of the sparse correction blocks of one target. slot (one per vertex, -1 where the
/// row has no block; shared by the rows one thread builds, reset by finish) finds a column's block.
struct CorrectionRow {
    std::vector<int> col;
    std::vector<Mat3> s, d;
    void add(int j, const Mat3& bs, const Mat3& bd, std::vector<int>& slot) {
        int& k = slot[static_cast<std::size_t>(j)];
        if (k < 0) {
            k = static_cast<int>(col.size());
            col.push_back(j);
            s.push_back(bs);
            d.push_back(bd);
        } else {
            s[static_cast<std::size_t>(k)] += bs;
            d[static_cast<std::size_t>(k)] += bd;
        }
    }
    void finish(std::vector<int>& slot) const {
        for (const int j : col) slot[static_cast<std::size_t>(j)] = -1;
    }
};

/// The near rule followed by the far rule's points with negative weights (the corners first when
/// the far rule has corner points): one batch per near face yields its refined integral minus the
/// far rule's share of the far sum.
bie::TriangleRule nearMinusFarBatch(const bie::TriangleRule& nearRule, bool corners, double cornerWeight, const Eigen::MatrixX3d& farBary,
                                    const Eigen::VectorXd& farWeight) {
    const Index nn = nearRule.weight.size(), nFar = (corners ? 3 : 0) + farWeight.size();
    bie::TriangleRule batch{Eigen::MatrixX3d(nn + nFar, 3), Eigen::VectorXd(nn + nFar)};
    batch.bary.topRows(nn) = nearRule.bary;
    batch.weight.head(nn) = nearRule.weight;
    Index nb = nn;
    if (corners)
        for (int m = 0; m < 3; ++m, ++nb) {
            batch.bary.row(nb) = Eigen::RowVector3d::Unit(m);
            batch.weight[nb] = -cornerWeight;
        }
    for (Index q = 0; q < farWeight.size(); ++q, ++nb) {
        batch.bary.row(nb) = farBary.row(q);
        batch.weight[nb] = -farWeight[q];
    }
    return batch;
}

/// The rows as compressed sparse rows of 3x3 blocks (start, column, S and D blocks column-major),
/// the layout the operator products stream through.
void flattenCorrections(const std::vector<CorrectionRow>& rows, std::vector<int>& start, std::vector<int>& col,
                        std::vector<double>& S, std::vector<double>& D) {
    const std::size_t nv = rows.size();
    start.assign(nv + 1, 0);
    for (std::size_t i = 0; i < nv; ++i) start[i + 1] = start[i] + static_cast<int>(rows[i].col.size());
    const std::size_t nnz = static_cast<std::size_t>(start[nv]);
    col.resize(nnz);
    S.resize(9 * nnz);
    D.resize(9 * nnz);
    for (std::size_t i = 0; i < nv; ++i)
        for (std::size_t k = 0; k < rows[i].col.size(); ++k) {
            const std::size_t p = static_cast<std::size_t>(start[i]) + k;
            col[p] = rows[i].col[k];
            Eigen::Map<Mat3>{&S[9 * p]} = rows[i].s[k];
            Eigen::Map<Mat3>{&D[9 * p]} = rows[i].d[k];
        }
}

}  // namespace

void BoundaryIntegralOperators::markNearFaces(const Vec3& x0, std::vector<char>& near) const {
    const Index nf = static_cast<Index>(faceNearReach2_.size());
    near.resize(static_cast<std::size_t>(nf));
#pragma omp simd
    for (Index f = 0; f < nf; ++f) near[static_cast<std::size_t>(f)] = isNearFace(x0, f);
}

// One parallel pass over the target vertices, kept as one loop: the adjacent faces' Duffy rule and
// the near faces' batched kernels add into the same row through the thread's slot map.
void BoundaryIntegralOperators::buildCorrections() {
    const Index nf = mesh_.numFaces(), nv = mesh_.numVertices();
    const bie::TriangleRule nearRule =
        bie::subdividedRule(bie::TriangleRule{ruleBary_, ruleWeight_}, options_.nearSubdivisions);
    Eigen::VectorXd gt, gw;
    bie::gaussLegendre01(options_.singularPoints, gt, gw);

    // Faces around each vertex.
    std::vector<std::vector<int>> vertexFaces(nv);
    for (Index f = 0; f < nf; ++f)
        for (int k = 0; k < 3; ++k) vertexFaces[mesh_.F(k, f)].push_back(static_cast<int>(f));

    const bie::TriangleRule batch = nearMinusFarBatch(nearRule, cornerPoints_ > 0, cornerWeight_, farBary_, farWeight_);
    const Index nn = nearRule.weight.size(), nFar = batch.weight.size() - nn;
    const Eigen::MatrixX3d& batchBary = batch.bary;
    const Eigen::VectorXd& batchWeight = batch.weight;
    std::vector<CorrectionRow> rows(nv);
#pragma omp parallel
    {
        std::vector<int> slot(static_cast<std::size_t>(nv), -1);
        std::vector<char> near(static_cast<std::size_t>(nf));
        Eigen::Matrix<double, Eigen::Dynamic, 12> P(nn + nFar, 12);
        Eigen::Matrix<double, Eigen::Dynamic, 4> d(nn + nFar, 4);  // separation and 1 / r per point
#pragma omp for schedule(dynamic, 16)
        for (Index i = 0; i < nv; ++i) {
            CorrectionRow& row = rows[i];
            const Vec3 x0 = mesh_.X.col(i);
            const Mat3 zero = Mat3::Zero();
            // Far-rule single layer of an adjacent face, to be replaced: S blocks per corner. A point at
            // the target contributes nothing to the far sum, so nothing is subtracted for it.
            auto subtractPoint = [&](const Vec3& y, double w, const double (&bary)[3], Index f) {
                const Vec3 sep = y - x0;
                if (sep.squaredNorm() == 0.0) return;
                const Mat3 g = w * stokes::stokeslet(sep);
                for (int m = 0; m < 3; ++m)
                    if (bary[m] != 0.0) row.add(mesh_.F(m, f), -bary[m] * g, zero, slot);
            };
            auto subtractFarRule = [&](Index f) {
                const Eigen::Matrix3d c = faceCorners(mesh_, f);
                if (cornerPoints_ > 0)
                    for (int m = 0; m < 3; ++m) {
                        double bary[3] = {0.0, 0.0, 0.0};
                        bary[m] = 1.0;
                        subtractPoint(c.col(m), faceArea_[f] * cornerWeight_, bary, f);
                    }
                for (Index q = 0; q < farWeight_.size(); ++q) {
                    const double bary[3] = {farBary_(q, 0), farBary_(q, 1), farBary_(q, 2)};
                    subtractPoint(c * farBary_.row(q).transpose(), faceArea_[f] * farWeight_[q], bary, f);
                }
            };
            // Adjacent faces: single layer in Duffy coordinates about x_i (corner c0 = i, then c1, c2
            // along the face): int_face G phi dS = 2 A int_0^1 G(e1 + t (e2 - e1)) c(t) dt with
            // c = 1/2, (1 - t)/2, t/2 for phi_c0, phi_c1, phi_c2 (the s-integral done exactly).
            for (const int f : vertexFaces[i]) {
                int k0 = 0;
                while (mesh_.F(k0, f) != i) ++k0;
                const int c0 = static_cast<int>(i), c1 = mesh_.F((k0 + 1) % 3, f), c2 = mesh_.F((k0 + 2) % 3, f);
                const Vec3 e1 = mesh_.X.col(c1) - x0, e2 = mesh_.X.col(c2) - x0;
                Mat3 b0 = zero, b1 = zero, b2 = zero;
                for (Index q = 0; q < gt.size(); ++q) {
                    const double t = gt[q];
                    const Mat3 g = (2.0 * faceArea_[f] * gw[q]) * stokes::stokeslet(e1 + t * (e2 - e1));
                    b0 += 0.5 * g;
                    b1 += (0.5 * (1.0 - t)) * g;
                    b2 += (0.5 * t) * g;
                }
                row.add(c0, b0, zero, slot);
                row.add(c1, b1, zero, slot);
                row.add(c2, b2, zero, slot);
                // The far rule's double-layer terms of a flat face through x_i vanish ((y - x_i) . n = 0).
                subtractFarRule(f);
            }
            // Near faces: refined rule for both layers (double layer with the subtraction u - u_i),
            // minus the far rule. The kernels at the batch's points, vectorised, as the six components
            // of their symmetric blocks (w G = a I + b d d^T, w K = c d d^T); the corner blocks are then
            // one small product with the batch's barycentric weights, and the target's own column takes
            // minus the sum of the double-layer blocks. No point of a near face lies at the target.
            const double px = x0.x(), py = x0.y(), pz = x0.z();
            markNearFaces(x0, near);
            for (const int f : vertexFaces[i]) near[f] = 0;
            const Index nq = nn + nFar;
            for (Index f = 0; f < nf; ++f) {
                if (!near[f]) continue;
                const Eigen::Matrix3d c = faceCorners(mesh_, f);
                const Vec3 n = faceNormal_.col(f);
                const double area = faceArea_[f];
#pragma omp simd
                for (Index q = 0; q < nq; ++q) {
                    const double b0 = batchBary(q, 0), b1 = batchBary(q, 1), b2 = batchBary(q, 2);
                    const double dx = c(0, 0) * b0 + c(0, 1) * b1 + c(0, 2) * b2 - px;
                    const double dy = c(1, 0) * b0 + c(1, 1) * b1 + c(1, 2) * b2 - py;
                    const double dz = c(2, 0) * b0 + c(2, 1) * b1 + c(2, 2) * b2 - pz;
                    d(q, 0) = dx, d(q, 1) = dy, d(q, 2) = dz, d(q, 3) = dx * dx + dy * dy + dz * dz;
                }
                bie::inverseSqrt(&d(0, 3), nq);
#pragma omp simd
                for (Index q = 0; q < nq; ++q) {
                    const double dx = d(q, 0), dy = d(q, 1), dz = d(q, 2), rinv = d(q, 3);
                    const double w = area * batchWeight[q];
                    const double a = w * rinv, b = a * rinv * rinv;
                    const double k = stokes::doubleLayerCoefficient(dx, dy, dz, rinv, w * n.x(), w * n.y(), w * n.z());
                    P(q, 0) = a + b * dx * dx, P(q, 1) = b * dx * dy, P(q, 2) = b * dx * dz;
                    P(q, 3) = a + b * dy * dy, P(q, 4) = b * dy * dz, P(q, 5) = a + b * dz * dz;
                    P(q, 6) = k * dx * dx, P(q, 7) = k * dx * dy, P(q, 8) = k * dx * dz;
                    P(q, 9) = k * dy * dy, P(q, 10) = k * dy * dz, P(q, 11) = k * dz * dz;
                }
                // (lazy: a coefficient loop; the blocked product's packing costs more at 12 x 52 x 3)
                const Eigen::Matrix<double, 12, 3> corners = P.transpose().lazyProduct(batchBary);
                const Eigen::Matrix<double, 12, 1> total = P.colwise().sum().transpose();
                const auto block = [](const auto& v, int o) {
                    Mat3 m;
                    m << v[o], v[o + 1], v[o + 2], v[o + 1], v[o + 3], v[o + 4], v[o + 2], v[o + 4], v[o + 5];
                    return m;
                };
                for (int m = 0; m < 3; ++m) {
                    const Eigen::Matrix<double, 12, 1> cm = corners.col(m);
                    row.add(mesh_.F(m, f), block(cm, 0), block(cm, 6), slot);
                }
                row.add(static_cast<int>(i), zero, -block(total, 6), slot);
            }
            row.finish(slot);
        }
    }

    flattenCorrections(rows, corrStart_, corrCol_, corrS_, corrD_);
}

double BoundaryIntegralOperators::meanCorrectionsPerTarget() const {
    return static_cast<double>(corrCol_.size()) / static_cast<double>(numVertices());
}

}  // namespace trbc
