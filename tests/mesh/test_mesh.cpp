// Meshes: icosphere counts and nesting, agreement with the provided sph_L*.off, the Evans-Fung
// map check values of docs/MEMBRANE_MODEL.md, Evans-Fung shape, geometry, principal axes and file round trips.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/io.hpp"
#include "core/error.hpp"
#include "mesh/topology.hpp"
#include "mesh/validate.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

TEST(Icosphere, CountsNestingAndValidity) {
    for (int level = 0; level <= 5; ++level) {
        const Mesh m = icosphere(level);
        const long p = 1L << (2 * level);
        EXPECT_EQ(m.numVertices(), 10 * p + 2);
        EXPECT_EQ(m.numFaces(), 20 * p);
        EXPECT_NO_THROW(validateClosedManifold(m));
        const Topology t = buildTopology(m.F, m.numVertices());
        EXPECT_EQ(t.numEdges(), 30 * p);
        int valence5 = 0;
        for (int i = 0; i < m.numVertices(); ++i) valence5 += t.valence(i) == 5;
        EXPECT_EQ(valence5, 12);
        EXPECT_NEAR(m.X.colwise().norm().minCoeff(), 1.0, 1e-12);
        if (level > 0) {
            const Mesh coarse = icosphere(level - 1);
            EXPECT_EQ(m.X.leftCols(coarse.numVertices()), coarse.X);
        }
    }
}

TEST(Icosphere, SameVertexSetAndAreaAsTheProvidedMeshes) {
    for (int level = 2; level <= 4; ++level) {
        const Mesh ours = icosphere(level);
        const Mesh theirs = readOff(test::meshPath("sph_L" + std::to_string(level) + ".off"));
        ASSERT_EQ(ours.numVertices(), theirs.numVertices());
        EXPECT_NEAR(totalArea(ours.X, ours.F), totalArea(theirs.X, theirs.F), 1e-5);
        for (Eigen::Index i = 0; i < theirs.numVertices(); ++i)  // every provided vertex is one of ours
            EXPECT_LT((ours.X.colwise() - theirs.X.col(i)).colwise().norm().minCoeff(), 1e-5);
    }
}

TEST(EvansFung, MapOfProvidedIcospheresGivesTheSpecCheckValues) {
    struct Row {
        const char* mesh;
        double area, volume, v;
    };
    for (const Row& r : {Row{"sph_L4.off", 133.8788, 93.8874, 0.64456}, Row{"sph_L3.off", 133.2503, 93.2800, 0.64493}}) {
        const Mesh s = readOff(test::meshPath(r.mesh));
        const Vertices X = evansFungMap(s.X);
        EXPECT_NEAR(totalArea(X, s.F), r.area, 1e-4) << r.mesh;
        EXPECT_NEAR(enclosedVolume(X, s.F), r.volume, 1e-4) << r.mesh;
        EXPECT_NEAR(reducedVolume(X, s.F), r.v, 1e-5) << r.mesh;
        const Vertices scaled = scaleToArea(X, s.F, 135.0);
        EXPECT_NEAR(totalArea(scaled, s.F), 135.0, 1e-10);
        EXPECT_NEAR(reducedVolume(scaled, s.F), r.v, 1e-5);  // scaling keeps v
    }
    EXPECT_NEAR(evansFungThickness(0.0), 3.91 * 0.207161, 1e-12);
}

