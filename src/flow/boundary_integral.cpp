#include "flow/boundary_integral.hpp"

#include <fmt/format.h>
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <type_traits>

#include "core/error.hpp"
#include "flow/stokes_kernels.hpp"
#include "mesh/geometry.hpp"
#include "mesh/validate.hpp"

namespace trbc {
namespace {

using stokes::Mat3;
using stokes::Vec3;
using Eigen::Index;

constexpr double kPi = std::numbers::pi;
// Points per block of the far loops: 1 / r of a block is computed in one pass (inverseSqrt), the
// kernels in a second; both stay in L1.
constexpr int kBlock = 256;

/// r <- 1 / sqrt(r) elementwise, 0 where r = 0 (a point at the target, left out of the far sums).
/// With AVX2 + FMA: the single-precision estimate (relative error < 1.5 2^-12) and three Newton
/// steps y <- y (3 - r y^2) / 2 in double precision (the error squares at each: 4e-4, 2e-7,
/// 6e-14, then rounding), a few ulp from the correctly rounded value; a fused far pass costs 0.88x
/// of one with packet square root and division (bench_stokes, level 3). Lanes outside the float
/// range take the exact formula.
void inverseSqrt(double* r, Index n) {
    Index k = 0;
#if defined(__AVX2__) && defined(__FMA__)
    const __m256d half = _mm256_set1_pd(0.5), three = _mm256_set1_pd(3.0);
    const __m256d lo = _mm256_set1_pd(static_cast<double>(std::numeric_limits<float>::min()));
    const __m256d hi = _mm256_set1_pd(static_cast<double>(std::numeric_limits<float>::max()));
    for (; k + 4 <= n; k += 4) {
        const __m256d x = _mm256_loadu_pd(r + k);
        const __m256d inRange = _mm256_and_pd(_mm256_cmp_pd(x, lo, _CMP_GE_OQ), _mm256_cmp_pd(x, hi, _CMP_LE_OQ));
        if (_mm256_movemask_pd(inRange) != 0xF) {
            for (Index j = k; j < k + 4; ++j) r[j] = r[j] > 0.0 ? 1.0 / std::sqrt(r[j]) : 0.0;
            continue;
        }
        __m256d y = _mm256_cvtps_pd(_mm_rsqrt_ps(_mm256_cvtpd_ps(x)));
        for (int it = 0; it < 3; ++it) {
            const __m256d xy2 = _mm256_mul_pd(_mm256_mul_pd(x, y), y);
            y = _mm256_mul_pd(_mm256_mul_pd(half, y), _mm256_sub_pd(three, xy2));
        }
        _mm256_storeu_pd(r + k, y);
    }
#endif
    for (; k < n; ++k) r[k] = r[k] > 0.0 ? 1.0 / std::sqrt(r[k]) : 0.0;
}

#if defined(__AVX2__) && defined(__FMA__)
/// 1 / sqrt(x) for eight floats: the estimate and one Newton step y (3 - x y^2) / 2 (relative
/// error ~2e-7, the float rounding); lanes outside the normal float range take the exact formula,
/// 0 where x = 0.
inline __m256 inverseSqrt8(__m256 x) {
    const __m256 lo = _mm256_set1_ps(std::numeric_limits<float>::min());
    const __m256 hi = _mm256_set1_ps(std::numeric_limits<float>::max());
    const __m256 inRange = _mm256_and_ps(_mm256_cmp_ps(x, lo, _CMP_GE_OQ), _mm256_cmp_ps(x, hi, _CMP_LE_OQ));
    if (_mm256_movemask_ps(inRange) != 0xFF) {
        alignas(32) float r[8];
        _mm256_store_ps(r, x);
        for (float& v : r) v = v > 0.0f ? 1.0f / std::sqrt(v) : 0.0f;
        return _mm256_load_ps(r);
    }
    const __m256 y = _mm256_rsqrt_ps(x);
    const __m256 xy2 = _mm256_mul_ps(_mm256_mul_ps(x, y), y);
    return _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(0.5f), y), _mm256_sub_ps(_mm256_set1_ps(3.0f), xy2));
}
#endif

/// The same in single precision (inverseSqrt8 with AVX2 + FMA).
void inverseSqrt(float* r, Index n) {
    Index k = 0;
#if defined(__AVX2__) && defined(__FMA__)
    for (; k + 8 <= n; k += 8) _mm256_storeu_ps(r + k, inverseSqrt8(_mm256_loadu_ps(r + k)));
#endif
    for (; k < n; ++k) r[k] = r[k] > 0.0f ? 1.0f / std::sqrt(r[k]) : 0.0f;
}

