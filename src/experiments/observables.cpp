#include "experiments/observables.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>

#include "core/error.hpp"
#include "mesh/geometry.hpp"

namespace trbc {

namespace {

// Ray casting of the equilibrium profile by slicing instead of ray-triangle tests.
//
// Every ray {(r_k, 0, z)} lies in the plane y = 0, so the points where it meets a triangle are the
// points of the slice (triangle ∩ {y = 0}) with x = r_k. For a triangle that is not in the plane
// the slice is a segment (or a point) spanned by its vertices with y = 0 and the points where its
// edges cross y = 0 strictly; there are never more than two of them. Along that segment z is
// linear in x, so every r_k in the segment's closed x-range gets z by interpolation, and a vertical
// segment gives both end z. A triangle lying in the plane contributes its three edges. Each
// triangle only visits the r_k inside its own x-range: O(faces + hits) instead of O(rays x faces).
//
// No ray is lost to round-off at shared vertices and edges: a vertex on the plane enters as its
// exact coordinates, the crossing point of an edge is computed from its endpoints in a fixed
// order (lower vertex index first), so neighbouring triangles see bit-identical slice endpoints,
// and the membership test r_k in [x_a, x_b] is inclusive and uses the very r_k that is stored.
// The slices of a closed mesh form closed polylines, so every r_k in their x-projection lies in
// at least one closed segment. A ray through a shared vertex or edge is counted by several
// triangles, which the min/max absorbs.
class RaySlab {
public:
    RaySlab(double radius, int rays)
        : radius_(radius), rays_(rays), scale_((rays - 1) / radius),
          lo_(static_cast<std::size_t>(rays), std::numeric_limits<double>::infinity()),
          hi_(static_cast<std::size_t>(rays), -std::numeric_limits<double>::infinity()) {}

    /// r_k = k/(rays-1) * radius (docs/FORWARD_MODEL.md, equilibrium: ray k of the profile), the one expression used everywhere.
    double r(int k) const { return static_cast<double>(k) / (rays_ - 1) * radius_; }

    /// Records the slice segment (xa, za)-(xb, zb) of one triangle.
    void addSegment(double xa, double za, double xb, double zb) {
        if (xa > xb) {
            std::swap(xa, xb);
            std::swap(za, zb);
        }
        if (xb < 0.0 || xa > radius_) return;
        // Candidate indices with one index of slack on each side; the exact test is below.
        const int kLo = static_cast<int>(std::max(0.0, std::floor(xa * scale_) - 1.0));
        const int kHi = static_cast<int>(std::min<double>(rays_ - 1, std::ceil(xb * scale_) + 1.0));
        for (int k = kLo; k <= kHi; ++k) {
            const double rk = r(k);
            if (rk < xa || rk > xb) continue;
            if (xb > xa) {
                record(k, za + (rk - xa) / (xb - xa) * (zb - za));  // (rk - xa) <= (xb - xa): t in [0, 1]
            } else {
                record(k, za);
                record(k, zb);
            }
        }
    }

    ThicknessProfile profile() const {
        ThicknessProfile p;
        for (int k = 0; k < rays_; ++k) {
            const auto i = static_cast<std::size_t>(k);
            if (lo_[i] > hi_[i]) continue;  // missed
            p.r.push_back(r(k));
            p.zLow.push_back(lo_[i]);
            p.zHigh.push_back(hi_[i]);
        }
        return p;
    }

private:
    void record(int k, double z) {
        const auto i = static_cast<std::size_t>(k);
        lo_[i] = std::min(lo_[i], z);
        hi_[i] = std::max(hi_[i], z);
    }

