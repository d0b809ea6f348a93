#pragma once
// Single- and double-layer Stokes operators on a closed triangulated surface, with piecewise-
// linear (vertex-based) densities on flat triangles and collocation at the vertices.
//
//   (S f)(x_i) = int_D G(x - x_i) . f(x) dS(x)                     single layer (no 1/(8 pi mu))
//   (D u)(x_i) = PV int_D u(x) . T(x - x_i) . n(x) dS(x)           double layer, n outward
// with G, T of flow/stokes_kernels.hpp (Pozrikidis 1992, ch. 2).
//
// Quadrature (precomputed per geometry):
// * every face carries a fixed symmetric rule (QuadratureOptions::farPoints); the operators are
//   an all-pairs sum over targets x quadrature points ("far" part, threaded over targets);
// * faces that touch the target vertex: the single-layer integral is done in polar (Duffy)
//   coordinates centred on the vertex, x = x_i + s (e1 + t (e2 - e1)), dS = 2 A s ds dt, where
//   s G = G(e1 + t (e2 - e1)) is smooth, so the s-integral is analytic and t uses Gauss-Legendre.
//   On a flat face through x_i the double-layer kernel vanishes identically ((x - x_i) . n = 0);
// * faces near the target (centroid closer than nearFactor x their longest edge) are integrated
//   with the rule on 4^nearSubdivisions sub-triangles;
// * the adjacent and near faces are stored as sparse 3x3 corrections per target (accurate
//   integral minus the far-rule sum), so the far loop stays a plain all-pairs sum;
// * double layer by singularity subtraction with the identity of flow/stokes_kernels.hpp:
//   PV int u . T . n dS = int (u(x) - u(x_i)) . T . n dS + u(x_i) . PV int T . n dS
//                       = int (u(x) - u(x_i)) . T . n dS - 4 pi u(x_i),
//   exact for rigid-body motions (D maps them to -4 pi times themselves).
#include <Eigen/Core>
#include <vector>

#include "mesh/mesh.hpp"

namespace trbc {

struct QuadratureOptions {
    /// Points of the symmetric triangle rule per face: 1, 3, 6 or 7. The error at the default
    /// settings is that of the flat-faced geometry (O(h^2)), not of the quadrature
    /// (docs/flow_verification.md).
    int farPoints = 3;
    double nearFactor = 2.0;    ///< near face: |centroid - x_i| < nearFactor * longest edge
    int nearSubdivisions = 2;   ///< near faces use the rule on 4^k sub-triangles (k >= 0)
    int singularPoints = 8;     ///< Gauss-Legendre points in the Duffy angle on adjacent faces
};

class BoundaryIntegralOperators {
public:
    /// Precomputes quadrature points and near-field corrections. Throws InputError when the mesh
    /// is not a closed, outward oriented manifold or the options are out of range.
    explicit BoundaryIntegralOperators(const Mesh& mesh, const QuadratureOptions& options = {});

    Eigen::Index numVertices() const { return mesh_.numVertices(); }
    const Mesh& mesh() const { return mesh_; }
    const QuadratureOptions& options() const { return options_; }

    /// (S f)(x_i) for a vertex density f (3 x Nv). Matrix-free, OpenMP over targets.
    Eigen::Matrix3Xd singleLayer(const Eigen::Matrix3Xd& f) const;
    /// (D u)(x_i) (principal value) for a vertex density u (3 x Nv).
    Eigen::Matrix3Xd doubleLayer(const Eigen::Matrix3Xd& u) const;

    /// Dense matrices of the same operators (3 Nv x 3 Nv; row 3 i + a, column 3 j + b), for
    /// small meshes: 8 (3 Nv)^2 bytes each.
    Eigen::MatrixXd assembleSingleLayer() const;
    Eigen::MatrixXd assembleDoubleLayer() const;

