#include "flow/boundary_integral.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.hpp"
#include "flow/quadrature_rules.hpp"
#include "flow/stokes_kernels.hpp"
#include "mesh/geometry.hpp"
#include "mesh/validate.hpp"

// The operators' set-up (geometry, quadrature points) and the surface integrals. The far sums are
// in far_field.cpp, the near and singular corrections in near_corrections.cpp, the dense blocks
// and the off-surface operator in block_matrix.cpp.
namespace trbc {
namespace {

using Eigen::Index;
using stokes::Mat3;
using stokes::Vec3;
using bie::faceCorners;

}  // namespace

BoundaryIntegralOperators::BoundaryIntegralOperators(const Mesh& mesh, const QuadratureOptions& options)
    : mesh_(mesh), options_(options) {
    validateClosedManifold(mesh_);
    if (!(options_.nearFactor >= 0.0) || !std::isfinite(options_.nearFactor))
        throw InputError(fmt::format("quadrature nearFactor = {}: must be finite and >= 0",
                                     options_.nearFactor));
    if (options_.nearSubdivisions < 0 || options_.nearSubdivisions > 5)
        throw InputError(fmt::format("quadrature nearSubdivisions = {}: must be in [0, 5]",
                                     options_.nearSubdivisions));
    if (options_.singularPoints < 1 || options_.singularPoints > 64)
        throw InputError(fmt::format("quadrature singularPoints = {}: must be in [1, 64]",
                                     options_.singularPoints));
    if (!mesh_.X.allFinite()) throw InputError("mesh: vertex positions must be finite");

    const Index nf = mesh_.numFaces(), nv = mesh_.numVertices();
    faceArea_ = trbc::faceAreas(mesh_.X, mesh_.F);
    faceNormal_.resize(3, nf);
    vertexNormal_ = Eigen::Matrix3Xd::Zero(3, nv);
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        const Vec3 twiceArea = (c.col(1) - c.col(0)).cross(c.col(2) - c.col(0));
        faceNormal_.col(f) = twiceArea.normalized();
        for (int k = 0; k < 3; ++k) vertexNormal_.col(mesh_.F(k, f)) += twiceArea;
    }
    vertexNormal_.colwise().normalize();
    vertexArea_ = trbc::vertexAreas(mesh_.X, mesh_.F);
    area_ = faceArea_.sum();
    volume_ = enclosedVolume(mesh_.X, mesh_.F);
    for (auto* a : {&faceCentroidX_, &faceCentroidY_, &faceCentroidZ_, &faceNearReach2_}) a->resize(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        const Vec3 centroid = c.rowwise().mean();
        faceCentroidX_[f] = centroid.x(), faceCentroidY_[f] = centroid.y(), faceCentroidZ_[f] = centroid.z();
        const double reach = options_.nearFactor * std::max({(c.col(1) - c.col(0)).norm(), (c.col(2) - c.col(1)).norm(),
                                                             (c.col(0) - c.col(2)).norm()});
        faceNearReach2_[f] = reach * reach;
    }
    buildQuadrature();
    buildCorrections();
}

void BoundaryIntegralOperators::buildQuadrature() {
    const bie::TriangleRule rule = bie::symmetricRule(options_.farPoints);
    ruleBary_ = rule.bary;
    ruleWeight_ = rule.weight;
    const Index nf = mesh_.numFaces(), nv = mesh_.numVertices(), nq = ruleWeight_.size();
    for (auto* v : {&fx_, &fy_, &fz_, &fw_}) v->assign(static_cast<std::size_t>(nf * nq), 0.0);
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        for (Index q = 0; q < nq; ++q) {
            const std::size_t k = static_cast<std::size_t>(f * nq + q);
            const Vec3 y = c * ruleBary_.row(q).transpose();
            fx_[k] = y.x(), fy_[k] = y.y(), fz_[k] = y.z();
            fw_[k] = faceArea_[f] * ruleWeight_[q];
        }
    }

    if (options_.farRule == FarRule::FacePoints) {
        cornerWeight_ = 0.0;
        farBary_ = ruleBary_;
        farWeight_ = ruleWeight_;
    } else {  // corners 1/12 each, centroid 3/4: exact for quadratics on the triangle
        cornerWeight_ = 1.0 / 12.0;
        farBary_ = Eigen::RowVector3d::Constant(1.0 / 3.0);
        farWeight_ = Eigen::VectorXd::Constant(1, 0.75);
    }
    cornerPoints_ = cornerWeight_ > 0.0 ? nv : 0;
    const Index nqf = farWeight_.size();
    const std::size_t n = static_cast<std::size_t>(cornerPoints_ + nf * nqf);
    for (auto* v : {&qx_, &qy_, &qz_, &qw_, &qnx_, &qny_, &qnz_}) v->assign(n, 0.0);
    const auto addPoint = [&](std::size_t k, const Vec3& y, double w, const Vec3& n) {
        qx_[k] = y.x(), qy_[k] = y.y(), qz_[k] = y.z();
        qw_[k] += w;
        qnx_[k] += w * n.x(), qny_[k] += w * n.y(), qnz_[k] += w * n.z();
    };
    for (Index f = 0; f < nf; ++f) {
        const Eigen::Matrix3d c = faceCorners(mesh_, f);
        const Vec3 n = faceNormal_.col(f);
        if (cornerPoints_ > 0)
            for (int m = 0; m < 3; ++m)
                addPoint(static_cast<std::size_t>(mesh_.F(m, f)), c.col(m), faceArea_[f] * cornerWeight_, n);
        for (Index q = 0; q < nqf; ++q)
            addPoint(static_cast<std::size_t>(cornerPoints_ + f * nqf + q), c * farBary_.row(q).transpose(),
                     faceArea_[f] * farWeight_[q], n);
    }
    if (options_.singlePrecisionFar) {
        // Relative to the centroid: float keeps ~1e-7 of the cell's extent in the separations.
        farCentre_ = mesh_.X.rowwise().mean();
        const auto toFloat = [](const std::vector<double>& a, std::vector<float>& b, double shift) {
            b.resize(a.size());
            for (std::size_t k = 0; k < a.size(); ++k) b[k] = static_cast<float>(a[k] - shift);
        };
        toFloat(qx_, qxf_, farCentre_.x());
        toFloat(qy_, qyf_, farCentre_.y());
        toFloat(qz_, qzf_, farCentre_.z());
        toFloat(qw_, qwf_, 0.0);
        toFloat(qnx_, qnxf_, 0.0);
        toFloat(qny_, qnyf_, 0.0);
        toFloat(qnz_, qnzf_, 0.0);
    }
}

