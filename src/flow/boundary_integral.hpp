#pragma once
// Single- and double-layer Stokes operators on a closed triangulated surface, with piecewise-
// linear (vertex-based) densities on flat triangles and collocation at the vertices.
//
//   (S f)(x_i) = int_D G(x - x_i) . f(x) dS(x)                     single layer (no 1/(8 pi mu))
//   (D u)(x_i) = PV int_D u(x) . T(x - x_i) . n(x) dS(x)           double layer, n outward
// with G, T of flow/stokes_kernels.hpp (Pozrikidis 1992, ch. 2).
//
// Quadrature (precomputed per geometry):
// * the far rule (QuadratureOptions::farRule) is a set of weighted points that every face
//   contributes to; the operators are an all-pairs sum over targets x points ("far" part,
//   threaded over targets). Default: the degree-2 rule with the corners and the centroid of each
//   face (weights 1/12 per corner, 3/4 at the centroid); a corner point is shared by the faces
//   of its star, so the sum runs over Nv + Nf points (3 Nf for the 3-point face rule). A point
//   at the target itself contributes nothing (its faces are all corrected, next items);
// * faces that touch the target vertex: the single-layer integral is done in polar (Duffy)
//   coordinates centred on the vertex, x = x_i + s (e1 + t (e2 - e1)), dS = 2 A s ds dt, where
//   s G = G(e1 + t (e2 - e1)) is smooth, so the s-integral is analytic and t uses Gauss-Legendre.
//   On a flat face through x_i the double-layer kernel vanishes identically ((x - x_i) . n = 0);
// * faces near the target (centroid closer than nearFactor x their longest edge) are integrated
//   with the symmetric farPoints rule on 4^nearSubdivisions sub-triangles;
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

/// The points of the far (all-pairs) sum.
enum class FarRule {
    /// Corners (weight 1/12 each) and centroid (3/4) of every face: degree 2 on Nv + Nf points.
    VerticesAndCentroids,
    /// The symmetric farPoints rule on every face (degree 2 on 3 Nf points at farPoints = 3):
    /// the reference for the quadrature checks of docs/flow_verification.md.
    FacePoints,
};

struct QuadratureOptions {
    FarRule farRule = FarRule::VerticesAndCentroids;
    /// Points of the symmetric triangle rule per face: 1, 3, 6 or 7. Base rule of the near faces
    /// (and the far rule with FarRule::FacePoints). The error at the default settings is that of
    /// the flat-faced geometry (O(h^2)), not of the quadrature (docs/flow_verification.md).
    int farPoints = 3;
    double nearFactor = 2.0;    ///< near face: |centroid - x_i| < nearFactor * longest edge
    int nearSubdivisions = 2;   ///< near faces use the rule on 4^k sub-triangles (k >= 0)
    int singularPoints = 8;     ///< Gauss-Legendre points in the Duffy angle on adjacent faces
    /// The far all-pairs sum of the matrix-free products in single precision: positions relative
    /// to the centroid, kernel and block sums of 256 points in float, the block sums added in
    /// double. Relative error 4e-8 to 1e-7 (docs/flow_verification.md, "Single-precision far
    /// sum"), far below the flat-face error (~4e-3), for 2.6x fewer cycles per target-point pair
    /// (eight float lanes per AVX2 instruction instead of four). The dense assembly stays in double.
    bool singlePrecisionFar = false;
};

/// A dense operator on vertex densities whose 3x3 blocks are all symmetric, as those of S and D
/// are (the kernels are a I + b d d^T and c d d^T at every point, and so are the corrections):
/// 6 doubles per block (xx, xy, xz, yy, yz, zz), row-major by target. Two thirds of the memory
/// of the full 3 Nv x 3 Nv matrix, and of the memory traffic of a product, which is what a
/// product costs at Nv ~ 10^3.
class SymmetricBlockMatrix {
public:
    SymmetricBlockMatrix() = default;
    explicit SymmetricBlockMatrix(Eigen::Index blocks);

    Eigen::Index blocks() const { return n_; }
    /// The Nv blocks of target row i, 6 doubles each.
    double* row(Eigen::Index i) { return &a_[static_cast<std::size_t>(6 * n_ * i)]; }
    const double* row(Eigen::Index i) const { return &a_[static_cast<std::size_t>(6 * n_ * i)]; }
    Eigen::Matrix3d block(Eigen::Index i, Eigen::Index j) const;
    /// Adds the symmetric matrix b (its upper triangle is read) to block (i, j).
    void addToBlock(Eigen::Index i, Eigen::Index j, const Eigen::Matrix3d& b);
    /// y = A x for x, y of 3 Nv (vertex-major, as a Matrix3Xd's storage); OpenMP over rows.
    void multiply(const double* x, double* y) const;
    Eigen::MatrixXd toDense() const;

private:
    Eigen::Index n_ = 0;
    std::vector<double> a_;
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
    /// Both at once, S f and D u, in one pass over the target-point pairs (the separations and
    /// 1 / r are shared): what one iteration of a second-kind interface solve needs.
    void layers(const Eigen::Matrix3Xd& f, const Eigen::Matrix3Xd& u, Eigen::Matrix3Xd& Sf,
                Eigen::Matrix3Xd& Du) const;

    /// Dense forms of the same operators, as symmetric blocks (48 Nv^2 bytes each): for small
    /// meshes, where one assembly and a few dozen products are cheaper than the far sums.
    SymmetricBlockMatrix assembleSingleLayerBlocks() const;
    SymmetricBlockMatrix assembleDoubleLayerBlocks() const;
    /// The same as full matrices (3 Nv x 3 Nv; row 3 i + a, column 3 j + b): 72 Nv^2 bytes each.
    Eigen::MatrixXd assembleSingleLayer() const { return assembleSingleLayerBlocks().toDense(); }
    Eigen::MatrixXd assembleDoubleLayer() const { return assembleDoubleLayerBlocks().toDense(); }