/// A rule on the reference triangle: barycentric coordinates (points x 3), weights summing to 1.
struct TriangleRule {
    Eigen::MatrixX3d bary;
    Eigen::VectorXd weight;
};

/// Symmetric rules (Strang & Fix 1973; Dunavant 1985): degree 1, 2, 4, 5 for 1, 3, 6, 7 points.
TriangleRule symmetricRule(int points) {
    TriangleRule r;
    std::vector<std::array<double, 4>> p;  // b0, b1, b2, w
    auto orbit3 = [&](double a, double w) {  // (a, a, 1 - 2a) and its permutations
        const double b = 1.0 - 2.0 * a;
        p.push_back({a, a, b, w});
        p.push_back({a, b, a, w});
        p.push_back({b, a, a, w});
    };
    switch (points) {
        case 1: p.push_back({1.0 / 3, 1.0 / 3, 1.0 / 3, 1.0}); break;
        case 3: orbit3(1.0 / 6, 1.0 / 3); break;
        case 6:
            orbit3(0.445948490915965, 0.223381589678011);
            orbit3(0.091576213509771, 0.109951743655322);
            break;
        case 7:
            p.push_back({1.0 / 3, 1.0 / 3, 1.0 / 3, 0.225});
            orbit3(0.470142064105115, 0.132394152788506);
            orbit3(0.101286507323456, 0.125939180544827);
            break;
        default:
            throw InputError(fmt::format("quadrature farPoints = {}: must be 1, 3, 6 or 7", points));
    }
    r.bary.resize(static_cast<Index>(p.size()), 3);
    r.weight.resize(static_cast<Index>(p.size()));
    for (Index q = 0; q < r.weight.size(); ++q) {
        for (int m = 0; m < 3; ++m) r.bary(q, m) = p[q][m];
        r.weight[q] = p[q][3];
    }
    return r;
}

/// The rule applied on the 4^levels sub-triangles of midpoint subdivision.
TriangleRule subdividedRule(const TriangleRule& base, int levels) {
    std::vector<Eigen::Matrix3d> tris{Eigen::Matrix3d::Identity()};  // rows: corners (barycentric)
    for (int l = 0; l < levels; ++l) {
        std::vector<Eigen::Matrix3d> next;
        for (const auto& t : tris) {
            const Eigen::RowVector3d a = t.row(0), b = t.row(1), c = t.row(2);
            const Eigen::RowVector3d ab = 0.5 * (a + b), bc = 0.5 * (b + c), ca = 0.5 * (c + a);
            for (const auto& [p, q, s] : {std::array{a, ab, ca}, std::array{ab, b, bc},
                                          std::array{ca, bc, c}, std::array{ab, bc, ca}}) {
                Eigen::Matrix3d m;
                m << p, q, s;
                next.push_back(m);
            }
        }
        tris.swap(next);
    }
    const Index nb = base.weight.size();
    TriangleRule r;
    r.bary.resize(nb * static_cast<Index>(tris.size()), 3);
    r.weight.resize(r.bary.rows());
    for (std::size_t t = 0; t < tris.size(); ++t)
        for (Index q = 0; q < nb; ++q) {
            const Index k = static_cast<Index>(t) * nb + q;
            r.bary.row(k) = base.bary.row(q) * tris[t];
            r.weight[k] = base.weight[q] / static_cast<double>(tris.size());
        }
    return r;
}

/// Gauss-Legendre nodes and weights on [0, 1] (Newton on P_n).
void gaussLegendre01(int n, Eigen::VectorXd& x, Eigen::VectorXd& w) {
    x.resize(n);
    w.resize(n);
    for (int i = 0; i < n; ++i) {
        double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), dp = 1.0;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1.0, p1 = z;  // P_0, P_1
            for (int k = 2; k <= n; ++k) {
                const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            const double pn = n == 1 ? z : p1, pm = n == 1 ? 1.0 : p0;
            dp = n * (z * pn - pm) / (z * z - 1.0);
            const double dz = pn / dp;
            z -= dz;
            if (std::abs(dz) < 1e-16) break;
        }
        x[i] = 0.5 * (1.0 - z);
        w[i] = 1.0 / ((1.0 - z * z) * dp * dp);  // 2/((1-z^2) P'^2), halved for [0, 1]
    }
}

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

/// The far-rule points and a density on them (structure of arrays), in T = double or float.
template <class T>
struct FarPoints {
    const T *x, *y, *z, *w, *wnx, *wny, *wnz;  ///< position, weight, weighted normal
    Index n;
};
template <class T>
struct PointDensity {
    const T *x, *y, *z;
};

