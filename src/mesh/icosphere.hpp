#pragma once
// Icosphere discretisation (docs/MEMBRANE_MODEL.md, mesh) and the Evans-Fung biconcave map (docs/MEMBRANE_MODEL.md, Evans-Fung shape).
#include "mesh/mesh.hpp"

namespace trbc {

/// Unit icosphere after `level` 1-to-4 subdivisions: Nv = 10 4^L + 2, Nf = 20 4^L. Nested: the
/// first Nv(L-1) vertices are those of level L-1.
Mesh icosphere(int level);

/// Evans-Fung (1972) resting-cell parameters, docs/MEMBRANE_MODEL.md, Evans-Fung shape.
struct EvansFung {
    double R0 = 3.91;  // um
    double c0 = 0.207161, c1 = 2.002558, c2 = -1.122762;
};

/// Maps unit-sphere vertices (axis z) onto the Evans-Fung biconcave surface:
/// x' = R0 s_x, y' = R0 s_y, z' = R0/2 s_z (c0 + c1 (1 - s_z^2) + c2 (1 - s_z^2)^2).
Vertices evansFungMap(const Vertices& unitSphere, const EvansFung& shape = {});

/// Thickness profile of the Evans-Fung shape, h(r) = R0 sqrt(1 - rho^2)(c0 + c1 rho^2 + c2 rho^4).
double evansFungThickness(double r, const EvansFung& shape = {});

}  // namespace trbc
