#pragma once
#include "mesh/io.hpp"
#include "mesh/mesh.hpp"

namespace trbc {

/// Checks that the mesh is a closed, consistently and outward oriented, genus-0 triangle
/// surface without degenerate or duplicate faces (docs/MEMBRANE_MODEL.md, mesh). Throws InputError whose
/// message names the file and line (when `source` is given), the face or edge, and the problem.
void validateClosedManifold(const Mesh& mesh, const MeshSource* source = nullptr);

/// Checks that `reference` can serve as the stress-free mesh of `mesh`: same vertex count and
/// the same face list.
void validateSameConnectivity(const Mesh& mesh, const Mesh& reference, const std::string& what);

}  // namespace trbc