/// Far parts at the target x0, in one pass over the points:
///   single layer  s = sum_q w_q G(y_q - x0) g_q,
///   double layer  v = sum_q w_q K(y_q - x0, n_q) (u_q - u0)   (singularity subtracted),
/// either or both (template flags). A point at x0 contributes nothing (1/r set to 0). Each block
/// of kBlock points is summed in T, the block sums in double.
template <class T, bool kSingle, bool kDouble>
void farSum(const T (&x0)[3], const FarPoints<T>& p, const PointDensity<T>& g, const PointDensity<T>& u,
            const T (&u0)[3], Vec3& s, Vec3& v) {
    alignas(64) T dx[kBlock], dy[kBlock], dz[kBlock], rinv[kBlock];
    const T* __restrict px = p.x;
    const T* __restrict py = p.y;
    const T* __restrict pz = p.z;
    const T* __restrict pw = p.w;
    const T* __restrict nx = p.wnx;
    const T* __restrict ny = p.wny;
    const T* __restrict nz = p.wnz;
    const T* __restrict gx = g.x;
    const T* __restrict gy = g.y;
    const T* __restrict gz = g.z;
    const T* __restrict ux = u.x;
    const T* __restrict uy = u.y;
    const T* __restrict uz = u.z;
    const T x00 = x0[0], x01 = x0[1], x02 = x0[2], u00 = u0[0], u01 = u0[1], u02 = u0[2];
    s.setZero();
    v.setZero();
    for (Index b0 = 0; b0 < p.n; b0 += kBlock) {
        const int m = static_cast<int>(std::min<Index>(kBlock, p.n - b0));
#pragma omp simd
        for (int k = 0; k < m; ++k) {
            dx[k] = px[b0 + k] - x00;
            dy[k] = py[b0 + k] - x01;
            dz[k] = pz[b0 + k] - x02;
            rinv[k] = dx[k] * dx[k] + dy[k] * dy[k] + dz[k] * dz[k];
        }
        inverseSqrt(rinv, m);
        T sx = 0, sy = 0, sz = 0, vx = 0, vy = 0, vz = 0;
#pragma omp simd reduction(+ : sx, sy, sz, vx, vy, vz)
        for (int k = 0; k < m; ++k) {
            const Index q = b0 + k;
            if constexpr (kSingle)
                stokes::addStokeslet(dx[k], dy[k], dz[k], rinv[k], pw[q], gx[q], gy[q], gz[q], sx, sy, sz);
            if constexpr (kDouble) {
                const T c = stokes::doubleLayerCoefficient(dx[k], dy[k], dz[k], rinv[k], nx[q], ny[q], nz[q]);
                // K (u_q - u0) = c d (d . (u_q - u0))
                const T du = c * (dx[k] * (ux[q] - u00) + dy[k] * (uy[q] - u01) + dz[k] * (uz[q] - u02));
                vx += du * dx[k];
                vy += du * dy[k];
                vz += du * dz[k];
            }
        }
        s += Vec3(double(sx), double(sy), double(sz));
        v += Vec3(double(vx), double(vy), double(vz));
    }
}