void BoundaryIntegralOperators::checkDensity(const Eigen::Matrix3Xd& v, const char* name) const {
    if (v.cols() != numVertices())
        throw InputError(fmt::format("{}: {} columns given, the mesh has {} vertices", name, v.cols(), numVertices()));
}

Eigen::Vector3d BoundaryIntegralOperators::integrate(const Eigen::Matrix3Xd& f) const {
    checkDensity(f, "surface density");
    return f * vertexArea_;
}

Eigen::Vector3d BoundaryIntegralOperators::moment(const Eigen::Matrix3Xd& f, const Eigen::Vector3d& c) const {
    checkDensity(f, "surface density");
    // int_face phi_a phi_b dS = A (1 + delta_ab) / 12.
    Vec3 m = Vec3::Zero();
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        Vec3 xs = Vec3::Zero(), fs = Vec3::Zero(), diag = Vec3::Zero();
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = mesh_.X.col(mesh_.F(k, t)) - c, g = f.col(mesh_.F(k, t));
            xs += x;
            fs += g;
            diag += x.cross(g);
        }
        m += faceArea_[t] / 12.0 * (xs.cross(fs) + diag);
    }
    return m;
}

Eigen::Matrix3d BoundaryIntegralOperators::firstMoment(const Eigen::Matrix3Xd& f,
                                                       const Eigen::Vector3d& c) const {
    checkDensity(f, "surface density");
    Mat3 m = Mat3::Zero();
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        Vec3 xs = Vec3::Zero(), fs = Vec3::Zero();
        Mat3 diag = Mat3::Zero();
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = mesh_.X.col(mesh_.F(k, t)) - c, g = f.col(mesh_.F(k, t));
            xs += x;
            fs += g;
            diag += x * g.transpose();
        }
        m += faceArea_[t] / 12.0 * (xs * fs.transpose() + diag);
    }
    return m;
}

double BoundaryIntegralOperators::normalFlux(const Eigen::Matrix3Xd& u) const {
    checkDensity(u, "surface velocity");
    double s = 0.0;
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        const Vec3 us = u.col(mesh_.F(0, t)) + u.col(mesh_.F(1, t)) + u.col(mesh_.F(2, t));
        s += faceArea_[t] / 3.0 * us.dot(faceNormal_.col(t));
    }
    return s;
}

Eigen::Vector3d BoundaryIntegralOperators::volumeMeanVelocity(const Eigen::Matrix3Xd& u) const {
    checkDensity(u, "surface velocity");
    Vec3 s = Vec3::Zero();
    for (Index t = 0; t < mesh_.numFaces(); ++t) {
        const Vec3 n = faceNormal_.col(t);
        Vec3 xs = Vec3::Zero(), diag = Vec3::Zero();
        double us = 0.0;
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = mesh_.X.col(mesh_.F(k, t));
            const double un = u.col(mesh_.F(k, t)).dot(n);
            xs += x;
            us += un;
            diag += un * x;
        }
        s += faceArea_[t] / 12.0 * (us * xs + diag);
    }
    return s / volume_;
}

}  // namespace trbc
