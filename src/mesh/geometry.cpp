#include "mesh/geometry.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <vector>

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

double volumeOfReducedVolume(double reducedVolume, double area) {
    return reducedVolume * std::pow(area, 1.5) / (6.0 * std::sqrt(std::numbers::pi));
}

namespace {
template <bool Gradients>
AreaVolume blockedAreaVolume(const Vertices& X, const Faces& F) {
    // Faces are processed in blocks of B: gather the corners a, b, c (relative to the vertex
    // centroid o) into structure-of-arrays buffers, evaluate the per-face terms in vectorisable
    // loops, then scatter them into a per-vertex accumulator [dA/dx (3), 6 dV/dx (3)].
    constexpr int B = 64;
    const Eigen::Index nv = X.cols(), nf = F.cols();
    const Eigen::Vector3d o = centroid(X);
    const double ox = o.x(), oy = o.y(), oz = o.z();
    const double* __restrict x = X.data();
    const int* __restrict fc = F.data();
    thread_local std::vector<double> accumulator;
    if constexpr (Gradients) accumulator.assign(6 * nv, 0.0);
    double* __restrict acc = accumulator.data();
    alignas(64) double in[9][B];     // a, b, c by component
    alignas(64) double len[B];       // |m|, m = (b - a) x (c - a)
    alignas(64) double out[19][B];   // dA/da, dA/db, dA/dc, 6 dV/da, 6 dV/db, 6 dV/dc, a.(b x c)
    double twiceArea = 0.0, sixVolume = 0.0;
    for (Eigen::Index t0 = 0; t0 < nf; t0 += B) {
        const int nb = static_cast<int>(std::min<Eigen::Index>(B, nf - t0));
        const int* ft = fc + 3 * t0;
        for (int l = 0; l < nb; ++l) {
            const double* pa = x + 3 * Eigen::Index(ft[3 * l]);
            const double* pb = x + 3 * Eigen::Index(ft[3 * l + 1]);
            const double* pc = x + 3 * Eigen::Index(ft[3 * l + 2]);
            in[0][l] = pa[0] - ox; in[1][l] = pa[1] - oy; in[2][l] = pa[2] - oz;
            in[3][l] = pb[0] - ox; in[4][l] = pb[1] - oy; in[5][l] = pb[2] - oz;
            in[6][l] = pc[0] - ox; in[7][l] = pc[1] - oy; in[8][l] = pc[2] - oz;
        }
        // Padding of the last block: a non-degenerate triangle (unit axes), never scattered.
        for (int l = nb; l < B; ++l)
            for (int d = 0; d < 9; ++d) in[d][l] = (d % 4 == 0) ? 1.0 : 0.0;
        for (int l = 0; l < B; ++l) {  // |m|^2
            const double ax = in[0][l], ay = in[1][l], az = in[2][l];
            const double ux = in[3][l] - ax, uy = in[4][l] - ay, uz = in[5][l] - az;
            const double vx = in[6][l] - ax, vy = in[7][l] - ay, vz = in[8][l] - az;
            const double mx = uy * vz - uz * vy, my = uz * vx - ux * vz, mz = ux * vy - uy * vx;
            len[l] = mx * mx + my * my + mz * mz;
        }
        // Eigen's packet sqrt: std::sqrt in the loop above would not vectorise (errno).
        Eigen::Map<Eigen::Array<double, B, 1>, Eigen::Aligned64> lenMap(len);
        lenMap = lenMap.sqrt();
        if constexpr (!Gradients) {
            for (int l = 0; l < nb; ++l) {  // 6 V_t = a.(b x c)
                const double bx = in[3][l], by = in[4][l], bz = in[5][l];
                const double cx = in[6][l], cy = in[7][l], cz = in[8][l];
                twiceArea += len[l];
                sixVolume += in[0][l] * (by * cz - bz * cy) + in[1][l] * (bz * cx - bx * cz) + in[2][l] * (bx * cy - by * cx);
            }
            continue;
        }
        for (int l = 0; l < B; ++l) {  // dA/da = n x (c - b) / 2 cyclic, n = m / |m|
            const double ax = in[0][l], ay = in[1][l], az = in[2][l];
            const double bx = in[3][l], by = in[4][l], bz = in[5][l];
            const double cx = in[6][l], cy = in[7][l], cz = in[8][l];
            const double ux = bx - ax, uy = by - ay, uz = bz - az;  // b - a
            const double vx = cx - ax, vy = cy - ay, vz = cz - az;  // c - a
            const double wx = cx - bx, wy = cy - by, wz = cz - bz;  // c - b
            const double mx = uy * vz - uz * vy, my = uz * vx - ux * vz, mz = ux * vy - uy * vx;
            const double h = 0.5 / len[l];
            const double nx = h * mx, ny = h * my, nz = h * mz;  // n / 2
            out[0][l] = ny * wz - nz * wy; out[1][l] = nz * wx - nx * wz; out[2][l] = nx * wy - ny * wx;
            out[3][l] = nz * vy - ny * vz; out[4][l] = nx * vz - nz * vx; out[5][l] = ny * vx - nx * vy;
            out[6][l] = ny * uz - nz * uy; out[7][l] = nz * ux - nx * uz; out[8][l] = nx * uy - ny * ux;
        }
        for (int l = 0; l < B; ++l) {  // 6 dV/da = b x c cyclic, 6 V_t = a.(b x c)
            const double ax = in[0][l], ay = in[1][l], az = in[2][l];
            const double bx = in[3][l], by = in[4][l], bz = in[5][l];
            const double cx = in[6][l], cy = in[7][l], cz = in[8][l];
            const double px = by * cz - bz * cy, py = bz * cx - bx * cz, pz = bx * cy - by * cx;
            out[9][l] = px; out[10][l] = py; out[11][l] = pz;
            out[12][l] = cy * az - cz * ay; out[13][l] = cz * ax - cx * az; out[14][l] = cx * ay - cy * ax;
            out[15][l] = ay * bz - az * by; out[16][l] = az * bx - ax * bz; out[17][l] = ax * by - ay * bx;
            out[18][l] = ax * px + ay * py + az * pz;
        }
        for (int l = 0; l < nb; ++l) {
            twiceArea += len[l];
            sixVolume += out[18][l];
            for (int c = 0; c < 3; ++c) {
                double* p = acc + 6 * Eigen::Index(ft[3 * l + c]);
                p[0] += out[3 * c][l]; p[1] += out[3 * c + 1][l]; p[2] += out[3 * c + 2][l];
                p[3] += out[9 + 3 * c][l]; p[4] += out[10 + 3 * c][l]; p[5] += out[11 + 3 * c][l];
            }
        }
    }
    AreaVolume r;
    r.area = 0.5 * twiceArea;
    r.volume = sixVolume / 6.0;
    if constexpr (!Gradients) return r;
    r.areaGradient.resize(3, nv);
    r.volumeGradient.resize(3, nv);
    double* __restrict gA = r.areaGradient.data();
    double* __restrict gV = r.volumeGradient.data();
    constexpr double sixth = 1.0 / 6.0;
    for (Eigen::Index v = 0; v < nv; ++v) {
        gA[3 * v] = acc[6 * v]; gA[3 * v + 1] = acc[6 * v + 1]; gA[3 * v + 2] = acc[6 * v + 2];
        gV[3 * v] = sixth * acc[6 * v + 3];
        gV[3 * v + 1] = sixth * acc[6 * v + 4];
        gV[3 * v + 2] = sixth * acc[6 * v + 5];
    }
    return r;
}
}  // namespace