    /// Single layer at points off the surface, (S f)(y_t) = int_D G(x - y_t) . f(x) dS(x), as a
    /// dense 3 Nt x 3 Nv matrix (row 3 t + a, column 3 j + b). Faces near a target (centroid
    /// closer than nearFactor x longest edge) are split adaptively into 4 sub-triangles until
    /// the criterion holds for every piece (at most `maxDepth` times): accurate down to target
    /// distances of ~ edge / 2^maxDepth. A target on the surface itself is not allowed (use
    /// assembleSingleLayer). For the couplings between two surfaces (cell and tube wall).
    Eigen::MatrixXd assembleSingleLayerAt(const Eigen::Matrix3Xd& targets, int maxDepth = 7) const;
    /// The same operator applied to a density f (3 x Nv), matrix-free.
    Eigen::Matrix3Xd singleLayerAt(const Eigen::Matrix3Xd& targets, const Eigen::Matrix3Xd& f,
                                   int maxDepth = 7) const;

    // Surface integrals of vertex densities, linear on each flat face (exact on the polyhedron).
    /// int f dS = sum_i A_i f_i (A_i: one third of the adjacent face areas).
    Eigen::Vector3d integrate(const Eigen::Matrix3Xd& f) const;
    /// int (x - c) x f dS (consistent P1 mass matrix).
    Eigen::Vector3d moment(const Eigen::Matrix3Xd& f, const Eigen::Vector3d& c) const;
    /// First moment int (x - c) f^T dS (3 x 3); its antisymmetric part is the torque, its
    /// symmetric traceless part the stresslet (consistent P1 mass matrix).
    Eigen::Matrix3d firstMoment(const Eigen::Matrix3Xd& f, const Eigen::Vector3d& c) const;
    /// int u . n dS with the face normals.
    double normalFlux(const Eigen::Matrix3Xd& u) const;
    /// Volume-averaged velocity of the enclosed fluid, (1/V) int x (u . n) dS (exact for a
    /// divergence-free interior flow; equals U for a rigid translation U).
    Eigen::Vector3d volumeMeanVelocity(const Eigen::Matrix3Xd& u) const;

    double area() const { return area_; }
    double volume() const { return volume_; }
    const Eigen::VectorXd& vertexAreas() const { return vertexArea_; }
    /// Unit vertex normals (area-weighted average of the face normals).
    const Eigen::Matrix3Xd& vertexNormals() const { return vertexNormal_; }
    const Eigen::Matrix3Xd& faceNormals() const { return faceNormal_; }
    const Eigen::VectorXd& faceAreas() const { return faceArea_; }
    /// Number of quadrature points of the far rule (faces x points per face).
    Eigen::Index numQuadraturePoints() const { return static_cast<Eigen::Index>(qw_.size()); }
    /// Average number of vertices with a near-field correction per target.
    double meanCorrectionsPerTarget() const;

private:
    // Single-layer blocks (per corner vertex) of face f at an off-surface target, adaptive.
    void offSurfaceBlocks(const Eigen::Vector3d& x0, Eigen::Index f, int maxDepth,
                          Eigen::Matrix3d (&blocks)[3]) const;
    // Face f is near x0: its centroid closer than nearFactor x its longest edge (the far rule does
    // not resolve the kernel there).
    bool isNearFace(const Eigen::Vector3d& x0, Eigen::Index f) const {
        return !((faceCentroid_.col(f) - x0).norm() >= options_.nearFactor * faceLongestEdge_[f]);
    }
    void buildQuadrature();
    void buildCorrections();
    // Density at the quadrature points, linear interpolation from the vertices.
    void interpolate(const Eigen::Matrix3Xd& v, std::vector<double>& vx, std::vector<double>& vy,
                     std::vector<double>& vz) const;

    Mesh mesh_;
    QuadratureOptions options_;
    double area_ = 0.0, volume_ = 0.0;
    Eigen::VectorXd faceArea_, vertexArea_;
    Eigen::Matrix3Xd faceNormal_, vertexNormal_;
    Eigen::Matrix3Xd faceCentroid_;
    Eigen::VectorXd faceLongestEdge_;
    // Far rule: barycentric coordinates (points x 3) and weights (sum 1) on the reference face.
    Eigen::MatrixX3d ruleBary_;
    Eigen::VectorXd ruleWeight_;
    // Quadrature points, structure of arrays: position, weight w = A_t w_q, weighted normal w n.
    std::vector<double> qx_, qy_, qz_, qw_, qnx_, qny_, qnz_;
    // Near-field corrections, CSR over targets: column vertex, single-layer and double-layer
    // 3x3 blocks (column-major, 9 doubles each).
    std::vector<int> corrStart_, corrCol_;
    std::vector<double> corrS_, corrD_;
};

}  // namespace trbc
