#pragma once
// The linear system of one linearly implicit step of the cell-flow integrator (flow/cell_flow.cpp),
// its preconditioner and the thermal noise of a step. Internal to the flow layer.
#include <Eigen/Dense>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <vector>

#include "core/error.hpp"
#include "flow/boundary_integral.hpp"
#include "flow/cell_flow.hpp"
#include "flow/sparse_ordering.hpp"
#include "solvers/gmres.hpp"

namespace trbc::cellflow {

using Eigen::Index;
using Eigen::VectorXd;

/// The cotangent Laplacian as a stiffness, w^T L w = sum over edges of (cot a + cot b) / 2
/// (w_i - w_j)^2, a and b the angles opposite the edge (symmetric; semidefinite unless a pair of
/// obtuse angles makes a weight negative; L M^-1 L is semidefinite either way).
Eigen::SparseMatrix<double> cotanLaplacian(const Vertices& X, const Faces& F);

/// A sparse LDL^T factor kept over the steps of a run. Its pattern is the same at every step, so
/// the fill-reducing ordering and the symbolic analysis are done once and each step refactorises
/// the values only. The ordering is METIS's nested dissection: on a closed surface mesh it leaves
/// less fill than AMD (level 4: 647k against 733k entries in L, 0.70x the factorisation time and
/// 0.82x a solve; docs/PERFORMANCE_FLOW.md). A different pattern (another mesh) is analysed afresh.
class SparseFactor {
public:
    void factorize(const Eigen::SparseMatrix<double>& K) {
        if (!samePattern(K)) {
            ldlt_.analyzePattern(K);
            outer_.assign(K.outerIndexPtr(), K.outerIndexPtr() + K.outerSize() + 1);
            inner_.assign(K.innerIndexPtr(), K.innerIndexPtr() + K.nonZeros());
        }
        ldlt_.factorize(K);
        if (ldlt_.info() != Eigen::Success) throw NumericalError("cell flow: the preconditioner factorisation failed");
    }
    VectorXd solve(const VectorXd& b) const { return ldlt_.solve(b); }

private:
    bool samePattern(const Eigen::SparseMatrix<double>& K) const {
        return K.isCompressed() && std::ssize(outer_) == K.outerSize() + 1 && std::ssize(inner_) == K.nonZeros() &&
               std::equal(outer_.begin(), outer_.end(), K.outerIndexPtr()) &&
               std::equal(inner_.begin(), inner_.end(), K.innerIndexPtr());
    }
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, SerialMetisOrdering<int>> ldlt_;
    std::vector<int> outer_, inner_;
};

/// The preconditioner's factors: the velocity block's matrix K1 = M B_s^-1 / (s c) + Gamma
/// (s = CellFlowOptions::preconditionerScale) on the vertex-edge graph in 3x3 blocks, and, at
/// steps stiff in bending, the normal components' scalar matrix N^T K1 N + Q on the two-ring graph
/// (Q = alpha kb L M^-1 L, the bending stiffness).
struct PreconditionerFactor {
    SparseFactor velocity, normal;
};

/// The coupled linear system of one (linearly implicit) step, frozen at the state Xs. Unknowns:
/// the membrane velocity u, the membrane tension tau (multiplier of the exact global area
/// constraint, force -tau dA/dx) and a uniform normal velocity q (flux correction):
///   u - k D u + c S M^-1 ((Gamma + alpha H) u + tau g) - q n = 2/(1+lambda) u_inf + c S M^-1 F_exp,
///   g . u = area rate,  dV/dx . u = volume rate,      g = dA/dx at Xs,
/// (the two scalar rows and columns scaled to unit norm), H u by central differences of the
/// membrane gradient. In block form [A_uu B; C 0] (x_u; x_m) with B the columns of the two
/// multipliers (tension, flux) and C the two constraint rows. Right preconditioner: the exact
/// inverse of [P B; C 0], with P = I + c B_s M^-1 Gamma for A_uu, B_s the 3x3 self-blocks of S
/// (a local approximation of the single layer):
///   P^-1 = (M B_s^-1 / c + Gamma)^-1 M B_s^-1 / c, a sparse SPD solve (Cholesky), then
///   y_m = (C P^-1 B)^-1 (C P^-1 r_u - r_m),  y_u = P^-1 r_u - P^-1 B y_m
/// (P^-1 B and the 2 x 2 Schur complement once per step). At steps stiff in bending (low
/// capillary number, small FvK) P also takes the implicit bending stiffness, through a correction
/// of the normal components (velocityPreconditioner). Eliminating the multipliers removes
/// the eigenvalues near zero and off the real axis that the block-diagonal form diag(P^-1, I)
/// leaves: 37 % fewer iterations at level 3 (docs/FLOW_SOLVER.md, "Preconditioner").
class CoupledSystem {
public:
    CoupledSystem(const CellFlowModel& model, const Vertices& Xs, double alpha, const CellFlowOptions& opt,
                  PreconditionerFactor& factor, const FlowEnvironment* env = nullptr);