    /// Single layer at points off the surface, (S f)(y_t) = int_D G(x - y_t) . f(x) dS(x), as a
    /// dense 3 Nt x 3 Nv matrix (row 3 t + a, column 3 j + b). Faces near a target (centroid
    /// closer than nearFactor x longest edge) are split adaptively into 4 sub-triangles until
    /// the criterion holds for every piece (at most `maxDepth` times): accurate down to target
    /// distances of ~ edge / 2^maxDepth. A target on the surface itself is not allowed (use
    /// assembleSingleLayer). For the couplings between two surfaces (cell and tube wall).
    Eigen::MatrixXd assembleSingleLayerAt(const Eigen::Matrix3Xd& targets, int maxDepth = 7) const;
    /// The same into A, resized to 3 Nt x 3 Nv (its storage kept when the size is unchanged).
    void assembleSingleLayerAt(const Eigen::Matrix3Xd& targets, Eigen::MatrixXd& A, int maxDepth = 7) const;
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
    /// Number of points of the far rule (Nv + Nf by default, faces x points per face with
    /// FarRule::FacePoints).
    Eigen::Index numQuadraturePoints() const { return static_cast<Eigen::Index>(qw_.size()); }
    /// Average number of vertices with a near-field correction per target.
    double meanCorrectionsPerTarget() const;

private:
    /// Throws InputError naming `name` unless v has one column per vertex.
    void checkDensity(const Eigen::Matrix3Xd& v, const char* name) const;
    // Single-layer blocks (per corner vertex) of face f at an off-surface target, adaptive.
    void offSurfaceBlocks(const Eigen::Vector3d& x0, Eigen::Index f, int maxDepth,
                          Eigen::Matrix3d (&blocks)[3]) const;
    // Face f is near x0: its centroid closer than nearFactor x its longest edge (the far rule does
    // not resolve the kernel there). A NaN distance counts as near.
    bool isNearFace(const Eigen::Vector3d& x0, Eigen::Index f) const {
        const auto i = static_cast<std::size_t>(f);
        const double ex = faceCentroidX_[i] - x0.x(), ey = faceCentroidY_[i] - x0.y(), ez = faceCentroidZ_[i] - x0.z();
        return !(ex * ex + ey * ey + ez * ez >= faceNearReach2_[i]);
    }
    // isNearFace for every face: the centroids are kept as structure of arrays so that this loop
    // over all faces of each target vectorises.
    void markNearFaces(const Eigen::Vector3d& x0, std::vector<char>& near) const;
    // S f and / or D u (far sum plus corrections); the far loop shares 1 / r between the two.
    template <bool kSingle, bool kDouble>
    void applyLayers(const Eigen::Matrix3Xd* f, const Eigen::Matrix3Xd* u, Eigen::Matrix3Xd* Sf,
                     Eigen::Matrix3Xd* Du) const;
    void buildQuadrature();
    void buildCorrections();
    // Density at the far-rule points, linear interpolation from the vertices.
    template <class T>
    void interpolate(const Eigen::Matrix3Xd& v, std::vector<T>& vx, std::vector<T>& vy, std::vector<T>& vz) const;
    template <class T, bool kSingle, bool kDouble>
    void applyLayersIn(const Eigen::Matrix3Xd* f, const Eigen::Matrix3Xd* u, Eigen::Matrix3Xd* Sf,
                       Eigen::Matrix3Xd* Du) const;

    Mesh mesh_;
    QuadratureOptions options_;
    double area_ = 0.0, volume_ = 0.0;
    Eigen::VectorXd faceArea_, vertexArea_;
    Eigen::Matrix3Xd faceNormal_, vertexNormal_;
    // Face centroids and squared near reaches (nearFactor x longest edge)^2, structure of arrays.
    std::vector<double> faceCentroidX_, faceCentroidY_, faceCentroidZ_, faceNearReach2_;
    // Symmetric face rule (farPoints): barycentric coordinates (points x 3), weights summing to 1;
    // base of the near faces and of the off-surface operator. Its points on every face, structure
    // of arrays (face-major; position and weight A_t w_q).
    Eigen::MatrixX3d ruleBary_;
    Eigen::VectorXd ruleWeight_;
    std::vector<double> fx_, fy_, fz_, fw_;
    // Far rule: weight of each corner per face area (0 with FarRule::FacePoints), the face part
    // (barycentric coordinates and weights per face area) and the points, structure of arrays:
    // the Nv corner points first (when cornerWeight_ > 0), then the face points (face-major);
    // position, weight w and weighted normal w n (corner points: sum over the star's faces).
    double cornerWeight_ = 0.0;
    Eigen::MatrixX3d farBary_;
    Eigen::VectorXd farWeight_;
    Eigen::Index cornerPoints_ = 0;
    std::vector<double> qx_, qy_, qz_, qw_, qnx_, qny_, qnz_;
    // The same in single precision (singlePrecisionFar), positions relative to farCentre_.
    Eigen::Vector3d farCentre_ = Eigen::Vector3d::Zero();
    std::vector<float> qxf_, qyf_, qzf_, qwf_, qnxf_, qnyf_, qnzf_;
    // Near-field corrections, CSR over targets: column vertex, single-layer and double-layer
    // 3x3 blocks (column-major, 9 doubles each).
    std::vector<int> corrStart_, corrCol_;
    std::vector<double> corrS_, corrD_;
};

}  // namespace trbc
