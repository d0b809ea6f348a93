#pragma once
// Shared helpers for the test suite.
#include <Eigen/Core>
#include <random>
#include <string>

#include "membrane/model.hpp"
#include "mesh/mesh.hpp"

namespace trbc::test {

inline std::string dataPath(const std::string& rel) { return std::string(TRBC_TEST_DATA) + "/" + rel; }
inline std::string meshPath(const std::string& name) { return dataPath("meshes/" + name); }

/// Icosphere with every vertex moved by a uniform random offset of relative size `amplitude`
/// (times the mean edge length), fixed seed.
Mesh perturbedIcosphere(int level, double amplitude, unsigned seed);

/// Central finite-difference gradient of the model energy, step h per coordinate.
Vertices finiteDifferenceGradient(const MembraneModel& model, const Vertices& X, double h);

/// max |a - b| / max |b| over all components.
double relativeMaxError(const Vertices& a, const Vertices& b);

/// Mean edge length of a mesh.
double meanEdgeLength(const Mesh& m);

/// A random rotation matrix (fixed seed).
Eigen::Matrix3d randomRotation(unsigned seed);

}  // namespace trbc::test