AreaVolume areaVolumeWithGradients(const Vertices& X, const Faces& F) { return blockedAreaVolume<true>(X, F); }

AreaVolume areaAndVolume(const Vertices& X, const Faces& F) { return blockedAreaVolume<false>(X, F); }

Eigen::VectorXd vertexAreas(const Vertices& X, const Faces& F) {
    const Eigen::VectorXd af = faceAreas(X, F);
    Eigen::VectorXd av = Eigen::VectorXd::Zero(X.cols());
    for (Eigen::Index f = 0; f < F.cols(); ++f)
        for (int k = 0; k < 3; ++k) av[F(k, f)] += af[f] / 3.0;
    return av;
}

Eigen::Vector3d centroid(const Vertices& X) { return X.rowwise().mean(); }

std::vector<Eigen::Index> inversionPartners(const Vertices& X0, double tol) {
    const Eigen::Index n = X0.cols();
    if (n == 0) return {};
    const Vertices X = X0.colwise() - centroid(X0);
    const double eps = tol * X.colwise().norm().maxCoeff();
    // Sorted by x, the partner of i lies among the vertices with x within eps of -x_i.
    std::vector<Eigen::Index> byX(static_cast<size_t>(n));
    std::iota(byX.begin(), byX.end(), Eigen::Index{0});
    std::sort(byX.begin(), byX.end(), [&X](Eigen::Index a, Eigen::Index b) { return X(0, a) < X(0, b); });
    std::vector<Eigen::Index> partner(static_cast<size_t>(n), -1);
    for (Eigen::Index i = 0; i < n; ++i) {
        auto it = std::lower_bound(byX.begin(), byX.end(), -X(0, i) - eps,
                                   [&X](Eigen::Index a, double x) { return X(0, a) < x; });
        for (; it != byX.end() && X(0, *it) <= -X(0, i) + eps; ++it)
            if ((X.col(*it) + X.col(i)).cwiseAbs().maxCoeff() <= eps) {
                partner[static_cast<size_t>(i)] = *it;
                break;
            }
        if (partner[static_cast<size_t>(i)] < 0) return {};
    }
    // An involution without fixed points (two vertices within eps of each other would break it).
    for (Eigen::Index i = 0; i < n; ++i) {
        const Eigen::Index j = partner[static_cast<size_t>(i)];
        if (j == i || partner[static_cast<size_t>(j)] != i) return {};
    }
    return partner;
}

void symmetrizeUnderInversion(Vertices& W, const std::vector<Eigen::Index>& partner) {
    // In place, once per pair (no copy: it runs on every gradient of a symmetric minimisation).
    for (Eigen::Index i = 0; i < W.cols(); ++i) {
        const Eigen::Index j = partner[static_cast<size_t>(i)];
        if (j < i) continue;
        const Eigen::Vector3d half = 0.5 * (W.col(i) - W.col(j));
        W.col(i) = half;
        W.col(j) = -half;
    }
}

double inversionAsymmetry(const Vertices& X0, const std::vector<Eigen::Index>& partner) {
    const Vertices X = X0.colwise() - centroid(X0);
    double asym = 0.0;
    for (Eigen::Index i = 0; i < X.cols(); ++i)
        asym = std::max(asym, (X.col(i) + X.col(partner[static_cast<size_t>(i)])).norm());
    return asym / X.colwise().norm().maxCoeff();
}

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

double meanEdgeLength(const Vertices& X, const Topology& topo) {
    double sum = 0.0;
    for (Eigen::Index e = 0; e < topo.edges.cols(); ++e) sum += (X.col(topo.edges(0, e)) - X.col(topo.edges(1, e))).norm();
    return sum / static_cast<double>(topo.edges.cols());
}

}  // namespace trbc