TEST(Geometry, ReducedVolumeVertexAreasAndPrincipalAxes) {
    const Mesh s = icosphere(4);
    EXPECT_NEAR(reducedVolume(s.X, s.F), 0.9996, 1e-4);  // docs/FORWARD_MODEL.md, stress-free state: polyhedra stay below 1
    const double A = totalArea(s.X, s.F), V = enclosedVolume(s.X, s.F);
    EXPECT_NEAR(volumeOfReducedVolume(reducedVolume(A, V), A), V, 1e-12 * V);  // the inverse at fixed area
    EXPECT_NEAR(volumeOfReducedVolume(1.0, 4.0 * M_PI), 4.0 * M_PI / 3.0, 1e-12);  // the unit sphere
    EXPECT_NEAR(vertexAreas(s.X, s.F).sum(), totalArea(s.X, s.F), 1e-12);
    Vertices ell = s.X;
    ell.row(0) *= 1.0;
    ell.row(1) *= 3.0;
    ell.row(2) *= 2.0;
    const Vertices rotated = (test::randomRotation(3) * ell).colwise() + Eigen::Vector3d(5, -2, 1);
    const Eigen::Vector3d e = extents(alignPrincipalAxes(rotated));
    EXPECT_NEAR(e[0], 6.0, 1e-6);
    EXPECT_NEAR(e[1], 4.0, 1e-6);
    EXPECT_NEAR(e[2], 2.0, 1e-6);
    EXPECT_NEAR(principalAxes(rotated).determinant(), 1.0, 1e-12);
}

// The blocked structure-of-arrays evaluation (blocks of 64 faces) against totalArea /
// enclosedVolume and central differences, on off-centre, distorted meshes whose face counts are
// and are not multiples of the block (80, 320, 1280 faces).
TEST(Geometry, AreaVolumeGradientsMatchFiniteDifferences) {
    for (int level : {1, 2, 3}) {
        Mesh m = icosphere(level);
        for (Eigen::Index i = 0; i < m.X.cols(); ++i)
            m.X.col(i) = Eigen::Vector3d(1.3, 0.8, 1.1).cwiseProduct(m.X.col(i)) * (1.0 + 0.1 * std::sin(3.0 * double(i))) +
                         Eigen::Vector3d(0.4, -0.2, 0.7);
        const AreaVolume av = areaVolumeWithGradients(m.X, m.F);
        EXPECT_NEAR(av.area, totalArea(m.X, m.F), 1e-12 * av.area) << "level " << level;
        EXPECT_NEAR(av.volume, enclosedVolume(m.X, m.F), 1e-12 * av.volume) << "level " << level;
        const AreaVolume values = areaAndVolume(m.X, m.F);  // the values-only pass of the retraction
        EXPECT_NEAR(values.area, av.area, 1e-14 * av.area) << "level " << level;
        EXPECT_NEAR(values.volume, av.volume, 1e-14 * av.volume) << "level " << level;
        EXPECT_EQ(values.areaGradient.size(), 0);
        const double h = 1e-6;
        double errA = 0.0, errV = 0.0;
        for (Eigen::Index i = 0; i < m.X.cols(); i += 7)
            for (int d = 0; d < 3; ++d) {
                Vertices Xp = m.X, Xm = m.X;
                Xp(d, i) += h;
                Xm(d, i) -= h;
                errA = std::max(errA, std::abs((totalArea(Xp, m.F) - totalArea(Xm, m.F)) / (2 * h) - av.areaGradient(d, i)));
                errV = std::max(errV, std::abs((enclosedVolume(Xp, m.F) - enclosedVolume(Xm, m.F)) / (2 * h) -
                                               av.volumeGradient(d, i)));
            }
        const double scaleA = av.areaGradient.colwise().norm().maxCoeff();
        const double scaleV = av.volumeGradient.colwise().norm().maxCoeff();
        EXPECT_LT(errA, 1e-6 * scaleA) << "level " << level;
        EXPECT_LT(errV, 1e-6 * scaleV) << "level " << level;
    }
}

