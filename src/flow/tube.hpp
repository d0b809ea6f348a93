#pragma once
// One cell in a straight circular microtube driven by a pressure gradient (docs/FLOW_TUBE.md),
// boundary-integral method with a rigid no-slip wall.
//
// Formulation (viscosity ratio lambda = 1, as in the paper's production runs, docs/FLOW_TUBE.md).
// The total flow is Poiseuille flow in the infinite tube of radius R plus a disturbance,
//   u = u_P + u',   u_P(x) = U_c (1 - (y^2 + z^2) / R^2) e_x,   U_c = G R^2 / (4 eta),
// G = -dp/dx the pressure gradient (equivalently a uniform body force density on all the fluid,
// inside and outside the cell, as in the reference). With lambda = 1 the cell's double layer
// vanishes and u_P solves the Stokes equations everywhere in the tube, so u' is the flow of the
// membrane's traction jump Delta f in the tube: it vanishes on the wall (and far along the
// tube). Represented by single layers on the cell and on the wall W (eta = 1, internal units):
//   u'(x) = -c [ S_c Delta f - S_W q ](x),   c = 1 / (8 pi)   (= 1 / (4 pi (1 + lambda))),
// with an unknown wall density q (the disturbance wall traction). No slip u'(x_w) = 0 on the
// wall gives S_WW q = S_Wc Delta f, so at the cell
//   u' = -c (S_cc - S_cW S_WW^-1 S_Wc) Delta f,
// i.e. the free-space single layer of flow/cell_flow.hpp gains the wall part
//   W = -S_cW S_WW^-1 S_Wc    (the Schur complement of the wall unknowns),
// applied inside the GMRES operator of the cell (FlowEnvironment::wallOperator).
//
// Wall. The infinite tube is truncated to |x - x_c| <= L (x_c: the cell's centroid at the
// step's predictor) and closed by two flat end caps on which u' = 0 as well: the disturbance then
// carries no net flux (the flux far from the cell is the Poiseuille flux of G, the infinite tube
// at fixed flux), and the cell's extra pressure drop is carried by the caps. Without the caps
// the ends would open onto unbounded fluid, the disturbance could leak through them and the
// result would depend on L like a periodic box at fixed body force (a translating sphere's drag
// was off by 20-45 %). The disturbance decays along the tube like exp(-4.47 |x| / R) (slowest
// axisymmetric Stokes eigenmode of a circular tube), so a margin of ~2.5 R beyond the cell's
// ends suffices (checked in tests/flow/test_tube.cpp). Mesh: N points per ring (staggered rings,
// spacing sqrt(3)/2 of the chord: near-equilateral faces), caps with concentric rings; single
// layer with the quadrature of flow/boundary_integral.hpp. The closed wall's single layer maps
// n to zero; a rank-one term n (A n)^T removes that null space (it does not affect the cell:
// S_cW n = 0 inside). The tube is translation invariant: the wall moves with the cell, S_WW
// (3 Nw x 3 Nw) is assembled and LU-factorised once; per step only the couplings S_cW, S_Wc
// (dense, adaptive near-field quadrature for the thin film between cell and wall) are
// assembled. Periodicity along the tube (the reference's 50 um box at fixed body force) is
// replaced by the infinite tube at the Poiseuille flux of G.
//
// Wall repulsion (docs/FLOW_TUBE.md: the reference adds a short-range repulsive wall force on the
// membrane vertices). Potential E = sum_i w psi(d_i), d_i = R - sqrt(y_i^2 + z_i^2) the distance of
// vertex i from the wall, w = A0 / Nv, and for d < delta
//   psi(d) = p0 [ delta^2 (1/d - 1/delta) - 2 delta ln(delta/d) + delta - d ],
//   -psi'(d) = p0 (delta/d - 1)^2   (a pressure, zero with zero slope at d = delta, growing like
//   1/d^2 at contact), psi = 0 for d >= delta.
// It is part of the membrane energy of the time stepping (explicit force, Hessian implicit). The
// polyhedral membrane's distance to the (convex) wall is smallest at a vertex, so the vertex
// clearance is the cell's clearance. A vertex at or beyond the discrete wall (the polygon of N
// points lies inside the circle by R (1 - cos(pi / N))) stops the run: "touched the wall".
//
// Fitting the cell. A closed surface of area A inside a cylinder of radius R < sqrt(A / 4 pi)
// encloses at most the volume of the capsule of radius R (cylinder with hemispherical caps):
//   V_max(R) = R A / 2 - 2 pi R^3 / 3;
// the tube can hold the cell only if V_max(R) >= V0, i.e. R >= R_min (1.497 um for A0 = 135 um^2,
// V0 = 94 um^3). The equilibrium shape (disc plane containing the axis) is wider than a 6.6 um
// tube; it is turned into a shape that fits by an affine map x -> (a x, c y, b z) about its
// centroid, b squeezing the widest transverse direction so that every vertex keeps a clearance,
// a and c found by Newton's method so that area and volume stay exactly A0 and V0 (the Lim
// reference stays the SFS: the initial shape carries elastic stress and relaxes in the flow).
#include <Eigen/Core>
#include <Eigen/LU>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "flow/boundary_integral.hpp"
#include "flow/cell_flow.hpp"
#include "flow/stokes_solver.hpp"
#include "mesh/mesh.hpp"