    double radius_;
    int rays_;
    double scale_;
    std::vector<double> lo_, hi_;
};

int sign(double y) { return (y > 0.0) - (y < 0.0); }

}  // namespace

Eigen::Vector3d sortedExtents(const Vertices& X) {
    if (X.cols() == 0) throw InputError("observables: the mesh has no vertices");
    if (!X.allFinite()) throw NumericalError("observables: non-finite vertex positions");
    Eigen::Vector3d e = extents(alignPrincipalAxes(X));
    std::sort(e.data(), e.data() + 3, std::greater<>());
    return e;
}

ThicknessProfile thicknessProfile(const Vertices& alignedX, const Faces& F, double radius, int rays) {
    if (rays < 2) throw InputError(fmt::format("thicknessProfile: rays = {} must be >= 2", rays));
    if (!(radius > 0.0) || !std::isfinite(radius))
        throw InputError(fmt::format("thicknessProfile: radius = {} must be positive and finite", radius));
    if (F.cols() > 0 && (F.minCoeff() < 0 || F.maxCoeff() >= alignedX.cols()))
        throw InputError("thicknessProfile: face index out of range");
    if (!alignedX.allFinite()) throw NumericalError("thicknessProfile: non-finite vertex positions");
    RaySlab slab(radius, rays);
    for (Eigen::Index f = 0; f < F.cols(); ++f) {
        const std::array<int, 3> id = {F(0, f), F(1, f), F(2, f)};
        std::array<int, 3> s{};
        for (int a = 0; a < 3; ++a) s[a] = sign(alignedX(1, id[a]));
        const int sMin = std::min({s[0], s[1], s[2]}), sMax = std::max({s[0], s[1], s[2]});
        if (sMin > 0 || sMax < 0) continue;  // entirely on one side of y = 0
        if (sMin == 0 && sMax == 0) {        // triangle in the plane: its slice is itself
            for (int a = 0; a < 3; ++a) {
                const int i = id[a], j = id[(a + 1) % 3];
                slab.addSegment(alignedX(0, i), alignedX(2, i), alignedX(0, j), alignedX(2, j));
            }
            continue;
        }
        std::array<Eigen::Vector2d, 2> p;  // slice points (x, z)
        int n = 0;
        for (int a = 0; a < 3; ++a)
            if (s[a] == 0) p[n++] = {alignedX(0, id[a]), alignedX(2, id[a])};
        for (int a = 0; a < 3; ++a) {
            const int b = (a + 1) % 3;
            if (s[a] * s[b] >= 0) continue;
            const int i = std::min(id[a], id[b]), j = std::max(id[a], id[b]);  // canonical order
            const double t = alignedX(1, i) / (alignedX(1, i) - alignedX(1, j));  // y_i + t (y_j - y_i) = 0
            p[n++] = {alignedX(0, i) + t * (alignedX(0, j) - alignedX(0, i)),
                      alignedX(2, i) + t * (alignedX(2, j) - alignedX(2, i))};
        }
        // n is 1 (a vertex touching the plane) or 2 (a segment); see the class comment.
        const Eigen::Vector2d& q = p[n - 1];
        slab.addSegment(p[0].x(), p[0].y(), q.x(), q.y());
    }
    return slab.profile();
}

EquilibriumObservables equilibriumObservables(const Vertices& X, const Faces& F, ThicknessProfile* profile) {
    if (X.cols() == 0 || F.cols() == 0) throw InputError("equilibriumObservables: empty mesh");
    if (!X.allFinite()) throw NumericalError("equilibriumObservables: non-finite vertex positions");
    const Vertices A = alignPrincipalAxes(X);
    const Eigen::Vector3d E = extents(A);
    EquilibriumObservables o;
    o.D = 0.5 * (E[0] + E[1]);
    if (!(o.D > 0.0)) throw NumericalError("equilibriumObservables: degenerate mesh (zero in-plane extent)");
    ThicknessProfile p = thicknessProfile(A, F, 0.5 * o.D);
    if (p.r.empty()) throw NumericalError("equilibriumObservables: no ray along +x hit the surface");
    std::size_t kMax = 0;  // first maximiser of h
    for (std::size_t k = 0; k < p.r.size(); ++k)
        if (p.zHigh[k] - p.zLow[k] > p.zHigh[kMax] - p.zLow[kMax]) kMax = k;
    o.hmax = p.zHigh[kMax] - p.zLow[kMax];
    o.rAtHmax = p.r[kMax];
    o.hmin = o.hmax;  // min over r_k <= r*: the rays before kMax, as r_k increases with k
    for (std::size_t k = 0; k < kMax; ++k) o.hmin = std::min(o.hmin, p.zHigh[k] - p.zLow[k]);
    if (profile) *profile = std::move(p);
    return o;
}

StretchObservables stretchObservables(const Vertices& X) {
    const Eigen::Vector3d e = sortedExtents(X);
    return {e[1], e[0]};
}

double deformationIndex(const Vertices& X) {
    const Eigen::Vector3d e = sortedExtents(X);
    if (!(e[1] > 0.0)) throw NumericalError("deformationIndex: degenerate mesh (zero second extent)");
    return e[0] / e[1];
}

}  // namespace trbc