TEST(Geometry, InversionPartnersOfIcospheresAndTheSymmetricPart) {
    for (int level = 0; level <= 3; ++level) {
        SCOPED_TRACE(level);
        const Mesh s = icosphere(level);
        const auto p = inversionPartners(s.X);
        ASSERT_EQ(p.size(), static_cast<size_t>(s.numVertices()));
        for (Eigen::Index i = 0; i < s.numVertices(); ++i) {
            const Eigen::Index j = p[static_cast<size_t>(i)];
            EXPECT_NE(j, i);
            EXPECT_EQ(p[static_cast<size_t>(j)], i);
            EXPECT_LT((s.X.col(i) + s.X.col(j)).norm(), 1e-12);
        }
        // The Evans-Fung disc and a moved copy (partners about the centroid) pair the same vertices.
        EXPECT_EQ(inversionPartners(evansFungMap(s.X)), p);
        const Vertices moved = (test::randomRotation(3) * evansFungMap(s.X)).colwise() + Eigen::Vector3d(1.0, -2.0, 3.0);
        EXPECT_EQ(inversionPartners(moved), p);
        EXPECT_LT(inversionAsymmetry(moved, p), 1e-12);
    }
    // Not centrally symmetric: one vertex moved by 1e-3 of the radius.
    const Mesh s = icosphere(2);
    Vertices bumped = s.X;
    bumped(2, 5) += 1e-3;
    EXPECT_TRUE(inversionPartners(bumped).empty());
    const auto p = inversionPartners(s.X);
    EXPECT_NEAR(inversionAsymmetry(bumped, p), 1e-3, 1e-4);

    // The symmetric part: w_j = -w_i for partners, idempotent, and the removed part is orthogonal to it.
    Vertices W = Vertices::Random(3, s.numVertices()), S = W;
    symmetrizeUnderInversion(S, p);
    for (Eigen::Index i = 0; i < s.numVertices(); ++i)
        EXPECT_EQ((S.col(i) + S.col(p[static_cast<size_t>(i)])).norm(), 0.0);
    Vertices S2 = S;
    symmetrizeUnderInversion(S2, p);
    EXPECT_EQ(S2, S);
    EXPECT_NEAR(((W - S).array() * S.array()).sum(), 0.0, 1e-12);
}

TEST(MeshIo, OffRoundTripAndPlyVtkWithFields) {
    const Mesh m = readOff(test::meshPath("rbc_642.off"));
    const auto dir = std::filesystem::temp_directory_path();
    const std::string off = (dir / "trbc_rt.off").string(), ply = (dir / "trbc_rt.ply").string(),
                      vtk = (dir / "trbc_rt.vtk").string();
    writeOff(off, m);
    const Mesh back = readOff(off);
    EXPECT_EQ(back.F, m.F);
    EXPECT_EQ(back.X, m.X);  // 17 significant digits: exact
    const Eigen::MatrixXd curvature = Eigen::RowVectorXd::LinSpaced(m.numVertices(), 0, 1);
    const Eigen::MatrixXd force = Eigen::MatrixXd::Ones(3, m.numVertices());
    writeMesh(ply, m, {{"force", force}, {"mean_curvature", curvature}});
    writeMesh(vtk, m, {{"force", force}, {"mean_curvature", curvature}});
    std::ifstream p(ply), v(vtk);
    const std::string plyText((std::istreambuf_iterator<char>(p)), {}), vtkText((std::istreambuf_iterator<char>(v)), {});
    EXPECT_NE(plyText.find("property double force_x"), std::string::npos);
    EXPECT_NE(plyText.find("element face 1280"), std::string::npos);
    EXPECT_NE(vtkText.find("VECTORS force double"), std::string::npos);
    EXPECT_NE(vtkText.find("SCALARS mean_curvature double 1"), std::string::npos);
    EXPECT_THROW(writeMesh((dir / "x.stl").string(), m), InputError);
    EXPECT_THROW(writeOff("/nonexistent-dir/x.off", m), InputError);
}

TEST(MeshIo, ReferenceWithOtherConnectivityIsRejected) {
    const Mesh a = readOff(test::meshPath("rbc_642.off")), b = readOff(test::meshPath("rbc_498.off"));
    EXPECT_THROW(validateSameConnectivity(a, b, "b.off"), InputError);
    EXPECT_NO_THROW(validateSameConnectivity(a, readOff(test::meshPath("sphere_642.off")), "s.off"));
}

}  // namespace
}  // namespace trbc
