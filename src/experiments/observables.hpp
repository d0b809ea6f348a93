#pragma once
// Measurement primitives of the three experiments (docs/FORWARD_MODEL.md, measurements): principal-axis alignment,
// extents, the thickness profile along a radial half-line, and the observables built on them.
#include <vector>

#include "mesh/mesh.hpp"

namespace trbc {

/// One entry per ray that hit the surface; the thickness is h = zHigh - zLow.
struct ThicknessProfile {
    std::vector<double> r, zLow, zHigh;
};

/// Equilibrium profile: on a mesh already in its principal frame (z = thinnest axis), cast `rays` rays
/// parallel to z through (r_k, 0), r_k = k/(rays-1) * radius, k = 0..rays-1, exact ray-triangle
/// intersection; zLow/zHigh = min/max z over all intersection points of the ray; rays that miss
/// are dropped. Requires rays >= 2, a finite radius > 0, valid face indices (else InputError) and
/// finite positions (else NumericalError).
ThicknessProfile thicknessProfile(const Vertices& alignedX, const Faces& F, double radius, int rays = 2000);

struct EquilibriumObservables {
    double D = 0, hmin = 0, hmax = 0, rAtHmax = 0;
};
/// equilibrium: align (alignment), D = (E_x + E_y)/2, profile along +x to D/2, hmax = max_k h(r_k), r* = the
/// first r_k where it occurs, hmin = min{h(r_k): r_k <= r*} (= hmax when there is no dimple).
/// Optionally returns the profile. Throws NumericalError if no ray hits.
EquilibriumObservables equilibriumObservables(const Vertices& X, const Faces& F, ThicknessProfile* profile = nullptr);

/// alignment: align, then the three extents sorted in decreasing order (not in the order of the principal
/// axes: near a round shape the axis of largest variance need not carry the largest extent).
Eigen::Vector3d sortedExtents(const Vertices& X);

struct StretchObservables {
    double D0 = 0, D1 = 0;
};
/// stretching: align, sort the three extents decreasing: D1 (axial) = largest, D0 (transverse) = second.
StretchObservables stretchObservables(const Vertices& X);

/// relaxation: align, L = largest extent, W = second largest, deformation index z = L/W.
double deformationIndex(const Vertices& X);

}  // namespace trbc