#if defined(__AVX2__) && defined(__FMA__)
constexpr bool kTwoTargetFarSum = true;
/// farSum<float> for two targets at once (AVX2 + FMA), with the weighted single-layer density
/// wg_q = w_q g_q: one pass per 8 points, each point's position, normal and densities loaded once
/// for both targets, 1 / r kept in registers (inverseSqrt8), twelve independent accumulators, the
/// double layer's factor -6 applied to the block sums. The multiplies set the pace (about 31 per
/// pair for both layers), so the gain over two farSum calls is modest (docs/PERFORMANCE.md,
/// "Flow solver").
template <bool kSingle, bool kDouble>
void farSumTwoTargets(const float (&x0)[2][3], const FarPoints<float>& p, const PointDensity<float>& wg,
                      const PointDensity<float>& u, const float (&u0)[2][3], Vec3 (&s)[2], Vec3 (&v)[2]) {
    alignas(32) static constexpr int kLanes[16] = {-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0};
    __m256 X[2][3], U[2][3];
    for (int t = 0; t < 2; ++t)
        for (int c = 0; c < 3; ++c) X[t][c] = _mm256_set1_ps(x0[t][c]), U[t][c] = _mm256_set1_ps(u0[t][c]);
    for (int t = 0; t < 2; ++t) s[t].setZero(), v[t].setZero();
    const auto hsum = [](__m256 a) {
        const __m128 q = _mm_add_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1));
        const __m128 d = _mm_add_ps(q, _mm_movehl_ps(q, q));
        return double(_mm_cvtss_f32(_mm_add_ss(d, _mm_movehdup_ps(d))));
    };
    for (Index b0 = 0; b0 < p.n; b0 += kBlock) {
        const Index bend = std::min<Index>(p.n, b0 + kBlock);
        __m256 acc[2][6];
        for (auto& a : acc)
            for (auto& c : a) c = _mm256_setzero_ps();
        for (Index k = b0; k < bend; k += 8) {
            // A partial last chunk reads zeros beyond the end, and its 1 / r is zeroed there (a
            // zero point near the target would overflow r^-5): those lanes add exactly nothing.
            const bool full = bend - k >= 8;
            const __m256i mask = _mm256_loadu_si256(
                reinterpret_cast<const __m256i*>(kLanes + 8 - static_cast<int>(std::min<Index>(8, bend - k))));
            const auto load = [&](const float* a) {
                return full ? _mm256_loadu_ps(a + k) : _mm256_maskload_ps(a + k, mask);
            };
            const __m256 px = load(p.x), py = load(p.y), pz = load(p.z);
            __m256 gx{}, gy{}, gz{}, nx{}, ny{}, nz{}, ux{}, uy{}, uz{};
            if constexpr (kSingle) gx = load(wg.x), gy = load(wg.y), gz = load(wg.z);
            if constexpr (kDouble)
                nx = load(p.wnx), ny = load(p.wny), nz = load(p.wnz), ux = load(u.x), uy = load(u.y), uz = load(u.z);
            for (int t = 0; t < 2; ++t) {
                const __m256 dx = _mm256_sub_ps(px, X[t][0]), dy = _mm256_sub_ps(py, X[t][1]),
                             dz = _mm256_sub_ps(pz, X[t][2]);
                const __m256 r2 = _mm256_fmadd_ps(dz, dz, _mm256_fmadd_ps(dy, dy, _mm256_mul_ps(dx, dx)));
                __m256 rinv = inverseSqrt8(r2);  // 0 for a point at the target
                if (!full) rinv = _mm256_and_ps(rinv, _mm256_castsi256_ps(mask));
                const __m256 r2inv = _mm256_mul_ps(rinv, rinv), r3inv = _mm256_mul_ps(r2inv, rinv);
                if constexpr (kSingle) {  // w G g = (w g) / r + (d . w g) d / r^3
                    const __m256 dg = _mm256_fmadd_ps(dz, gz, _mm256_fmadd_ps(dy, gy, _mm256_mul_ps(dx, gx)));
                    const __m256 b = _mm256_mul_ps(r3inv, dg);
                    acc[t][0] = _mm256_add_ps(acc[t][0], _mm256_fmadd_ps(rinv, gx, _mm256_mul_ps(b, dx)));
                    acc[t][1] = _mm256_add_ps(acc[t][1], _mm256_fmadd_ps(rinv, gy, _mm256_mul_ps(b, dy)));
                    acc[t][2] = _mm256_add_ps(acc[t][2], _mm256_fmadd_ps(rinv, gz, _mm256_mul_ps(b, dz)));
                }
                if constexpr (kDouble) {  // c / -6 = (d . w n) / r^5
                    const __m256 dn = _mm256_fmadd_ps(dz, nz, _mm256_fmadd_ps(dy, ny, _mm256_mul_ps(dx, nx)));
                    const __m256 c = _mm256_mul_ps(dn, _mm256_mul_ps(r3inv, r2inv));
                    const __m256 ddu = _mm256_fmadd_ps(
                        dz, _mm256_sub_ps(uz, U[t][2]),
                        _mm256_fmadd_ps(dy, _mm256_sub_ps(uy, U[t][1]), _mm256_mul_ps(dx, _mm256_sub_ps(ux, U[t][0]))));
                    const __m256 du = _mm256_mul_ps(c, ddu);
                    acc[t][3] = _mm256_fmadd_ps(du, dx, acc[t][3]);
                    acc[t][4] = _mm256_fmadd_ps(du, dy, acc[t][4]);
                    acc[t][5] = _mm256_fmadd_ps(du, dz, acc[t][5]);
                }
            }
        }
        for (int t = 0; t < 2; ++t) {
            if constexpr (kSingle) s[t] += Vec3(hsum(acc[t][0]), hsum(acc[t][1]), hsum(acc[t][2]));
            if constexpr (kDouble) v[t] += -6.0 * Vec3(hsum(acc[t][3]), hsum(acc[t][4]), hsum(acc[t][5]));
        }
    }
}
#else
constexpr bool kTwoTargetFarSum = false;
#endif

Eigen::Matrix3d faceCorners(const Mesh& m, Index f) {
    Eigen::Matrix3d c;
    for (int k = 0; k < 3; ++k) c.col(k) = m.X.col(m.F(k, f));
    return c;
}

}  // namespace

