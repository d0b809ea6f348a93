// The far field of the boundary-integral operators, matrix-free: the densities interpolated to
// the far rule's points, the fused far sums (flow/far_sum.hpp) at every target, then the sparse
// near corrections.
#include <fmt/format.h>

#include <Eigen/Core>
#include <numbers>
#include <type_traits>
#include <vector>

#include "core/error.hpp"
#include "core/simd.hpp"
#include "flow/boundary_integral.hpp"
#include "flow/far_sum.hpp"
#include "flow/stokes_kernels.hpp"

namespace trbc {
namespace {

using Eigen::Index;
using stokes::Mat3;
using stokes::Vec3;
using bie::FarPoints;
using bie::PointDensity;
using bie::farSum;

constexpr double kPi = std::numbers::pi;

}  // namespace

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
    // Targets two at a time in float where the CPU has AVX2 + FMA (farSumTwoTargetsAvx2; an odd
    // last target alone), else one at a time.
#if defined(TRBC_FAR_SUM_AVX2_DISPATCH)
    const bool two = kFloat && simd::active() == simd::Path::avx2;
#else
    constexpr bool two = false;
#endif
    const Index targets = two ? 2 : 1;
    std::vector<T> wgx, wgy, wgz;
    if (two && kSingle) {
        const Index np = numQuadraturePoints();
        wgx.resize(static_cast<std::size_t>(np)), wgy.resize(wgx.size()), wgz.resize(wgx.size());
        for (Index k = 0; k < np; ++k) wgx[k] = qwf_[k] * gx[k], wgy[k] = qwf_[k] * gy[k], wgz[k] = qwf_[k] * gz[k];
    }
    const PointDensity<T> wg{wgx.data(), wgy.data(), wgz.data()};
#pragma omp parallel for schedule(static)
    for (Index i0 = 0; i0 < nv; i0 += targets) {
#if defined(TRBC_FAR_SUM_AVX2_DISPATCH)
        if constexpr (kFloat) {
            if (two && i0 + 1 < nv) {
                T x0[2][3], u0t[2][3];
                Vec3 s[2], v[2];
                target(i0, x0[0], u0t[0]);
                target(i0 + 1, x0[1], u0t[1]);
                bie::farSumTwoTargetsAvx2<kSingle, kDouble>(x0, pts, wg, ud, u0t, s, v);
                finish(i0, s[0], v[0]);
                finish(i0 + 1, s[1], v[1]);
                continue;
            }
        }
#endif
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
    checkDensity(f, "single-layer density");
    Eigen::Matrix3Xd out;
    applyLayers<true, false>(&f, nullptr, &out, nullptr);
    return out;
}

Eigen::Matrix3Xd BoundaryIntegralOperators::doubleLayer(const Eigen::Matrix3Xd& u) const {
    checkDensity(u, "double-layer density");
    Eigen::Matrix3Xd out;
    applyLayers<false, true>(nullptr, &u, nullptr, &out);
    return out;
}

void BoundaryIntegralOperators::layers(const Eigen::Matrix3Xd& f, const Eigen::Matrix3Xd& u, Eigen::Matrix3Xd& Sf,
                                       Eigen::Matrix3Xd& Du) const {
    checkDensity(f, "single-layer density");
    checkDensity(u, "double-layer density");
    applyLayers<true, true>(&f, &u, &Sf, &Du);
}

}  // namespace trbc
