#pragma once
// Geometry of a triangle mesh as free functions over plain arrays (docs/MEMBRANE_MODEL.md, mesh).
#include <Eigen/Core>
#include <vector>

#include "mesh/mesh.hpp"
#include "mesh/topology.hpp"

namespace trbc {

/// A_t = |(x_j - x_i) x (x_k - x_i)| / 2 for every face.
Eigen::VectorXd faceAreas(const Vertices& X, const Faces& F);
/// A = sum_t A_t.
double totalArea(const Vertices& X, const Faces& F);
/// V = 1/6 sum_t x_i . (x_j x x_k) (signed, positive for outward faces).
double enclosedVolume(const Vertices& X, const Faces& F);
/// v = 6 sqrt(pi) V / A^{3/2}: volume over that of the sphere with the same area.
double reducedVolume(double area, double volume);
double reducedVolume(const Vertices& X, const Faces& F);
/// V = v A^{3/2} / (6 sqrt(pi)): the volume of reduced volume v at area A.
double volumeOfReducedVolume(double reducedVolume, double area);
/// A, V and their gradients dA/dx_i = 1/2 sum_t n_t x (x_k - x_j), dV/dx_i = 1/6 sum_t x_j x x_k
/// over the faces (i, j, k) around vertex i, in one pass over the faces (the retraction of the
/// constrained minimiser calls this a few times per step).
struct AreaVolume {
    double area = 0.0, volume = 0.0;
    Vertices areaGradient, volumeGradient;
};
AreaVolume areaVolumeWithGradients(const Vertices& X, const Faces& F);
/// A and V alone (gradients left empty), same summation as areaVolumeWithGradients.
AreaVolume areaAndVolume(const Vertices& X, const Faces& F);
/// A_i = 1/3 sum of the areas of the faces around vertex i.
Eigen::VectorXd vertexAreas(const Vertices& X, const Faces& F);
/// Unweighted vertex centroid.
Eigen::Vector3d centroid(const Vertices& X);

/// Partners under the point inversion about the centroid c, x -> 2c - x: partner[i] = j with every
/// component of (x_j - c) + (x_i - c) within tol * max_k |x_k - c| (an icosphere of any level, and
/// its Evans-Fung disc, map onto themselves); empty when some vertex has none or the pairing is
/// not an involution without fixed points.
std::vector<Eigen::Index> inversionPartners(const Vertices& X, double tol = 1e-9);
/// The inversion-symmetric part of per-vertex vectors, w_i <- (w_i - w_partner[i]) / 2: the
/// gradient of an inversion-invariant energy at a symmetric shape is of this kind, and for positions
/// it is the symmetric part of the shape moved to the origin (a translation no energy sees).
void symmetrizeUnderInversion(Vertices& W, const std::vector<Eigen::Index>& partner);
/// max_i |(x_i - c) + (x_partner[i] - c)| / max_i |x_i - c|: 0 for a centrally symmetric shape.
double inversionAsymmetry(const Vertices& X, const std::vector<Eigen::Index>& partner);

/// Principal frame of the vertex cloud (docs/FORWARD_MODEL.md, measurements): rotation R whose rows are the
/// eigenvectors of the vertex covariance, by decreasing variance (x largest, z smallest), with
/// det R = +1. Aligned positions are R (x - centroid).
Eigen::Matrix3d principalAxes(const Vertices& X);
/// Vertices centred and expressed in the principal frame.
Vertices alignPrincipalAxes(const Vertices& X);
/// Bounding-box extents of the vertices along the coordinate axes.
Eigen::Vector3d extents(const Vertices& X);

/// Uniform scaling about the centroid so that the total area equals `area`.
Vertices scaleToArea(const Vertices& X, const Faces& F, double area);

/// Mean edge length l0 of the mesh.
double meanEdgeLength(const Vertices& X, const Topology& topo);

}  // namespace trbc