BoundaryIntegralOperators::BoundaryIntegralOperators(const Mesh& mesh, const QuadratureOptions& options)
    : mesh_(mesh), options_(options) {
    validateClosedManifold(mesh_);
    if (!(options_.nearFactor >= 0.0) || !std::isfinite(options_.nearFactor))
        throw InputError(fmt::format("quadrature nearFactor = {}: must be finite and >= 0",
                                     options_.nearFactor));
    if (options_.nearSubdivisions < 0 || options_.nearSubdivisions > 5)
        throw InputError(fmt::format("quadrature nearSubdivisions = {}: must be in [0, 5]",
                                     options_.nearSubdivisions));
    if (options_.singularPoints < 1 || options_.singularPoints > 64)
        throw InputError(fmt::format("quadrature singularPoints = {}: must be in [1, 64]",
                                     options_.singularPoints));
    if (!mesh_.X.allFinite()) throw InputError("mesh: vertex positions must be finite");

    const Index nf = mesh_.numFaces(), nv = mesh_.numVertices();
    faceArea_ = trbc::faceAreas(mesh_.X, mesh_.F);
    faceNormal_.resize(3, nf);
    vertexNormal_ = Eigen::Matrix3Xd::Zero(3, nv);
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        const Vec3 twiceArea = (c.col(1) - c.col(0)).cross(c.col(2) - c.col(0));
        faceNormal_.col(f) = twiceArea.normalized();
        for (int k = 0; k < 3; ++k) vertexNormal_.col(mesh_.F(k, f)) += twiceArea;
    }
    vertexNormal_.colwise().normalize();
    vertexArea_ = trbc::vertexAreas(mesh_.X, mesh_.F);
    area_ = faceArea_.sum();
    volume_ = enclosedVolume(mesh_.X, mesh_.F);
    for (auto* a : {&faceCentroidX_, &faceCentroidY_, &faceCentroidZ_, &faceNearReach2_}) a->resize(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        const Vec3 centroid = c.rowwise().mean();
        faceCentroidX_[f] = centroid.x(), faceCentroidY_[f] = centroid.y(), faceCentroidZ_[f] = centroid.z();
        const double reach = options_.nearFactor * std::max({(c.col(1) - c.col(0)).norm(), (c.col(2) - c.col(1)).norm(),
                                                             (c.col(0) - c.col(2)).norm()});
        faceNearReach2_[f] = reach * reach;
    }
    buildQuadrature();
    buildCorrections();
}

void BoundaryIntegralOperators::markNearFaces(const Vec3& x0, std::vector<char>& near) const {
    const Index nf = static_cast<Index>(faceNearReach2_.size());
    near.resize(static_cast<std::size_t>(nf));
#pragma omp simd
    for (Index f = 0; f < nf; ++f) near[static_cast<std::size_t>(f)] = isNearFace(x0, f);
}

void BoundaryIntegralOperators::buildQuadrature() {
    const TriangleRule rule = symmetricRule(options_.farPoints);
    ruleBary_ = rule.bary;
    ruleWeight_ = rule.weight;
    const Index nf = mesh_.numFaces(), nv = mesh_.numVertices(), nq = ruleWeight_.size();
    for (auto* v : {&fx_, &fy_, &fz_, &fw_}) v->assign(static_cast<std::size_t>(nf * nq), 0.0);
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        for (Index q = 0; q < nq; ++q) {
            const std::size_t k = static_cast<std::size_t>(f * nq + q);
            const Vec3 y = c * ruleBary_.row(q).transpose();
            fx_[k] = y.x(), fy_[k] = y.y(), fz_[k] = y.z();
            fw_[k] = faceArea_[f] * ruleWeight_[q];
        }
    }

    if (options_.farRule == FarRule::FacePoints) {
        cornerWeight_ = 0.0;
        farBary_ = ruleBary_;
        farWeight_ = ruleWeight_;
    } else {  // corners 1/12 each, centroid 3/4: exact for quadratics on the triangle
        cornerWeight_ = 1.0 / 12.0;
        farBary_ = Eigen::RowVector3d::Constant(1.0 / 3.0);
        farWeight_ = Eigen::VectorXd::Constant(1, 0.75);
    }
    cornerPoints_ = cornerWeight_ > 0.0 ? nv : 0;
    const Index nqf = farWeight_.size();
    const std::size_t n = static_cast<std::size_t>(cornerPoints_ + nf * nqf);
    for (auto* v : {&qx_, &qy_, &qz_, &qw_, &qnx_, &qny_, &qnz_}) v->assign(n, 0.0);
    const auto addPoint = [&](std::size_t k, const Vec3& y, double w, const Vec3& n) {
        qx_[k] = y.x(), qy_[k] = y.y(), qz_[k] = y.z();
        qw_[k] += w;
        qnx_[k] += w * n.x(), qny_[k] += w * n.y(), qnz_[k] += w * n.z();
    };
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        const Vec3 n = faceNormal_.col(f);
        if (cornerPoints_ > 0)
            for (int m = 0; m < 3; ++m)
                addPoint(static_cast<std::size_t>(mesh_.F(m, f)), c.col(m), faceArea_[f] * cornerWeight_, n);
        for (Index q = 0; q < nqf; ++q)
            addPoint(static_cast<std::size_t>(cornerPoints_ + f * nqf + q), c * farBary_.row(q).transpose(),
                     faceArea_[f] * farWeight_[q], n);
    }
    if (options_.singlePrecisionFar) {
        // Relative to the centroid: float keeps ~1e-7 of the cell's extent in the separations.
        farCentre_ = mesh_.X.rowwise().mean();
        const auto toFloat = [](const std::vector<double>& a, std::vector<float>& b, double shift) {
            b.resize(a.size());
            for (std::size_t k = 0; k < a.size(); ++k) b[k] = static_cast<float>(a[k] - shift);
        };
        toFloat(qx_, qxf_, farCentre_.x());
        toFloat(qy_, qyf_, farCentre_.y());
        toFloat(qz_, qzf_, farCentre_.z());
        toFloat(qw_, qwf_, 0.0);
        toFloat(qnx_, qnxf_, 0.0);
        toFloat(qny_, qnyf_, 0.0);
        toFloat(qnz_, qnzf_, 0.0);
    }
}

