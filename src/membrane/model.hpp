#pragma once
// A membrane model: any composition of the energy terms of MODEL.md C, evaluated together in
// one threaded sweep over the mesh (face pass, edge pass, vertex gather).
#include <Eigen/Core>
#include <optional>
#include <vector>

#include "membrane/kernels.hpp"
#include "membrane/parameters.hpp"
#include "mesh/mesh.hpp"
#include "mesh/topology.hpp"

namespace trbc {

/// Energy of each term; terms that are switched off are zero.
struct EnergyTerms {
    double bending = 0.0, ade = 0.0, lim = 0.0, area = 0.0, volume = 0.0;
    double total() const { return bending + ade + lim + area + volume; }
};

/// Per-vertex quantities of the last evaluation (for output and diagnostics).
struct VertexDiagnostics {
    Eigen::VectorXd area;           ///< A_i, one third of the adjacent face areas
    Eigen::VectorXd meanCurvature;  ///< H_i = M_i / A_i (Juelicher), 1/R on a sphere
};

class MembraneModel {
public:
    /// `faces`: connectivity of every mesh this model will see. `reference`: stress-free
    /// positions (same connectivity), required when the Lim term is on.
    MembraneModel(const Faces& faces, Eigen::Index numVertices, const MembraneParameters& params,
                  const Vertices* reference = nullptr);

    /// Total energy U(X); when `grad` is given it receives dU/dX (forces are -grad).
    /// Not re-entrant: one model per thread (it owns its scratch buffers).
    double evaluate(const Vertices& X, Vertices* grad = nullptr, EnergyTerms* terms = nullptr) const;

    /// Vertex areas and Juelicher mean curvature at X.
    VertexDiagnostics vertexDiagnostics(const Vertices& X) const;

    const MembraneParameters& parameters() const { return params_; }
    /// Replaces the moduli (same reference and connectivity).
    void setParameters(const MembraneParameters& params);
    /// Replaces the stress-free reference of the Lim term.
    void setReference(const Vertices& reference);
    const Faces& faces() const { return faces_; }
    const Topology& topology() const { return topo_; }
    Eigen::Index numVertices() const { return numVertices_; }

private:
    struct Scratch {
        Eigen::Matrix3Xd faceNormal;
        Eigen::VectorXd faceArea, faceVolume, faceEnergy;
        Eigen::VectorXd edgeLenTheta;  // l_e theta_e
        Eigen::VectorXd vertexArea, vertexH, vertexEnergy, vertexH2;  // H2: H^2 - H0^2
        Eigen::Matrix<double, 9, Eigen::Dynamic> faceGrad;
        Eigen::Matrix<double, 12, Eigen::Dynamic> edgeGrad;
    };
    void resizeScratch() const;

    Faces faces_;
    Eigen::Index numVertices_;
    Topology topo_;
    MembraneParameters params_;
    std::vector<kernels::LimReference> limRef_;
    mutable Scratch s_;
};

/// Membrane-viscosity forces (MODEL.md C.4) for velocities V at positions X:
/// f_i = -gamma sum_j [(v_i - v_j).e_ij] e_ij. Equals -Gamma(X) V, Gamma the edge-friction matrix.
Vertices membraneViscousForce(const Vertices& X, const Vertices& V, double gamma, const Topology& topo);

}  // namespace trbc
