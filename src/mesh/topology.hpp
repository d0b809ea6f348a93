#pragma once
// Edge and adjacency structure of a closed oriented manifold mesh.
//
// Edge e = (a, b) is stored with the orientation it has in its first face (a, b, c); the
// second face is (b, a, d) (docs/MEMBRANE_MODEL.md, notation). The dihedral angle of e is defined with
// these two faces. Vertex -> face-corner and vertex -> edge lists (CSR) let force loops
// gather per-vertex sums without write conflicts, so threaded results do not depend on the
// number of threads.
#include <Eigen/Core>
#include <vector>

#include "mesh/mesh.hpp"

namespace trbc {

struct Topology {
    Eigen::Matrix2Xi edges;     ///< (a, b) per edge, oriented as in faceOfEdge(0, e)
    Eigen::Matrix2Xi opposite;  ///< (c, d): third vertex of face (a,b,c) and of face (b,a,d)
    Eigen::Matrix2Xi edgeFaces; ///< the two faces of each edge: (a,b,c) first, (b,a,d) second
    Eigen::Matrix3Xi faceEdges; ///< (m, f): the edge of face f opposite its corner m

    // CSR: corners (3*face + k) incident to vertex i are vertexCorners[vertexCornerStart[i] ..
    // vertexCornerStart[i+1]).
    std::vector<int> vertexCornerStart, vertexCorners;
    // CSR: incident edges of each vertex (the edges where the vertex is a or b).
    std::vector<int> vertexEdgeStart, vertexEdgeList;

    Eigen::Index numEdges() const { return edges.cols(); }
    int valence(int i) const { return vertexEdgeStart[i + 1] - vertexEdgeStart[i]; }
};

/// Builds the topology. Precondition: the mesh passed validateClosedManifold (mesh/validate.hpp).
Topology buildTopology(const Faces& F, Eigen::Index numVertices);

}  // namespace trbc
