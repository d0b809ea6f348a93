#pragma once
// A closed triangle mesh as plain arrays (geometry-central / libigl style): vertex positions X
// (3 x Nv) and faces F (3 x Nf, 0-based, counter-clockwise seen from outside; docs/MEMBRANE_MODEL.md, mesh).
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace trbc {

using Vertices = Eigen::Matrix3Xd;
using Faces = Eigen::Matrix3Xi;

struct Mesh {
    Vertices X;
    Faces F;

    Eigen::Index numVertices() const { return X.cols(); }
    Eigen::Index numFaces() const { return F.cols(); }
};

}  // namespace trbc
