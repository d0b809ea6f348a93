#include "mesh/topology.hpp"

#include <cstdint>
#include <stdexcept>
#include <unordered_map>

namespace trbc {
namespace {

std::uint64_t edgeKey(int a, int b) {
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
           static_cast<std::uint32_t>(b);
}

// Builds a CSR list of items, each item touching one vertex.
void buildCsr(Eigen::Index numVertices, const std::vector<int>& vertexOfItem,
              std::vector<int>& start, std::vector<int>& items) {
    start.assign(numVertices + 1, 0);
    for (int v : vertexOfItem) ++start[v + 1];
    for (Eigen::Index i = 0; i < numVertices; ++i) start[i + 1] += start[i];
    items.assign(vertexOfItem.size(), 0);
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (std::size_t k = 0; k < vertexOfItem.size(); ++k)
        items[fill[vertexOfItem[k]]++] = static_cast<int>(k);
}

}  // namespace

Topology buildTopology(const Faces& F, Eigen::Index numVertices) {
    const Eigen::Index nf = F.cols();
    // Directed half-edge (i -> j) -> face index.
    std::unordered_map<std::uint64_t, int> halfEdgeFace;
    halfEdgeFace.reserve(static_cast<std::size_t>(3 * nf));
    for (Eigen::Index f = 0; f < nf; ++f)
        for (int k = 0; k < 3; ++k)
            halfEdgeFace.emplace(edgeKey(F(k, f), F((k + 1) % 3, f)), static_cast<int>(f));

    const Eigen::Index ne = 3 * nf / 2;
    Topology t;
    t.edges.resize(2, ne);
    t.opposite.resize(2, ne);
    t.edgeFaces.resize(2, ne);
    t.faceEdges.resize(3, nf);
    Eigen::Index e = 0;
    for (Eigen::Index f = 0; f < nf; ++f) {
        for (int k = 0; k < 3; ++k) {
            const int a = F(k, f), b = F((k + 1) % 3, f), c = F((k + 2) % 3, f);
            if (a > b) continue;  // each undirected edge once, from the face holding a -> b, a < b
            auto it = halfEdgeFace.find(edgeKey(b, a));
            if (it == halfEdgeFace.end() || e >= ne)
                throw std::logic_error("buildTopology: mesh is not a closed manifold (validate first)");
            const int g = it->second;
            int d = -1, md = -1;  // d = F(md, g)
            for (int m = 0; m < 3; ++m)
                if (F(m, g) != a && F(m, g) != b) {
                    d = F(m, g);
                    md = m;
                }
            t.edges.col(e) << a, b;
            t.opposite.col(e) << c, d;
            t.edgeFaces.col(e) << static_cast<int>(f), g;
            t.faceEdges((k + 2) % 3, f) = static_cast<int>(e);  // opposite c
            t.faceEdges(md, g) = static_cast<int>(e);              // opposite d
            ++e;
        }
    }
    if (e != ne) throw std::logic_error("buildTopology: edge count mismatch (validate first)");

    std::vector<int> cornerVertex(static_cast<std::size_t>(3 * nf));
    for (Eigen::Index f = 0; f < nf; ++f)
        for (int k = 0; k < 3; ++k) cornerVertex[3 * f + k] = F(k, f);
    buildCsr(numVertices, cornerVertex, t.vertexCornerStart, t.vertexCorners);

    // Incident edges: those where the vertex is an endpoint.
    std::vector<int> endVertex(static_cast<std::size_t>(2 * ne));
    for (Eigen::Index i = 0; i < ne; ++i) {
        endVertex[2 * i] = t.edges(0, i);
        endVertex[2 * i + 1] = t.edges(1, i);
    }
    std::vector<int> endItems;
    buildCsr(numVertices, endVertex, t.vertexEdgeStart, endItems);
    t.vertexEdgeList.resize(endItems.size());
    for (std::size_t k = 0; k < endItems.size(); ++k) t.vertexEdgeList[k] = endItems[k] / 2;
    return t;
}

}  // namespace trbc
