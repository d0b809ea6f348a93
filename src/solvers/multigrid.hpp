#pragma once
// Geometric multigrid on the icosphere hierarchy (docs/MEMBRANE_MODEL.md, mesh: level l+1 is level l with every
// edge split at its midpoint, the coarse vertices keeping their indices), used as the starting
// inverse Hessian H0 of L-BFGS for the static states (docs/FORWARD_MODEL.md "Multigrid H0").
//
// The operator is the scalar stiffness model
//     P = a0 I + a1 L + a2 L^2,
// L the graph Laplacian of the mesh, applied to each Cartesian component: for a mode of
// wavenumber k on edges of length l0, L ~ (k l0)^2, so a1 = mu carries the in-plane (and tension)
// stiffness and a2 = kb / l0^2 the bending stiffness of smooth modes; a0 > 0 makes P definite on
// rigid translations. One symmetric V-cycle (forward Gauss-Seidel before the coarse correction,
// backward after, Galerkin coarse operators R A P with R = P^T, exact solve on the 12-vertex
// icosahedron) approximates P^-1 at a cost of a few sparse products, of the order of one force
// evaluation, and is symmetric positive definite as L-BFGS requires.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <optional>
#include <vector>

#include "mesh/mesh.hpp"
#include "solvers/minimize.hpp"

namespace trbc {

struct StiffnessModel {
    double a0 = 0.0, a1 = 0.0, a2 = 0.0;  ///< coefficients of I, L and L^2 (force per length)
};

/// The stiffness model of a Lim + Juelicher membrane: a1 = mu, a2 = kb / l0^2 (l0 the mean edge
/// length) and a0 = (K_alpha + mu) A_v / R_c^2, the stiffness that the in-plane moduli give a normal
/// displacement of a surface curved on the scale R_c (A_v the area per vertex). Consistent units.
StiffnessModel membraneStiffness(double Kalpha, double mu, double kb, double areaPerVertex, double meanEdgeLength,
                                 double curvatureRadius);

class IcosphereMultigrid {
public:
    /// The hierarchy for faces F, or nothing when F is not an icosphere of level >= 1
    /// (icosphere(level).F exactly) or s is not admissible (a0 > 0, a1 >= 0, a2 >= 0).
    static std::optional<IcosphereMultigrid> build(const Faces& F, const StiffnessModel& s);

    /// New coefficients on the same hierarchy (the Galerkin operators of I, L and L^2 are kept
    /// per level, so this costs a few sparse sums). Throws std::invalid_argument when s is not
    /// admissible.
    void setStiffness(const StiffnessModel& s);

    /// v <- B v with B ~ P^-1 (one V-cycle); v holds 3 coordinates per vertex.
    void apply(Eigen::VectorXd& v) const;
    /// The same on a 3 x Nv array.
    Vertices apply(const Vertices& b) const;
    /// P x (for tests).
    Vertices multiply(const Vertices& x) const;

    int levels() const { return static_cast<int>(A_.size()); }
    Eigen::Index numVertices() const { return A_.back().rows(); }

private:
    using RowMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor>;
    // Work arrays hold (x, y, z, 0) per vertex so that every stencil entry is one 4-wide
    // multiply-add.
    using Padded = Eigen::Matrix4Xd;
    void vcycle(std::size_t l) const;

    std::vector<RowMatrix> identity_, laplacian_, bilaplacian_;  ///< Galerkin R X P of I, L, L^2
    std::vector<RowMatrix> A_;                 ///< operator per level, coarsest first
    std::vector<Eigen::VectorXd> invDiag_;     ///< 1 / diag(A_l)
    std::vector<Eigen::Matrix2Xi> parents_;    ///< parents_[l]: the two coarse ends of each midpoint of level l
    Eigen::MatrixXd coarseInverse_;            ///< A_0^-1 (12 x 12)
    mutable std::vector<Padded> b_, x_, r_;    ///< per-level right-hand side, iterate, residual (apply is not reentrant)
};

/// One V-cycle of mg as the H0 of lbfgsMinimize; empty (no preconditioner) when mg is. mg must
/// outlive the result.
Preconditioner asPreconditioner(const std::optional<IcosphereMultigrid>& mg);

}  // namespace trbc
