#pragma once
// A membrane model: any composition of the energy terms of docs/MEMBRANE_MODEL.md, evaluated together in
// one threaded sweep over the mesh (face pass, edge pass, vertex gather).
#include <Eigen/Core>
#include <optional>
#include <vector>

#include "membrane/kernels.hpp"
#include "membrane/parameters.hpp"
#include "mesh/mesh.hpp"
#include "mesh/topology.hpp"

namespace trbc {

/// Energy of each term; terms that are switched off are zero. `capsule` is the in-plane energy of
/// the neo-Hookean or Skalak law (MembraneParameters::law), `lim` that of the Lim law.
struct EnergyTerms {
    double bending = 0.0, ade = 0.0, lim = 0.0, area = 0.0, volume = 0.0, capsule = 0.0;
    double total() const { return bending + ade + lim + area + volume + capsule; }
};

/// Per-vertex quantities of the last evaluation (for output and diagnostics).
struct VertexDiagnostics {
    Eigen::VectorXd area;           ///< A_i, one third of the adjacent face areas
    Eigen::VectorXd meanCurvature;  ///< H_i = M_i / A_i (Juelicher), 1/R on a sphere
};

class MembraneModel {
public:
    /// `faces`: connectivity of every mesh this model will see. `reference`: stress-free
    /// positions (same connectivity), required when an in-plane term (Lim or capsule law) is on.
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
    /// Replaces the stress-free reference of the in-plane term.
    void setReference(const Vertices& reference);
    const Faces& faces() const { return faces_; }
    const Topology& topology() const { return topo_; }
    Eigen::Index numVertices() const { return numVertices_; }

private:
    // Per-face, per-edge and per-vertex quantities of the last evaluation, as structures of arrays
    // (one column per quantity) so that the loops in evaluate() vectorise. Each array has kPad
    // (model.cpp) rows more than there are faces, edges or vertices; the padding of faceArea,
    // edgeLenTheta and faceGrad stays zero.
    struct Scratch {
        Eigen::Matrix<double, Eigen::Dynamic, 3> faceNormal, faceY;  // n_t; y = x_i - o
        Eigen::Matrix<double, Eigen::Dynamic, 9> faceEdge;  // (t, 3 m + c): edge opposite corner m
        Eigen::VectorXd faceArea, faceInvTwiceArea, faceVolume;  // A_t, 1/(2 A_t), V_t
        Eigen::VectorXd faceInPlaneEnergy, faceInPlaneCArea, faceInPlaneCN;  // kernels::LimFace, CapsuleFace
        Eigen::VectorXd edgeLenTheta, edgeThetaOverLen;          // l_e theta_e, theta_e / l_e
        Eigen::VectorXd vertexArea, vertexH, vertexEnergy;
        Eigen::VectorXd vertexCoefM, vertexCoefA;  // kb (H - H0), 2 kb/3 (H^2 - H0^2)
        Eigen::Matrix3Xd faceGrad;  // column m (Nf + kPad) + t: gradient at corner m of face t
    };
    void resizeScratch() const;
    kernels::LimReference limReference(Eigen::Index face) const;

    Faces faces_;
    Eigen::Index numVertices_;
    Topology topo_;
    MembraneParameters params_;
    // 64-bit copies of the index arrays that the face and edge loops read (faces_,
    // topo_.faceEdges, topo_.edgeFaces): with 32-bit indices GCC vectorises those loops eight
    // elements at a time on AVX2 (the width of the narrowest type), two registers per double, and
    // runs out of registers.
    Eigen::Matrix<Eigen::Index, 3, Eigen::Dynamic> faceVertices_, faceEdges_;
    Eigen::Matrix<Eigen::Index, 2, Eigen::Dynamic> edgeFaces_;
    // Per edge (a, b): the position in s_.faceEdge.data() of the x component of x_b - x_a, an edge
    // vector of its first face (y and z follow one and two columns further).
    Eigen::Matrix<Eigen::Index, Eigen::Dynamic, 1> edgeVector_;
    // The vertex rings as tables of fixed width ringWidth_ (the largest valence), entry (k, i) at
    // k Nv + i: the k-th face corner of vertex i (topo_.vertexCorners order) as its face and as its
    // column of s_.faceGrad, and the k-th incident edge (topo_.vertexEdgeList). Shorter rings are
    // filled up with the first padding entry (zero) of faceArea, faceGrad and edgeLenTheta. The
    // vertex loops then vectorise across vertices.
    int ringWidth_ = 0;
    std::vector<int> ringFace_, ringEdge_, ringGradColumn_;
    // Lim stress-free data per face (rows), one column per field of kernels::LimReference.
    Eigen::Matrix<double, Eigen::Dynamic, 5> limRef_;
    mutable Scratch s_;
};

/// Membrane-viscosity forces (docs/MEMBRANE_MODEL.md, membrane viscosity) for velocities V at positions X:
/// f_i = -gamma sum_j [(v_i - v_j).e_ij] e_ij. Equals -Gamma(X) V, Gamma the edge-friction matrix.
Vertices membraneViscousForce(const Vertices& X, const Vertices& V, double gamma, const Topology& topo);
/// Unit edge vectors e = (x_a - x_b) / |x_a - x_b| of the edges (a, b) of topo.
Eigen::Matrix3Xd unitEdgeVectors(const Vertices& X, const Topology& topo);
/// The same force with the edge directions given (an implicit time step keeps Gamma fixed over
/// its solve, so the directions are computed once per step).
Vertices membraneViscousForceAlong(const Eigen::Matrix3Xd& unitEdges, const Vertices& V, double gamma, const Topology& topo);

}  // namespace trbc