void BoundaryIntegralOperators::buildCorrections() {
    const Index nf = mesh_.numFaces(), nv = mesh_.numVertices();
    const TriangleRule nearRule =
        subdividedRule(TriangleRule{ruleBary_, ruleWeight_}, options_.nearSubdivisions);
    Eigen::VectorXd gt, gw;
    gaussLegendre01(options_.singularPoints, gt, gw);

    // Faces around each vertex.
    std::vector<std::vector<int>> vertexFaces(nv);
    for (Index f = 0; f < nf; ++f)
        for (int k = 0; k < 3; ++k) vertexFaces[mesh_.F(k, f)].push_back(static_cast<int>(f));

    // The near rule followed by the far rule's points with negative weights: one batch per near
    // face yields its refined integral minus the far rule's share of the far sum.
    const Index nn = nearRule.weight.size(), nFar = (cornerPoints_ > 0 ? 3 : 0) + farWeight_.size();
    Eigen::MatrixX3d batchBary(nn + nFar, 3);
    Eigen::VectorXd batchWeight(nn + nFar);
    batchBary.topRows(nn) = nearRule.bary;
    batchWeight.head(nn) = nearRule.weight;
    Index nb = nn;
    if (cornerPoints_ > 0)
        for (int m = 0; m < 3; ++m, ++nb) {
            batchBary.row(nb) = Eigen::RowVector3d::Unit(m);
            batchWeight[nb] = -cornerWeight_;
        }
    for (Index q = 0; q < farWeight_.size(); ++q, ++nb) {
        batchBary.row(nb) = farBary_.row(q);
        batchWeight[nb] = -farWeight_[q];
    }
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
                inverseSqrt(&d(0, 3), nq);
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

    corrStart_.assign(nv + 1, 0);
    for (Index i = 0; i < nv; ++i) corrStart_[i + 1] = corrStart_[i] + static_cast<int>(rows[i].col.size());
    const std::size_t nnz = static_cast<std::size_t>(corrStart_[nv]);
    corrCol_.resize(nnz);
    corrS_.resize(9 * nnz);
    corrD_.resize(9 * nnz);
    for (Index i = 0; i < nv; ++i)
        for (std::size_t k = 0; k < rows[i].col.size(); ++k) {
            const std::size_t p = corrStart_[i] + k;
            corrCol_[p] = rows[i].col[k];
            Eigen::Map<Mat3>{&corrS_[9 * p]} = rows[i].s[k];
            Eigen::Map<Mat3>{&corrD_[9 * p]} = rows[i].d[k];
        }
}

double BoundaryIntegralOperators::meanCorrectionsPerTarget() const {
    return static_cast<double>(corrCol_.size()) / static_cast<double>(numVertices());
}

