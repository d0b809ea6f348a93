#include "mesh/icosphere.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdint>
#include <unordered_map>

#include "core/error.hpp"

namespace trbc {

Mesh icosphere(int level) {
    if (level < 0 || level > 8)
        throw InputError(fmt::format("icosphere level {} out of range [0, 8]", level));
    const double a = 0.850650808352039932, b = 0.525731112119133606;  // unit circumradius
    std::vector<Eigen::Vector3d> v = {
        {0, a, b},  {0, a, -b},  {0, -a, b},  {0, -a, -b}, {b, 0, a},  {b, 0, -a},
        {-b, 0, a}, {-b, 0, -a}, {a, b, 0},   {a, -b, 0},  {-a, b, 0}, {-a, -b, 0}};
    // The 20 faces are the triples of mutually adjacent vertices (edge length 2b).
    std::vector<Eigen::Vector3i> f;
    const double edge2 = 4 * b * b;
    auto adjacent = [&](int i, int j) { return std::abs((v[i] - v[j]).squaredNorm() - edge2) < 1e-9; };
    for (int i = 0; i < 12; ++i)
        for (int j = i + 1; j < 12; ++j)
            for (int k = j + 1; k < 12; ++k)
                if (adjacent(i, j) && adjacent(j, k) && adjacent(i, k)) {
                    const bool outward = (v[j] - v[i]).cross(v[k] - v[i]).dot(v[i] + v[j] + v[k]) > 0;
                    f.push_back(outward ? Eigen::Vector3i(i, j, k) : Eigen::Vector3i(i, k, j));
                }

    for (int l = 0; l < level; ++l) {
        std::unordered_map<std::uint64_t, int> midpoint;
        auto mid = [&](int i, int j) {
            const std::uint64_t key = (static_cast<std::uint64_t>(std::min(i, j)) << 32) |
                                      static_cast<std::uint32_t>(std::max(i, j));
            auto [it, inserted] = midpoint.emplace(key, static_cast<int>(v.size()));
            if (inserted) v.push_back((v[i] + v[j]).normalized());
            return it->second;
        };
        std::vector<Eigen::Vector3i> next;
        next.reserve(4 * f.size());
        for (const auto& t : f) {
            const int ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
            next.emplace_back(t[0], ab, ca);
            next.emplace_back(t[1], bc, ab);
            next.emplace_back(t[2], ca, bc);
            next.emplace_back(ab, bc, ca);
        }
        f.swap(next);
    }
    Mesh m;
    m.X.resize(3, static_cast<Eigen::Index>(v.size()));
    m.F.resize(3, static_cast<Eigen::Index>(f.size()));
    for (std::size_t i = 0; i < v.size(); ++i) m.X.col(i) = v[i];
    for (std::size_t i = 0; i < f.size(); ++i) m.F.col(i) = f[i];
    return m;
}

Vertices evansFungMap(const Vertices& s, const EvansFung& p) {
    Vertices y(3, s.cols());
    for (Eigen::Index i = 0; i < s.cols(); ++i) {
        const double z = s(2, i), q = 1.0 - z * z;
        y(0, i) = p.R0 * s(0, i);
        y(1, i) = p.R0 * s(1, i);
        y(2, i) = 0.5 * p.R0 * z * (p.c0 + p.c1 * q + p.c2 * q * q);
    }
    return y;
}

double evansFungThickness(double r, const EvansFung& p) {
    const double rho2 = (r / p.R0) * (r / p.R0);
    if (rho2 >= 1.0) return 0.0;
    return p.R0 * std::sqrt(1.0 - rho2) * (p.c0 + p.c1 * rho2 + p.c2 * rho2 * rho2);
}

}  // namespace trbc