namespace trbc {

/// Default local error per step (R_A) of a tube run: at 1e-3 the main run drifts off the steady
/// shape (-1.1 % in length at 40 mmHg/mm), at 6.25e-5 it keeps it to 1e-5 (docs/FLOW_TUBE.md, "Step
/// tolerance").
inline constexpr double kTubeStepTolerance = 6.25e-5;

/// Largest volume a closed surface of area A encloses inside a cylinder of radius R: the capsule
/// of radius R, R A / 2 - 2 pi R^3 / 3, for R <= sqrt(A / 4 pi); the sphere beyond.
double maxVolumeInTube(double area, double radius);
/// Smallest radius of a tube that holds a cell of area A and volume V (V_max(R_min) = V).
/// Throws InputError when V exceeds the sphere's volume for A.
double minimumTubeRadius(double area, double volume);

/// Closed, outward oriented triangulation of the cylinder y^2 + z^2 = R^2, -L <= x <= L, with flat
/// end caps: `pointsPerRing` vertices per ring, rings staggered by half a point and spaced
/// sqrt(3)/2 of the chord (adjusted so that the rings end exactly at +-L); caps with concentric
/// rings of proportionally fewer points and a centre vertex.
Mesh tubeMesh(double radius, double halfLength, int pointsPerRing);

/// The truncated, capped tube wall: wall-wall single layer assembled and LU-factorised once.
class TubeWall {
public:
    TubeWall(double radius, double halfLength, int pointsPerRing, const QuadratureOptions& quadrature = {});

    double radius() const { return radius_; }
    double halfLength() const { return halfLength_; }
    int pointsPerRing() const { return pointsPerRing_; }
    Eigen::Index numVertices() const { return ops_->numVertices(); }
    /// Operators of the wall centred at x = 0 (the wall at centre x_c is this one shifted).
    const BoundaryIntegralOperators& operators() const { return *ops_; }
    /// Inward offset of the polygonal wall from the circle at the ring points' mid-chords.
    double sagitta() const;
    double setupSeconds() const { return setupSeconds_; }

    /// Couplings between a closed surface and the wall centred at x = centre.
    struct Coupling {
        const TubeWall* wall = nullptr;
        double centre = 0.0;
        Eigen::MatrixXd Scw;  ///< single layer of the wall at the surface's vertices (3 Ns x 3 Nw)
        Eigen::MatrixXd Swc;  ///< single layer of the surface at the wall's vertices (3 Nw x 3 Ns)
        /// Wall density q = S_WW^-1 S_Wc f for a surface density f (3 x Ns).
        Vertices wallDensity(const Vertices& f) const;
        /// The walls' part of the single layer at the surface, W f = -S_cW S_WW^-1 S_Wc f.
        Vertices apply(const Vertices& f) const;
    };
    std::shared_ptr<const Coupling> couple(const BoundaryIntegralOperators& surface, double centre) const;
    /// Wall vertices for the tube centred at x = centre.
    Vertices vertices(double centre) const;
    /// q = S_WW^-1 v for a wall velocity v (3 x Nw).
    Vertices solveWall(const Vertices& v) const;
    /// S_WW^-1 B for a matrix B (3 Nw rows).
    Eigen::MatrixXd solveWallMatrix(const Eigen::MatrixXd& B) const { return lu_.solve(B); }

private:
    double radius_, halfLength_;
    int pointsPerRing_;
    std::unique_ptr<BoundaryIntegralOperators> ops_;
    Eigen::PartialPivLU<Eigen::MatrixXd> lu_;
    double setupSeconds_ = 0.0;
    /// The matrices of released couplings, reused by the next: a flow step's pair (59 MB each at
    /// level 3) would otherwise be mapped and zeroed afresh every step (9 % of a level-3 tube
    /// run's CPU time, in the kernel).
    struct SparePool {
        std::mutex mutex;
        std::vector<Eigen::MatrixXd> matrices;
    };
    std::shared_ptr<SparePool> spare_ = std::make_shared<SparePool>();
};

/// Poiseuille flow U_c (1 - (y^2 + z^2) / R^2) e_x at the points X.
Vertices poiseuilleVelocity(const Vertices& X, double radius, double centreLineSpeed);

/// Rigid body in the tube (tests, verification): first-kind equation with the walls' part,
///   U + Omega x (x_i - c) = u_P(x_i) - 1/(8 pi mu) (S + W) f,
/// null space f ~ n removed by a rank-one term, dense direct solve. `freelySuspended`: U and Omega
/// unknown, zero force and torque (lumped vertex areas); otherwise U, Omega prescribed.
RigidBodyResult solveRigidBodyInTube(const BoundaryIntegralOperators& body, const TubeWall& wall, double viscosity,
                                     double centreLineSpeed, const Eigen::Vector3d& center, bool freelySuspended,
                                     const Eigen::Vector3d& velocity = Eigen::Vector3d::Zero(),
                                     const Eigen::Vector3d& angularVelocity = Eigen::Vector3d::Zero(),
                                     double tubeCentre = 0.0);

/// Tube set-up in internal units (lengths R_A, time unit of the model, viscosity eta_out).
struct TubeSetup {
    double radius = 1.0;
    double centreLineSpeed = 0.0;  ///< U_c = G R^2 / (4 eta)
    double halfLength = 5.0;       ///< of the discretised wall
    int pointsPerRing = 24;
    double repulsionRange = 0.03;     ///< delta
    double repulsionPressure = 10.0;  ///< p0
    double vertexWeight = 0.0;        ///< w = A0 / Nv
    /// The cell must stay this far (from its centroid to its farthest vertex along x) inside the
    /// ends of the discretised wall, minus this margin (units of R).
    double endMargin = 1.0;
};

/// The tube as the cell's environment (FlowEnvironment of flow/cell_flow.hpp). Valid for a model
/// with viscosity ratio 1 only (file comment; `trbc flow tube` enforces it). Records the
/// smallest clearance and the largest distance of the centroid from the axis over the accepted
/// states.
class TubeEnvironment : public FlowEnvironment {
public:
    TubeEnvironment(const TubeSetup& setup, const QuadratureOptions& quadrature = {});
    Vertices background(const Vertices& X) const override;
    void addExternalGradient(const Vertices& X, Vertices& g) const override;
    DensityMap wallOperator(const Vertices& Xs, const BoundaryIntegralOperators& cellOperators) const override;
    std::string inadmissible(const Vertices& X) const override;