template <class T>
void BoundaryIntegralOperators::interpolate(const Eigen::Matrix3Xd& v, std::vector<T>& vx, std::vector<T>& vy,
                                            std::vector<T>& vz) const {
    const Index nf = mesh_.numFaces(), nq = farWeight_.size(), n0 = cornerPoints_;
    for (auto* p : {&vx, &vy, &vz}) p->resize(static_cast<std::size_t>(n0 + nf * nq));
    for (Index j = 0; j < n0; ++j) vx[j] = T(v(0, j)), vy[j] = T(v(1, j)), vz[j] = T(v(2, j));
    for (Index f = 0; f < nf; ++f) {
        const Vec3 a = v.col(mesh_.F(0, f)), b = v.col(mesh_.F(1, f)), c = v.col(mesh_.F(2, f));
        for (Index q = 0; q < nq; ++q) {
            const Vec3 y = farBary_(q, 0) * a + farBary_(q, 1) * b + farBary_(q, 2) * c;
            const Index k = n0 + f * nq + q;
            vx[k] = T(y.x()), vy[k] = T(y.y()), vz[k] = T(y.z());
        }
    }
}

namespace {
void checkDensity(const Eigen::Matrix3Xd& v, Index nv, const char* name) {
    if (v.cols() != nv)
        throw InputError(fmt::format("{}: {} columns given, the mesh has {} vertices", name, v.cols(), nv));
}
}  // namespace

template <bool kSingle, bool kDouble>
void BoundaryIntegralOperators::applyLayers(const Eigen::Matrix3Xd* f, const Eigen::Matrix3Xd* u,
                                            Eigen::Matrix3Xd* Sf, Eigen::Matrix3Xd* Du) const {
    if (options_.singlePrecisionFar)
        applyLayersIn<float, kSingle, kDouble>(f, u, Sf, Du);
    else
        applyLayersIn<double, kSingle, kDouble>(f, u, Sf, Du);
}

template <class T, bool kSingle, bool kDouble>
void BoundaryIntegralOperators::applyLayersIn(const Eigen::Matrix3Xd* f, const Eigen::Matrix3Xd* u,
                                              Eigen::Matrix3Xd* Sf, Eigen::Matrix3Xd* Du) const {
    constexpr bool kFloat = std::is_same_v<T, float>;
    const Index nv = numVertices();
    std::vector<T> gx, gy, gz, ux, uy, uz;
    if constexpr (kSingle) interpolate(*f, gx, gy, gz), Sf->resize(3, nv);
    if constexpr (kDouble) interpolate(*u, ux, uy, uz), Du->resize(3, nv);
    const FarPoints<T> pts = [&] {
        if constexpr (kFloat)
            return FarPoints<T>{qxf_.data(), qyf_.data(), qzf_.data(), qwf_.data(), qnxf_.data(), qnyf_.data(), qnzf_.data(),
                                numQuadraturePoints()};
        else
            return FarPoints<T>{qx_.data(), qy_.data(), qz_.data(), qw_.data(), qnx_.data(), qny_.data(), qnz_.data(),
                                numQuadraturePoints()};
    }();
    const Vec3 centre = kFloat ? farCentre_ : Vec3::Zero();
    const PointDensity<T> g{gx.data(), gy.data(), gz.data()}, ud{ux.data(), uy.data(), uz.data()};
    const auto target = [&](Index i, T (&x0)[3], T (&u0t)[3]) {
        for (int c = 0; c < 3; ++c) {
            x0[c] = T(mesh_.X(c, i) - centre[c]);
            u0t[c] = kDouble ? T((*u)(c, i)) : T(0);
        }
    };
    const auto finish = [&](Index i, Vec3 s, Vec3 v) {
        for (int p = corrStart_[i]; p < corrStart_[i + 1]; ++p) {
            const std::size_t o = 9 * static_cast<std::size_t>(p);
            if constexpr (kSingle) s += Eigen::Map<const Mat3>(&corrS_[o]) * f->col(corrCol_[p]);
            if constexpr (kDouble) v += Eigen::Map<const Mat3>(&corrD_[o]) * u->col(corrCol_[p]);
        }
        if constexpr (kSingle) Sf->col(i) = s;
        if constexpr (kDouble) Du->col(i) = v - 4.0 * kPi * u->col(i);
    };
    // Targets two at a time in float with AVX2 + FMA (farSumTwoTargets; an odd last target alone),
    // else one at a time.
    constexpr bool kTwo = kFloat && kTwoTargetFarSum;
    constexpr Index kTargets = kTwo ? 2 : 1;
    std::vector<T> wgx, wgy, wgz;
    if constexpr (kTwo && kSingle) {
        const Index np = numQuadraturePoints();
        wgx.resize(static_cast<std::size_t>(np)), wgy.resize(wgx.size()), wgz.resize(wgx.size());
        for (Index k = 0; k < np; ++k) wgx[k] = qwf_[k] * gx[k], wgy[k] = qwf_[k] * gy[k], wgz[k] = qwf_[k] * gz[k];
    }
    const PointDensity<T> wg{wgx.data(), wgy.data(), wgz.data()};
#pragma omp parallel for schedule(static)
    for (Index i0 = 0; i0 < nv; i0 += kTargets) {
        if constexpr (kTwo) {
            if (i0 + 1 < nv) {
                T x0[2][3], u0t[2][3];
                Vec3 s[2], v[2];
                target(i0, x0[0], u0t[0]);
                target(i0 + 1, x0[1], u0t[1]);
                farSumTwoTargets<kSingle, kDouble>(x0, pts, wg, ud, u0t, s, v);
                finish(i0, s[0], v[0]);
                finish(i0 + 1, s[1], v[1]);
                continue;
            }
        }
        {
            T x0[3], u0t[3];
            Vec3 s, v;
            target(i0, x0, u0t);
            farSum<T, kSingle, kDouble>(x0, pts, g, ud, u0t, s, v);
            finish(i0, s, v);
        }
    }
}

