#include "mesh/validate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <map>
#include <numeric>
#include <vector>

#include "core/error.hpp"
#include "mesh/geometry.hpp"

namespace trbc {
namespace {

class Reporter {
public:
    explicit Reporter(const MeshSource* s) : s_(s) {}

    std::string where(int face) const {
        if (s_ && face >= 0 && face < static_cast<int>(s_->faceLine.size()))
            return fmt::format("{}:{}: face {}", s_->path, s_->faceLine[face], face);
        return fmt::format("mesh: face {}", face);
    }
    std::string faceRef(int face) const {
        if (s_ && face >= 0 && face < static_cast<int>(s_->faceLine.size()))
            return fmt::format("face {} (line {})", face, s_->faceLine[face]);
        return fmt::format("face {}", face);
    }
    std::string file() const { return s_ ? s_->path : std::string("mesh"); }
    std::string vertex(int v) const {
        if (s_ && v >= 0 && v < static_cast<int>(s_->vertexLine.size()))
            return fmt::format("{}:{}: vertex {}", s_->path, s_->vertexLine[v], v);
        return fmt::format("mesh: vertex {}", v);
    }

private:
    const MeshSource* s_;
};

int findRoot(std::vector<int>& parent, int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
}

}  // namespace

void validateClosedManifold(const Mesh& mesh, const MeshSource* source) {
    const Reporter rep(source);
    const auto nv = static_cast<int>(mesh.numVertices());
    const auto nf = static_cast<int>(mesh.numFaces());
    if (nv < 4 || nf < 4)
        throw InputError(fmt::format("{}: a closed triangle mesh needs at least 4 vertices and 4 faces "
                                     "(has {} and {})", rep.file(), nv, nf));
    for (int i = 0; i < nv; ++i)
        if (!mesh.X.col(i).allFinite())
            throw InputError(fmt::format("{} has a NaN/Inf coordinate", rep.vertex(i)));

    // Degenerate faces: repeated indices or (numerically) zero area relative to the mesh size.
    const double extent = (mesh.X.rowwise().maxCoeff() - mesh.X.rowwise().minCoeff()).norm();
    const double minArea = 1e-14 * extent * extent;
    for (int f = 0; f < nf; ++f) {
        const int i = mesh.F(0, f), j = mesh.F(1, f), k = mesh.F(2, f);
        for (int idx : {i, j, k})
            if (idx < 0 || idx >= nv)
                throw InputError(fmt::format("{} has vertex index {} out of range [0, {}]", rep.where(f),
                                             idx, nv - 1));
        if (i == j || j == k || k == i)
            throw InputError(fmt::format("{} ({} {} {}) is degenerate: it repeats a vertex", rep.where(f),
                                         i, j, k));
        const double area = 0.5 * (mesh.X.col(j) - mesh.X.col(i)).cross(mesh.X.col(k) - mesh.X.col(i)).norm();
        if (!(area > minArea))
            throw InputError(fmt::format("{} ({} {} {}) is degenerate: its area is {:.3g} (collinear or "
                                         "coincident vertices)", rep.where(f), i, j, k, area));
    }

    // Duplicate faces (same vertex set, whatever the order).
    {
        std::map<std::array<int, 3>, int> seen;
        for (int f = 0; f < nf; ++f) {
            std::array<int, 3> key{mesh.F(0, f), mesh.F(1, f), mesh.F(2, f)};
            std::sort(key.begin(), key.end());
            auto [it, inserted] = seen.emplace(key, f);
            if (!inserted)
                throw InputError(fmt::format("{} ({} {} {}) duplicates {}", rep.where(f), mesh.F(0, f),
                                             mesh.F(1, f), mesh.F(2, f), rep.faceRef(it->second)));
        }
    }

    // Undirected edge -> faces using it, with the direction each face traverses it.
    struct Use {
        int face;
        bool forward;  // face traverses min -> max
    };
    std::map<std::pair<int, int>, std::vector<Use>> edgeUses;
    for (int f = 0; f < nf; ++f)
        for (int k = 0; k < 3; ++k) {
            const int a = mesh.F(k, f), b = mesh.F((k + 1) % 3, f);
            edgeUses[{std::min(a, b), std::max(a, b)}].push_back({f, a < b});
        }
    for (const auto& [edge, uses] : edgeUses) {
        const auto [a, b] = edge;
        if (uses.size() == 1)
            throw InputError(fmt::format("{}: edge ({}, {}) belongs to this face only: the surface has an "
                                         "open boundary (a hole); trbc needs a closed surface",
                                         rep.where(uses[0].face), a, b));
        if (uses.size() > 2) {
            std::string list;
            for (const auto& u : uses) list += (list.empty() ? "" : ", ") + rep.faceRef(u.face);
            throw InputError(fmt::format("{}: non-manifold edge ({}, {}) shared by {} faces: {}",
                                         rep.where(uses[0].face), a, b, uses.size(), list));
        }
        if (uses[0].forward == uses[1].forward)
            throw InputError(fmt::format("{}: inconsistent orientation: this face and {} traverse edge "
                                         "({}, {}) in the same direction; faces must all be "
                                         "counter-clockwise seen from outside",
                                         rep.where(uses[1].face), rep.faceRef(uses[0].face), a, b));
    }

    // Isolated vertices, connected components and genus.
    std::vector<int> used(nv, 0), parent(nv);
    std::iota(parent.begin(), parent.end(), 0);
    for (int f = 0; f < nf; ++f)
        for (int k = 0; k < 3; ++k) {
            used[mesh.F(k, f)] = 1;
            const int r1 = findRoot(parent, mesh.F(k, f)), r2 = findRoot(parent, mesh.F((k + 1) % 3, f));
            if (r1 != r2) parent[r1] = r2;
        }
    for (int i = 0; i < nv; ++i)
        if (!used[i]) throw InputError(fmt::format("{} belongs to no face (isolated vertex)", rep.vertex(i)));
    int components = 0;
    for (int i = 0; i < nv; ++i) components += findRoot(parent, i) == i;
    if (components != 1)
        throw InputError(fmt::format("{}: the mesh has {} disconnected pieces; trbc needs one closed surface",
                                     rep.file(), components));
    const int ne = static_cast<int>(edgeUses.size());
    const int euler = nv - ne + nf;
    if (euler != 2) {
        const std::string kind = (euler < 2 && euler % 2 == 0)
                                     ? fmt::format("the surface has genus {}", (2 - euler) / 2)
                                     : std::string("the surface is not a closed manifold (pinched vertex?)");
        throw InputError(fmt::format("{}: {} (Euler characteristic V - E + F = {} - {} + {} = {}); trbc "
                                     "needs a closed genus-0 surface (V - E + F = 2)",
                                     rep.file(), kind, nv, ne, nf, euler));
    }
    // Non-manifold vertices: the faces around each vertex must form a single fan. With every edge
    // shared by exactly two faces, V - E + F = 2 and one component, a pinched vertex would lower the
    // Euler characteristic, so it is already caught above.

    const double volume = enclosedVolume(mesh.X, mesh.F);
    if (!(volume > 0))
        throw InputError(fmt::format("{}: faces are oriented inwards (signed volume {:.6g} <= 0); faces must "
                                     "be counter-clockwise seen from outside (reverse every face)",
                                     rep.file(), volume));
}

void validateSameConnectivity(const Mesh& mesh, const Mesh& reference, const std::string& what) {
    if (reference.numVertices() != mesh.numVertices() || reference.numFaces() != mesh.numFaces())
        throw InputError(fmt::format("{}: has {} vertices and {} faces but the mesh has {} and {}; the "
                                     "stress-free mesh needs the same connectivity", what,
                                     reference.numVertices(), reference.numFaces(), mesh.numVertices(),
                                     mesh.numFaces()));
    for (Eigen::Index f = 0; f < mesh.numFaces(); ++f)
        if (reference.F.col(f) != mesh.F.col(f))
            throw InputError(fmt::format("{}: face {} is ({} {} {}) but the mesh's face {} is ({} {} {}); the "
                                         "stress-free mesh needs the same face list", what, f,
                                         reference.F(0, f), reference.F(1, f), reference.F(2, f), f,
                                         mesh.F(0, f), mesh.F(1, f), mesh.F(2, f)));
}

}  // namespace trbc
