#include <fmt/format.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "core/error.hpp"
#include "flow/quadrature_rules.hpp"

namespace trbc::bie {
namespace {
using Eigen::Index;
constexpr double kPi = std::numbers::pi;
}  // namespace

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

}  // namespace trbc::bie
