// The linear system of one cell-flow step (flow/coupled_system.hpp): the cotangent Laplacian of
// the bending preconditioner against the exact Dirichlet energy of the coordinates, and the
// coupled solve against the area and volume rates it imposes and against the unpreconditioned
// system.
// Level 2 (162 vertices) keeps the suite fast.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "core/scratch_dir.hpp"
#include "flow/cell_flow.hpp"
#include "flow/coupled_system.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"

namespace trbc {
namespace {

using cellflow::CoupledSystem;
using cellflow::PreconditionerFactor;

// On a flat triangle the piecewise-linear interpolant of a coordinate is exact and the tangential
// gradients of x, y and z satisfy |grad x|^2 + |grad y|^2 + |grad z|^2 = 2 (the trace of the
// tangential projector), so sum_c X_c^T L X_c = 2 A for any closed triangulation. The rows of L
// sum to zero (a constant has no energy) and L is symmetric.
void expectDirichletEnergyOfTheCoordinatesIsTwiceTheArea(const Vertices& X, const Faces& F) {
    const Eigen::SparseMatrix<double> L = cellflow::cotanLaplacian(X, F);
    double energy = 0.0;
    for (int c = 0; c < 3; ++c) {
        const Eigen::VectorXd xc = X.row(c).transpose();
        energy += xc.dot(L * xc);
    }
    const double area = totalArea(X, F);
    EXPECT_NEAR(energy, 2.0 * area, 1e-12 * area);
    const Eigen::VectorXd rowSums = L * Eigen::VectorXd::Ones(X.cols());
    EXPECT_LT(rowSums.norm(), 1e-12 * L.norm());
    const Eigen::SparseMatrix<double> asymmetry = L - Eigen::SparseMatrix<double>(L.transpose());
    EXPECT_LT(asymmetry.norm(), 1e-14 * L.norm());
}

TEST(CotanLaplacian, DirichletEnergyOfTheCoordinatesIsTwiceTheArea) {
    const Mesh sphere = icosphere(2);
    expectDirichletEnergyOfTheCoordinatesIsTwiceTheArea(sphere.X, sphere.F);
    // A stretched, sheared sphere: obtuse angles and negative weights do not change the identity.
    Eigen::Matrix3d A;
    A << 3.0, 0.8, 0.0, 0.0, 1.0, 0.4, 0.0, 0.0, 0.5;
    expectDirichletEnergyOfTheCoordinatesIsTwiceTheArea(A * sphere.X, sphere.F);
}

const ShearCell& cellL2() {
    static const std::filesystem::path cache = processTemporaryDirectory("trbc_test_coupled_cache_");
    static const ShearCell c = prepareShearCell(paperTable1Cell(), 2, cache);
    return c;
}

/// One solve of the step's system at the cell's initial shape in shear, with its elastic force,
/// a prescribed area and volume rate and the Hessian weight of a BDF2 step. `dA`, `dV`: the rates
/// of the area and volume along the solution's velocity, by central differences of the geometry.
CoupledSystem::Solution solveAtRest(const CellFlowOptions& opt, double areaRate, double volumeRate, double* dA = nullptr,
                                    double* dV = nullptr) {
    const ShearCell& c = cellL2();
    FlowConditions f;
    f.etaOut = 28.9;
    f.etaIn = 10.0;
    f.shearRate = 50.0;
    const CellFlowModel m(paperTable1Cell(), f, c.faces, c.reference);
    const Vertices X = m.toInternal(c.initial);
    PreconditionerFactor factor;
    const CoupledSystem sys(m, X, 0.05, opt, factor);
    Vertices g(3, X.cols());
    sys.gradient(X, g);
    const CoupledSystem::Solution s = sys.solve(-g, areaRate, volumeRate);
    const double eps = 1e-5 / s.u.colwise().norm().maxCoeff();
    const Vertices Xp = X + eps * s.u, Xm = X - eps * s.u;
    if (dA) *dA = (totalArea(Xp, c.faces) - totalArea(Xm, c.faces)) / (2.0 * eps);
    if (dV) *dV = (enclosedVolume(Xp, c.faces) - enclosedVolume(Xm, c.faces)) / (2.0 * eps);
    return s;
}

TEST(CoupledSystem, TheSolutionMeetsItsAreaAndVolumeRatesAndDoesNotDependOnThePreconditioner) {
    CellFlowOptions tight;
    tight.gmresTolerance = 1e-10;
    tight.gmresMaxIterations = 2000;
    const double areaRate = 0.02, volumeRate = -0.03;
    double dA = 0.0, dV = 0.0;
    const CoupledSystem::Solution s = solveAtRest(tight, areaRate, volumeRate, &dA, &dV);
    ASSERT_TRUE(s.gmres.converged) << s.gmres.residual;
    EXPECT_NEAR(dA, areaRate, 1e-6);
    EXPECT_NEAR(dV, volumeRate, 1e-6);
    ASSERT_TRUE(std::isfinite(s.tension));
    const double uMax = s.u.colwise().norm().maxCoeff();
    ASSERT_GT(uMax, 0.0);

    CellFlowOptions blockDiagonal = tight, none = tight;
    blockDiagonal.eliminateMultipliers = false;
    none.preconditioner = false;
    for (const CellFlowOptions* o : {&blockDiagonal, &none}) {
        const CoupledSystem::Solution t = solveAtRest(*o, areaRate, volumeRate);
        ASSERT_TRUE(t.gmres.converged) << t.gmres.residual;
        EXPECT_LT((t.u - s.u).colwise().norm().maxCoeff(), 1e-7 * uMax);
        EXPECT_NEAR(t.tension, s.tension, 1e-7 * std::abs(s.tension) + 1e-12);
        EXPECT_NEAR(t.fluxCorrection, s.fluxCorrection, 1e-7 * uMax);
        EXPECT_LT(s.gmres.iterations, t.gmres.iterations);
    }
}

}  // namespace
}  // namespace trbc