Eigen::Matrix3Xd BoundaryIntegralOperators::singleLayer(const Eigen::Matrix3Xd& f) const {
    checkDensity(f, numVertices(), "single-layer density");
    Eigen::Matrix3Xd out;
    applyLayers<true, false>(&f, nullptr, &out, nullptr);
    return out;
}

Eigen::Matrix3Xd BoundaryIntegralOperators::doubleLayer(const Eigen::Matrix3Xd& u) const {
    checkDensity(u, numVertices(), "double-layer density");
    Eigen::Matrix3Xd out;
    applyLayers<false, true>(nullptr, &u, nullptr, &out);
    return out;
}

void BoundaryIntegralOperators::layers(const Eigen::Matrix3Xd& f, const Eigen::Matrix3Xd& u, Eigen::Matrix3Xd& Sf,
                                       Eigen::Matrix3Xd& Du) const {
    checkDensity(f, numVertices(), "single-layer density");
    checkDensity(u, numVertices(), "double-layer density");
    applyLayers<true, true>(&f, &u, &Sf, &Du);
}

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

Eigen::Vector3d BoundaryIntegralOperators::integrate(const Eigen::Matrix3Xd& f) const {
    checkDensity(f, numVertices(), "surface density");
    return f * vertexArea_;
}

Eigen::Vector3d BoundaryIntegralOperators::moment(const Eigen::Matrix3Xd& f, const Eigen::Vector3d& c) const {
    checkDensity(f, numVertices(), "surface density");
    // int_face phi_a phi_b dS = A (1 + delta_ab) / 12.
    Vec3 m = Vec3::Zero();
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        Vec3 xs = Vec3::Zero(), fs = Vec3::Zero(), diag = Vec3::Zero();
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = mesh_.X.col(mesh_.F(k, t)) - c, g = f.col(mesh_.F(k, t));
            xs += x;
            fs += g;
            diag += x.cross(g);
        }
        m += faceArea_[t] / 12.0 * (xs.cross(fs) + diag);
    }
    return m;
}

Eigen::Matrix3d BoundaryIntegralOperators::firstMoment(const Eigen::Matrix3Xd& f,
                                                       const Eigen::Vector3d& c) const {
    checkDensity(f, numVertices(), "surface density");
    Mat3 m = Mat3::Zero();
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        Vec3 xs = Vec3::Zero(), fs = Vec3::Zero();
        Mat3 diag = Mat3::Zero();
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = mesh_.X.col(mesh_.F(k, t)) - c, g = f.col(mesh_.F(k, t));
            xs += x;
            fs += g;
            diag += x * g.transpose();
        }
        m += faceArea_[t] / 12.0 * (xs * fs.transpose() + diag);
    }
    return m;
}

double BoundaryIntegralOperators::normalFlux(const Eigen::Matrix3Xd& u) const {
    checkDensity(u, numVertices(), "surface velocity");
    double s = 0.0;
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        const Vec3 us = u.col(mesh_.F(0, t)) + u.col(mesh_.F(1, t)) + u.col(mesh_.F(2, t));
        s += faceArea_[t] / 3.0 * us.dot(faceNormal_.col(t));
    }
    return s;
}

Eigen::Vector3d BoundaryIntegralOperators::volumeMeanVelocity(const Eigen::Matrix3Xd& u) const {
    checkDensity(u, numVertices(), "surface velocity");
    Vec3 s = Vec3::Zero();
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        const Vec3 n = faceNormal_.col(t);
        Vec3 xs = Vec3::Zero(), diag = Vec3::Zero();
        double us = 0.0;
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = mesh_.X.col(mesh_.F(k, t));
            const double un = u.col(mesh_.F(k, t)).dot(n);
            xs += x;
            us += un;
            diag += un * x;
        }
        s += faceArea_[t] / 12.0 * (us * xs + diag);
    }
    return s / volume_;
}

}  // namespace trbc