    const TubeSetup& setup() const { return setup_; }
    const TubeWall& wall() const { return wall_; }
    /// Smallest vertex clearance to the (circular) wall seen in inadmissible(), internal units.
    double minClearance() const { return minClearance_; }
    double maxOffAxis() const { return maxOffAxis_; }
    /// Starts the two records above afresh (between the stages of a run).
    void resetRecords() const;
    std::vector<double> records() const override { return {minClearance_, maxOffAxis_}; }
    void restoreRecords(const std::vector<double>& r) const override;
    /// Repulsion energy of the vertices (test of the gradient).
    double repulsionEnergy(const Vertices& X) const;

private:
    TubeSetup setup_;
    TubeWall wall_;
    mutable double minClearance_, maxOffAxis_ = 0.0;
};

/// Vertex clearance R - max_i sqrt(y_i^2 + z_i^2).
double wallClearance(const Vertices& X, double radius);

/// The affine fit of the file comment: returns X unchanged when every vertex already keeps
/// `clearance` from the wall, otherwise (a x, c y, b z) about the centroid (centred on the axis)
/// with area A0 and volume V0 (lengths in um). Throws NumericalError when no such shape is found.
Vertices fitIntoTube(const Vertices& X, const Faces& F, double radius, double clearance, double A0, double V0);

/// Observables of docs/FLOW_TUBE.md from frames at times t (any consistent units).
struct TubeObservables {
    double length = 0.0;      ///< extent along x, mean over the second half of the frames
    double widthY = 0.0;      ///< extent along y, same window
    double widthZ = 0.0;      ///< extent along z, same window
    double velocity = 0.0;    ///< slope of the centroid x(t), least squares over the last eighth
    /// Plateau checks: relative change of the length between the 3rd and the 4th quarter of the
    /// record, and of the velocity between the 7th and the last eighth.
    double lengthChange = 0.0, velocityChange = 0.0;
    double maxOffAxis = 0.0;  ///< largest distance of the centroid from the axis over the frames
    /// Path of the fastest vertex in the co-moving frame over the averaging window (the sum over
    /// consecutive frames of the largest vertex displacement relative to the centroid), and the
    /// centroid's travel over that window: their ratio bounds the membrane's speed relative to the
    /// cell (a tank-treading membrane: of order 0.1-1). A ratio ~0 means the membrane is at rest in
    /// the co-moving frame: then the membrane-viscosity force, which depends on relative vertex
    /// velocities only (docs/MEMBRANE_MODEL.md, membrane viscosity), vanishes in the steady state, and that state does not
    /// depend on eta_m.
    double cellFrameMotion = 0.0, travel = 0.0;
    std::size_t framesUsed = 0;
};
/// True when the shape has settled: over the frames in [t_last - span, t_last] the extents along x
/// (length), y and z (widths) vary by less than `tolerance` relative (max - min over mean). False
/// until the record covers `span`.
bool tubeShapeSettled(const std::vector<double>& t, const std::vector<Vertices>& frames, double span,
                      double tolerance);

/// Throws InputError for fewer than 16 frames or inconsistent sizes.
TubeObservables analyzeTubeFrames(const std::vector<double>& t, const std::vector<Vertices>& frames);

}  // namespace trbc
