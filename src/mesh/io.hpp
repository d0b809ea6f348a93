#pragma once
// Mesh files: OFF in and out (docs/MEMBRANE_MODEL.md, mesh); PLY and legacy VTK out with per-vertex fields
// (force, mean curvature, vertex area, ...) for ParaView, and back in as trbc writes them.
#include <string>
#include <vector>

#include "mesh/mesh.hpp"

namespace trbc {

/// Where each face came from, for error messages that name the line.
struct MeshSource {
    std::string path;
    std::vector<int> vertexLine;  ///< 1-based line of the first token of each vertex record
    std::vector<int> faceLine;    ///< 1-based line of the first token of each face record
};

/// Reads an ASCII OFF file and validates it (validateClosedManifold). Throws InputError
/// naming the file, line and problem.
Mesh readOff(const std::string& path);

/// Reads an ASCII triangle mesh by its extension: .off (readOff), .ply (ASCII PLY: x, y, z of the
/// vertex element, the vertex_indices list of the face element), .vtk (legacy ASCII POLYDATA with
/// POLYGONS, or UNSTRUCTURED_GRID with triangle CELLS in the 4.2 or 5.1 layout). Validated like
/// readOff; InputError naming the file and the problem (binary files, other cell types, ...).
Mesh readMesh(const std::string& path);

/// Parses an OFF file without topological validation (for tools that inspect broken meshes).
Mesh parseOff(const std::string& path, MeshSource* source = nullptr);

/// A per-vertex field: 1 row (scalar) or 3 rows (vector), one column per vertex.
struct VertexField {
    std::string name;
    Eigen::MatrixXd values;
};

void writeOff(const std::string& path, const Mesh& mesh);
void writePly(const std::string& path, const Mesh& mesh, const std::vector<VertexField>& fields = {});
void writeVtk(const std::string& path, const Mesh& mesh, const std::vector<VertexField>& fields = {});
/// Chooses the format from the extension (.off, .ply, .vtk); fields are dropped for OFF.
void writeMesh(const std::string& path, const Mesh& mesh, const std::vector<VertexField>& fields = {});

}  // namespace trbc