    const BoundaryIntegralOperators& operators() const { return ops_; }
    double area() const { return area_; }
    double volume() const { return volume_; }
    const Vertices& areaGradient() const { return areaGradient_; }
    const Vertices& volumeGradient() const { return volumeGradient_; }

    /// Gradient of the membrane energy plus the environment's external potential at X.
    void gradient(const Vertices& X, Vertices& g) const;

    /// H v (Hessian of the membrane energy, and of the external potential, at Xs times v),
    /// central differences.
    Vertices hessianTimes(const Vertices& v) const;

    struct Solution {
        Vertices u;
        double tension = 0.0;
        double fluxCorrection = 0.0;  ///< uniform normal velocity added to conserve the volume
        GmresResult gmres;
    };

    /// Solves for u and tau with the explicit nodal force Fexp and the prescribed rate of
    /// area change g . u = areaRate and volume change dV/dx . u = volumeRate; GMRES starts from zero.
    /// `extraVelocity` (optional) is added to the right-hand side's velocity (the thermal noise).
    Solution solve(const Vertices& Fexp, double areaRate, double volumeRate, const Vertices* extraVelocity = nullptr) const;

    /// The fluid's mobility of nodal forces, M_lambda F = (I - k D)^-1 c S M^-1 F (GMRES for
    /// lambda != 1, its iterations added to `iterations`).
    Vertices mobility(const Vertices& F, double tolerance, long& iterations) const;
    /// (I - k D) w: a velocity w of the mobility M_lambda as it enters the system's right-hand side.
    Vertices secondKind(const Vertices& w) const { return k_ == 0.0 ? w : Vertices(w - k_ * doubleLayer(w)); }

private:
    Vertices doubleLayer(const Vertices& u) const;
    /// P^-1 r for the velocity block.
    VectorXd velocityPreconditioner(Eigen::Ref<const VectorXd> r) const;
    /// The two scalar rows of the system applied to a velocity: (g . u / |g|, dV/dx . u / |dV/dx|).
    Eigen::Vector2d constraintRows(Eigen::Ref<const VectorXd> u) const;
    Vertices single(const Vertices& f) const;
    /// S f and, unless k = 0 (lambda = 1), D u: dense products or one fused matrix-free pass.
    void layers(const Vertices& f, const Vertices& u, Vertices& Sf, Vertices& Du) const;
    /// Nodal force of the implicit terms, -(Gamma u + alpha H u).
    Vertices implicitForce(const Vertices& u) const;
    /// c S M^-1 F: the velocity induced by nodal membrane forces F (S plus the walls' part W).
    Vertices forceVelocity(const Vertices& F) const;

    /// Self-block of the single layer at vertex i: from the dense matrix, or the integral over a
    /// flat disc of the star's area with a hat density, pi rho (3/2 I - 1/2 n n^T).
    Eigen::Matrix3d selfBlock(Index i) const;

    void buildPreconditioner();

    /// N^T Kp N + the bending stiffness, N the unit vertex normals.
    void factorizeNormal(const Eigen::SparseMatrix<double>& Kp);

    const CellFlowModel& model_;
    Vertices Xs_;
    double alpha_;
    const CellFlowOptions& opt_;
    const FlowEnvironment* env_;
    PreconditionerFactor& precFactor_;
    BoundaryIntegralOperators ops_;
    FlowEnvironment::DensityMap wall_;
    double c_ = 0.0, k_ = 0.0;
    VectorXd invArea_;
    bool dense_ = false;
    SymmetricBlockMatrix Sd_, Dd_;
    mutable Vertices gp_, gm_;
    double area_ = 0.0, volume_ = 0.0, gNorm_ = 1.0, vNorm_ = 1.0, wNorm_ = 1.0;
    Vertices areaGradient_, volumeGradient_, w_, normals_;
    std::vector<Eigen::Matrix3d> precBlocks_;
    bool eliminateMultipliers_ = false;
    bool bending_ = false;               ///< the bending stiffness in the preconditioner at this step
    Eigen::SparseMatrix<double> bendingL_;  ///< alpha kb L M^-1 L
    Vertices unitNormals_;
    bool areaConstrained_ = true;
    Eigen::MatrixX2d precB_;  ///< P^-1 B
    Eigen::PartialPivLU<Eigen::Matrix2d> schurLu_;
};

/// The two noises of a thermal step h at the state of `sys` (ThermalOptions): the fluid's velocity
/// w = sqrt(2 kT / h) M_lambda^(1/2) xi as it enters the right-hand side, (I - k D) w, and the
/// membrane-viscosity force f_Gamma = sqrt(2 kT gamma / h) sum_e xi_e d_e on the edges' ends.
struct ThermalNoise {
    Vertices velocity, force;
};
ThermalNoise thermalNoise(const CoupledSystem& sys, const CellFlowModel& model, const Vertices& X, double h,
                          const ThermalOptions& th, long stepIndex, CellFlowResult& res);

}  // namespace trbc::cellflow
