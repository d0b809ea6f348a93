#include "membrane/model.hpp"

#include <fmt/format.h>

#include <numbers>

#include "core/error.hpp"
#include "mesh/validate.hpp"

namespace trbc {

using kernels::Vec3;

namespace {
// Below this many faces a single thread is faster than waking the team.
constexpr Eigen::Index kParallelMinFaces = 2000;

double serialSum(const Eigen::VectorXd& v) {
    double s = 0.0;
    for (Eigen::Index i = 0; i < v.size(); ++i) s += v[i];
    return s;
}
}  // namespace

MembraneModel::MembraneModel(const Faces& faces, Eigen::Index numVertices, const MembraneParameters& params,
                             const Vertices* reference)
    : faces_(faces), numVertices_(numVertices), topo_(buildTopology(faces, numVertices)), params_(params) {
    if (reference) setReference(*reference);
    if (params_.hasLim() && limRef_.empty())
        throw InputError("the Lim in-plane term needs a stress-free reference mesh");
    resizeScratch();
}

void MembraneModel::setParameters(const MembraneParameters& params) {
    if (params.hasLim() && limRef_.empty())
        throw InputError("the Lim in-plane term needs a stress-free reference mesh");
    params_ = params;
}

void MembraneModel::setReference(const Vertices& ref) {
    if (ref.cols() != numVertices_)
        throw InputError(fmt::format("stress-free reference has {} vertices, the mesh has {}", ref.cols(),
                                     numVertices_));
    limRef_.resize(static_cast<std::size_t>(faces_.cols()));
    for (Eigen::Index f = 0; f < faces_.cols(); ++f)
        limRef_[f] = kernels::limReference(ref.col(faces_(0, f)), ref.col(faces_(1, f)), ref.col(faces_(2, f)));
}

void MembraneModel::resizeScratch() const {
    const auto nf = faces_.cols(), ne = topo_.numEdges(), nv = numVertices_;
    s_.faceNormal.resize(3, nf);
    s_.faceArea.resize(nf);
    s_.faceVolume.resize(nf);
    s_.faceEnergy.resize(nf);
    s_.edgeLenTheta.resize(ne);
    s_.vertexArea.resize(nv);
    s_.vertexH.resize(nv);
    s_.vertexEnergy.resize(nv);
    s_.vertexH2.resize(nv);
    s_.faceGrad.resize(9, nf);
    s_.edgeGrad.resize(12, ne);
}

double MembraneModel::evaluate(const Vertices& X, Vertices* grad, EnergyTerms* termsOut) const {
    if (X.cols() != numVertices_)
        throw std::invalid_argument(fmt::format("MembraneModel::evaluate: {} vertices, model built for {}",
                                                X.cols(), numVertices_));
    const auto& F = faces_;
    const auto& T = topo_;
    const auto nf = F.cols(), ne = T.numEdges(), nv = numVertices_;
    const auto& P = params_;
    const bool bending = P.hasBending(), ade = P.hasAde(), lim = P.hasLim();
    const bool curvature = bending || ade;
    const double H0 = 0.5 * P.bending.C0;
    const Vec3 origin = X.col(0);  // volume about a mesh point: round-off free of the position
    const bool wantGrad = grad != nullptr;
    if (wantGrad) grad->resize(3, nv);

    EnergyTerms terms;
    double areaTotal = 0.0, volumeTotal = 0.0, sumLenTheta = 0.0;
    double cAreaGlobal = 0.0, cVolume = 0.0, cEdgeGlobal = 0.0;

#pragma omp parallel if (nf >= kParallelMinFaces)
    {
        // Pass 1: face geometry.
#pragma omp for schedule(static)
        for (Eigen::Index f = 0; f < nf; ++f) {
            const Vec3 xi = X.col(F(0, f)), xj = X.col(F(1, f)), xk = X.col(F(2, f));
            const auto g = kernels::faceGeometry(xi, xj, xk);
            s_.faceNormal.col(f) = g.normal;
            s_.faceArea[f] = g.area;
            s_.faceVolume[f] = (xi - origin).dot((xj - origin).cross(xk - origin)) / 6.0;
        }
        // Pass 2: l_e theta_e of every edge.
        if (curvature) {
#pragma omp for schedule(static)
            for (Eigen::Index e = 0; e < ne; ++e) {
                const Vec3 ev = X.col(T.edges(1, e)) - X.col(T.edges(0, e));
                const double l = ev.norm();
                const double theta = kernels::dihedralAngle(s_.faceNormal.col(T.edgeFaces(0, e)),
                                                            s_.faceNormal.col(T.edgeFaces(1, e)), ev / l);
                s_.edgeLenTheta[e] = l * theta;
            }
        }
        // Pass 3: vertex area, integrated mean curvature M_i = 1/4 sum l theta, H_i = M_i / A_i.
        if (curvature) {
#pragma omp for schedule(static)
            for (Eigen::Index i = 0; i < nv; ++i) {
                double a = 0.0, m = 0.0;
                for (int c = T.vertexCornerStart[i]; c < T.vertexCornerStart[i + 1]; ++c)
                    a += s_.faceArea[T.vertexCorners[c] / 3];
                if (curvature)
                    for (int k = T.vertexEdgeStart[i]; k < T.vertexEdgeStart[i + 1]; ++k)
                        m += s_.edgeLenTheta[T.vertexEdgeList[k]];
                a /= 3.0;
                const double H = 0.25 * m / a;
                s_.vertexArea[i] = a;
                s_.vertexH[i] = H;
                s_.vertexH2[i] = H * H - H0 * H0;
                s_.vertexEnergy[i] = 2.0 * P.bending.kb * a * (H - H0) * (H - H0);
            }
        }
#pragma omp single
        {
            areaTotal = serialSum(s_.faceArea);
            volumeTotal = serialSum(s_.faceVolume);
            if (bending) terms.bending = serialSum(s_.vertexEnergy);
            if (ade) {
                sumLenTheta = serialSum(s_.edgeLenTheta);
                const double d = sumLenTheta - P.bending.DA0;
                terms.ade = std::numbers::pi * P.bending.kad / (2.0 * areaTotal) * d * d;
                cEdgeGlobal = std::numbers::pi * P.bending.kad / areaTotal * d;
                cAreaGlobal -= terms.ade / areaTotal;
            }
            if (P.hasArea()) {
                const double dA = areaTotal - P.penalty.A0;
                terms.area = 0.5 * P.penalty.kA * dA * dA / P.penalty.A0;
                cAreaGlobal += P.penalty.kA * dA / P.penalty.A0;
            }
            if (P.hasVolume()) {
                const double dV = volumeTotal - P.penalty.V0;
                terms.volume = 0.5 * P.penalty.kV * dV * dV / P.penalty.V0;
                cVolume = P.penalty.kV * dV / P.penalty.V0;
            }
        }
        // Pass 4: per-face gradient (area-gradient terms, volume, Lim) and Lim energy.
        if (wantGrad || lim) {
#pragma omp for schedule(static)
            for (Eigen::Index f = 0; f < nf; ++f) {
                const int i = F(0, f), j = F(1, f), k = F(2, f);
                const Vec3 xi = X.col(i), xj = X.col(j), xk = X.col(k);
                const double area = s_.faceArea[f];
                double cArea = cAreaGlobal;
                if (bending)
                    cArea -= (2.0 * P.bending.kb / 3.0) * (s_.vertexH2[i] + s_.vertexH2[j] + s_.vertexH2[k]);
                kernels::LimFace lf{};
                const Vec3 a = xj - xi, b = xk - xi;
                if (lim) {
                    lf = kernels::limFace(P.lim, limRef_[f], a, b, area);
                    s_.faceEnergy[f] = lf.energy;
                    cArea += lf.cArea;
                }
                if (!wantGrad) continue;
                const Vec3 n = s_.faceNormal.col(f);
                auto gA = kernels::areaGradient(n, xi, xj, xk);
                Vec3 gi = cArea * gA.i, gj = cArea * gA.j, gk = cArea * gA.k;
                if (cVolume != 0.0) {
                    const auto gV = kernels::volumeGradient(xi - origin, xj - origin, xk - origin);
                    gi += cVolume * gV.i;
                    gj += cVolume * gV.j;
                    gk += cVolume * gV.k;
                }
                if (lim) {
                    const auto gN = kernels::limShearGradient(lf.cN, limRef_[f], a, b);
                    gi += gN.i;
                    gj += gN.j;
                    gk += gN.k;
                }
                s_.faceGrad.col(f).segment<3>(0) = gi;
                s_.faceGrad.col(f).segment<3>(3) = gj;
                s_.faceGrad.col(f).segment<3>(6) = gk;
            }
        }
        // Pass 5: per-edge gradient of the l theta terms (bending and ADE).
        if (wantGrad && curvature) {
#pragma omp for schedule(static)
            for (Eigen::Index e = 0; e < ne; ++e) {
                const int a = T.edges(0, e), b = T.edges(1, e), c = T.opposite(0, e), d = T.opposite(1, e);
                double coef = cEdgeGlobal;
                if (bending) coef += P.bending.kb * (s_.vertexH[a] + s_.vertexH[b] - 2.0 * H0);
                const Vec3 xa = X.col(a), xb = X.col(b);
                const double l = (xb - xa).norm();
                const int f1 = T.edgeFaces(0, e), f2 = T.edgeFaces(1, e);
                const auto g = kernels::lengthThetaGradient(
                    coef, xa, xb, X.col(c), X.col(d), s_.faceNormal.col(f1), s_.faceNormal.col(f2),
                    s_.faceArea[f1], s_.faceArea[f2], s_.edgeLenTheta[e] / l);
                s_.edgeGrad.col(e) << g.a, g.b, g.c, g.d;
            }
        }
        // Pass 6: gather per-vertex gradients.
        if (wantGrad) {
#pragma omp for schedule(static)
            for (Eigen::Index i = 0; i < nv; ++i) {
                Vec3 g = Vec3::Zero();
                for (int c = T.vertexCornerStart[i]; c < T.vertexCornerStart[i + 1]; ++c) {
                    const int corner = T.vertexCorners[c];
                    g += s_.faceGrad.col(corner / 3).segment<3>(3 * (corner % 3));
                }
                if (curvature)
                    for (int s = T.vertexSlotStart[i]; s < T.vertexSlotStart[i + 1]; ++s) {
                        const int slot = T.vertexSlots[s];
                        g += s_.edgeGrad.col(slot / 4).segment<3>(3 * (slot % 4));
                    }
                grad->col(i) = g;
            }
        }
    }
    if (lim) terms.lim = serialSum(s_.faceEnergy);
    if (termsOut) *termsOut = terms;
    return terms.total();
}

VertexDiagnostics MembraneModel::vertexDiagnostics(const Vertices& X) const {
    MembraneModel probe(*this);
    probe.params_.bending.kb = probe.params_.bending.kb != 0.0 ? probe.params_.bending.kb : 1.0;
    probe.params_.lim = {};
    probe.evaluate(X);
    return {probe.s_.vertexArea, probe.s_.vertexH};
}

Vertices membraneViscousForce(const Vertices& X, const Vertices& V, double gamma, const Topology& T) {
    const auto ne = T.numEdges(), nv = X.cols();
    Eigen::Matrix<double, 3, Eigen::Dynamic> fe(3, ne);
#pragma omp parallel for schedule(static) if (ne >= 3000)
    for (Eigen::Index e = 0; e < ne; ++e) {
        const int a = T.edges(0, e), b = T.edges(1, e);
        fe.col(e) = kernels::edgeViscousForce(gamma, X.col(a), X.col(b), V.col(a), V.col(b));
    }
    Vertices f(3, nv);
#pragma omp parallel for schedule(static) if (nv >= 1000)
    for (Eigen::Index i = 0; i < nv; ++i) {
        Vec3 s = Vec3::Zero();
        for (int k = T.vertexEdgeStart[i]; k < T.vertexEdgeStart[i + 1]; ++k) {
            const int e = T.vertexEdgeList[k];
            s += (T.edges(0, e) == i) ? Vec3(fe.col(e)) : Vec3(-fe.col(e));
        }
        f.col(i) = s;
    }
    return f;
}

}  // namespace trbc
