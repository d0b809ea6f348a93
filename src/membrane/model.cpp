#include "membrane/model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <numbers>
#include <stdexcept>
#include <type_traits>

#include "core/error.hpp"
#include "mesh/validate.hpp"

#if defined(TRBC_AVX512_KERNELS) && defined(__GNUC__) && !defined(__clang__)
// The force loops of this file only (no Eigen packet code runs in them) use AVX-512 with 512-bit
// vectors when the build machine has it; the rest of trbc is built without AVX-512 because GCC 12
// warns falsely inside Eigen's AVX-512 packet code. Measured: 120 us vs 150-160 us at Nv = 2562.
#pragma GCC target("avx512f,avx512vl,avx512dq,avx512bw,avx512cd,prefer-vector-width=512")
#endif

// The loop iterations are independent (outputs never alias inputs): vectorise without run-time
// alias checks.
#if defined(__clang__)
#define TRBC_IVDEP _Pragma("clang loop vectorize(assume_safety)")
#else
#define TRBC_IVDEP _Pragma("GCC ivdep")
#endif

namespace trbc {

using kernels::Real3;
using kernels::Vec3;

namespace {
// Below this many faces a single thread is faster than waking the team.
constexpr Eigen::Index kParallelMinFaces = 2000;
// Faces, edges and vertices are processed in fixed blocks of this many (a multiple of the SIMD
// width).
constexpr Eigen::Index kBlock = 256;
// Extra rows of the scratch arrays. Without them, for meshes such as icospheres (Nf = 5120 at
// level 4) every per-face column is a multiple of 4 KiB long, so the ~30 arrays that a loop streams
// through all map to the same L1 cache sets and alias in store-to-load forwarding. The padding
// also holds the zero entries that short vertex rings point to.
constexpr Eigen::Index kPad = 40;

// Calls body(begin, end) for the blocks [b, b + kBlock) of [0, n), shared among the threads of
// the enclosing parallel region (an orphaned `omp for`, with its barrier). The blocks do not
// depend on the number of threads, so neither does the code path (vector body or remainder) of
// any element: results are bit-identical for any thread count.
template <class Body>
void forBlocks(Eigen::Index n, const Body& body) {
#pragma omp for schedule(static)
    for (Eigen::Index b = 0; b < n; b += kBlock) body(b, std::min(b + kBlock, n));
}

// Calls f with std::bool_constant arguments equal to the runtime flags, so that `if constexpr`
// takes switches out of the vectorised loops (a loop with a large `if` inside does not vectorise).
template <class Fn>
void withFlags(bool a, Fn&& f) {
    if (a)
        f(std::true_type{});
    else
        f(std::false_type{});
}
template <class Fn>
void withFlags(bool a, bool b, Fn&& f) {
    withFlags(a, [&](auto ca) { withFlags(b, [&](auto cb) { f(ca, cb); }); });
}

// The in-plane energy of the face loop, as a compile-time constant (one vectorised loop per law).
enum class FaceLaw { None, Lim, NeoHookean, Skalak };
template <FaceLaw law>
using FaceLawConstant = std::integral_constant<FaceLaw, law>;

template <class Fn>
void withFaceLaw(const MembraneParameters& p, Fn&& f) {
    if (p.hasLim())
        f(FaceLawConstant<FaceLaw::Lim>{});
    else if (!p.hasCapsuleLaw())
        f(FaceLawConstant<FaceLaw::None>{});
    else if (p.law == InPlaneLaw::NeoHookean)
        f(FaceLawConstant<FaceLaw::NeoHookean>{});
    else
        f(FaceLawConstant<FaceLaw::Skalak>{});
}

// "the Lim in-plane term needs a stress-free reference mesh" and the same for the other laws.
void requireReference(const MembraneParameters& p, bool haveReference) {
    if (!p.hasInPlane() || haveReference) return;
    const char* name = p.law == InPlaneLaw::Lim ? "Lim" : p.law == InPlaneLaw::NeoHookean ? "neo-Hookean" : "Skalak";
    throw InputError(fmt::format("the {} in-plane term needs a stress-free reference mesh", name));
}

// Sum of v[0, n) in a fixed order (8 interleaved partial sums): vectorises, and is the same for
// any number of threads.
double fixedOrderSum(const Eigen::VectorXd& v, Eigen::Index n) {
    constexpr int kLanes = 8;
    double acc[kLanes] = {};
    const Eigen::Index nFull = n - n % kLanes;
    for (Eigen::Index i = 0; i < nFull; i += kLanes)
        for (int l = 0; l < kLanes; ++l) acc[l] += v[i + l];
    for (Eigen::Index i = nFull; i < n; ++i) acc[i - nFull] += v[i];
    return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
}

// out = sqrt(in) for n values, four at a time with Eigen's packet sqrt (correctly rounded, as
// std::sqrt). A loop that calls std::sqrt does not vectorise (std::sqrt may set errno), so the
// loops leave their square roots to this, between two loops over the same block.
void sqrtArray(const double* in, double* out, Eigen::Index n) {
    Eigen::Index i = 0;
    for (; i + 4 <= n; i += 4) Eigen::Array4d::Map(out + i) = Eigen::Array4d::Map(in + i).sqrt();
    for (; i < n; ++i) out[i] = std::sqrt(in[i]);
}

Real3 col3(const Vertices& X, Eigen::Index i) { return {X(0, i), X(1, i), X(2, i)}; }

template <int Cols>
Real3 row3(const Eigen::Matrix<double, Eigen::Dynamic, Cols>& m, Eigen::Index r, int c0 = 0) {
    return {m(r, c0), m(r, c0 + 1), m(r, c0 + 2)};
}
template <int Cols>
void setRow3(Eigen::Matrix<double, Eigen::Dynamic, Cols>& m, Eigen::Index r, Real3 v, int c0 = 0) {
    m(r, c0) = v.x;
    m(r, c0 + 1) = v.y;
    m(r, c0 + 2) = v.z;
}
}  // namespace

MembraneModel::MembraneModel(const Faces& faces, Eigen::Index numVertices, const MembraneParameters& params,
                             const Vertices* reference)
    : faces_(faces), numVertices_(numVertices), topo_(buildTopology(faces, numVertices)), params_(params) {
    const auto& T = topo_;
    if (T.vertexCornerStart != T.vertexEdgeStart)  // as many faces as edges around each vertex
        throw std::logic_error("MembraneModel: mesh is not closed (validate first)");
    const Eigen::Index nf = faces.cols(), ne = T.numEdges(), nv = numVertices, rows = nf + kPad;
    faceVertices_ = faces.cast<Eigen::Index>();
    faceEdges_ = T.faceEdges.cast<Eigen::Index>();
    edgeFaces_ = T.edgeFaces.cast<Eigen::Index>();
    edgeVector_.resize(ne);
    for (Eigen::Index e = 0; e < ne; ++e)
        for (int m = 0; m < 3; ++m)
            if (T.faceEdges(m, T.edgeFaces(0, e)) == e) edgeVector_[e] = 3 * m * rows + T.edgeFaces(0, e);

    for (Eigen::Index i = 0; i < nv; ++i) ringWidth_ = std::max(ringWidth_, T.valence(static_cast<int>(i)));
    const auto ringSize = static_cast<std::size_t>(ringWidth_ * nv);
    ringFace_.assign(ringSize, static_cast<int>(nf));
    ringEdge_.assign(ringSize, static_cast<int>(ne));
    ringGradColumn_.assign(ringSize, static_cast<int>(3 * rows));
    for (Eigen::Index i = 0; i < nv; ++i)
        for (int k = 0; k < T.valence(static_cast<int>(i)); ++k) {
            const int corner = T.vertexCorners[T.vertexCornerStart[i] + k];
            const auto slot = static_cast<std::size_t>(k * nv + i);
            ringFace_[slot] = corner / 3;
            ringEdge_[slot] = T.vertexEdgeList[T.vertexEdgeStart[i] + k];
            ringGradColumn_[slot] = static_cast<int>(corner % 3 * rows + corner / 3);
        }

    if (reference) setReference(*reference);
    requireReference(params_, limRef_.rows() != 0);
    resizeScratch();
}

void MembraneModel::setParameters(const MembraneParameters& params) {
    requireReference(params, limRef_.rows() != 0);
    params_ = params;
}

void MembraneModel::setReference(const Vertices& ref) {
    if (ref.cols() != numVertices_)
        throw InputError(fmt::format("stress-free reference has {} vertices, the mesh has {}", ref.cols(),
                                     numVertices_));
    limRef_.resize(faces_.cols() + kPad, 5);
    for (Eigen::Index f = 0; f < faces_.cols(); ++f) {
        const auto r =
            kernels::limReference(ref.col(faces_(0, f)), ref.col(faces_(1, f)), ref.col(faces_(2, f)));
        limRef_.row(f) << r.a0a0, r.b0b0, r.a0b0, r.area0, r.invArea0;
    }
}

kernels::LimReference MembraneModel::limReference(Eigen::Index f) const {
    return {limRef_(f, 0), limRef_(f, 1), limRef_(f, 2), limRef_(f, 3), limRef_(f, 4)};
}

void MembraneModel::resizeScratch() const {
    const auto nf = faces_.cols() + kPad, ne = topo_.numEdges() + kPad, nv = numVertices_ + kPad;
    s_.faceNormal.resize(nf, 3);
    s_.faceY.resize(nf, 3);
    s_.faceEdge.resize(nf, 9);
    s_.faceArea.setZero(nf);
    for (auto* v : {&s_.faceInvTwiceArea, &s_.faceVolume, &s_.faceInPlaneEnergy, &s_.faceInPlaneCArea,
                    &s_.faceInPlaneCN})
        v->resize(nf);
    s_.edgeLenTheta.setZero(ne);
    s_.edgeThetaOverLen.resize(ne);
    for (auto* v : {&s_.vertexArea, &s_.vertexH, &s_.vertexEnergy, &s_.vertexCoefM, &s_.vertexCoefA})
        v->resize(nv);
    s_.faceGrad.setZero(3, 3 * nf + 1);
}

// Passes: (1) faces: normal, area, volume, edge vectors, in-plane law; (2) edges: l theta; (3) vertices:
// A_i, H_i; global sums; (4) faces: gradient at the three corners, including the face's share of
// the l theta gradient of its three edges; (5) vertices: sum of their corner gradients.
// Passes 1-5 vectorise across faces, edges and vertices (gathers through the index arrays).
double MembraneModel::evaluate(const Vertices& X, Vertices* grad, EnergyTerms* termsOut) const {
    if (X.cols() != numVertices_)
        throw std::invalid_argument(fmt::format("MembraneModel::evaluate: {} vertices, model built for {}",
                                                X.cols(), numVertices_));
    const auto& F = faceVertices_;
    const auto nf = F.cols(), ne = edgeFaces_.cols(), nv = numVertices_, rows = nf + kPad;
    const auto& P = params_;
    const bool bending = P.hasBending(), ade = P.hasAde(), lim = P.hasLim(), capsule = P.hasCapsuleLaw();
    const bool inPlane = lim || capsule;
    const bool curvature = bending || ade;
    const double H0 = 0.5 * P.bending.C0, kb = P.bending.kb;
    const Real3 o = col3(X, 0);  // volume about a mesh point: round-off free of the position
    const bool wantGrad = grad != nullptr;
    if (wantGrad) grad->resize(3, nv);

    EnergyTerms terms;
    double areaTotal = 0.0, volumeTotal = 0.0;
    // Coefficients of dA_t/dx, dV_t/dx and d(l_e theta_e)/dx common to all faces and edges.
    struct {
        double area = 0.0, volume = 0.0, edge = 0.0;
    } global;

    // Pass 1 on faces [begin, end): A_t, n_t, V_t, the edge vectors e (kernels::oppositeEdges),
    // y = x_i - o, and the in-plane energy (Lim or a capsule law) with its gradient coefficients.
    const auto faceGeometry = [&](Eigen::Index begin, Eigen::Index end, auto law) {
        const LimParameters limParams = P.lim;  // local copies: not reloaded after each store
        const CapsuleLawParameters capsuleParams = P.capsule;
        const Real3 origin = o;
        double twiceArea[kBlock], aa[kBlock], bb[kBlock], ab[kBlock];  // |c|, a.a, b.b, a.b
        TRBC_IVDEP
        for (Eigen::Index f = begin; f < end; ++f) {
            const Real3 xi = col3(X, F(0, f)), xj = col3(X, F(1, f)), xk = col3(X, F(2, f));
            const kernels::Corner3 e = kernels::oppositeEdges(xi, xj, xk);
            const Real3 a = xj - xi, b = xk - xi, c = kernels::twiceAreaVector(xi, xj, xk);
            setRow3(s_.faceEdge, f, e.i, 0);
            setRow3(s_.faceEdge, f, e.j, 3);
            setRow3(s_.faceEdge, f, e.k, 6);
            setRow3(s_.faceY, f, xi - origin);
            setRow3(s_.faceNormal, f, c);      // normalised below
            twiceArea[f - begin] = dot(c, c);  // square-rooted below
            s_.faceVolume[f] = kernels::faceVolume(xi - origin, xj - origin, xk - origin);
            aa[f - begin] = dot(a, a);
            bb[f - begin] = dot(b, b);
            ab[f - begin] = dot(a, b);
        }
        sqrtArray(twiceArea, twiceArea, end - begin);
        TRBC_IVDEP
        for (Eigen::Index f = begin; f < end; ++f) {
            const double inv = 1.0 / twiceArea[f - begin], area = 0.5 * twiceArea[f - begin];
            setRow3(s_.faceNormal, f, inv * row3(s_.faceNormal, f));
            s_.faceArea[f] = area;
            s_.faceInvTwiceArea[f] = inv;
            if constexpr (law == FaceLaw::Lim) {
                const auto r = limReference(f);
                const double N = kernels::limN(r, aa[f - begin], bb[f - begin], ab[f - begin]);
                const auto lf = kernels::limFace(limParams, r, N, area, 2.0 * inv);
                s_.faceInPlaneEnergy[f] = lf.energy;
                s_.faceInPlaneCArea[f] = lf.cArea;
                s_.faceInPlaneCN[f] = lf.cN;
            } else if constexpr (law != FaceLaw::None) {
                constexpr InPlaneLaw kLaw = law == FaceLaw::NeoHookean ? InPlaneLaw::NeoHookean : InPlaneLaw::Skalak;
                const auto r = limReference(f);
                const double N = kernels::limN(r, aa[f - begin], bb[f - begin], ab[f - begin]);
                const auto cf = kernels::capsuleFace<kLaw>(capsuleParams, r, N, area, 2.0 * inv);
                s_.faceInPlaneEnergy[f] = cf.energy;
                s_.faceInPlaneCArea[f] = cf.cArea;
                s_.faceInPlaneCN[f] = cf.cN;
            }
        }
    };

    // Pass 2 on edges [begin, end): l_e theta_e and theta_e / l_e.
    const auto edgeAngles = [&](Eigen::Index begin, Eigen::Index end) {
        kernels::DihedralArgs args[kBlock];
        double lenSq[kBlock], len[kBlock];
        TRBC_IVDEP
        for (Eigen::Index e = begin; e < end; ++e) {
            const double* v = s_.faceEdge.data() + edgeVector_[e];
            const Real3 ev = {v[0], v[rows], v[2 * rows]};
            args[e - begin] = kernels::dihedralArgs(row3(s_.faceNormal, edgeFaces_(0, e)),
                                                    row3(s_.faceNormal, edgeFaces_(1, e)), ev);
            lenSq[e - begin] = dot(ev, ev);
        }
        sqrtArray(lenSq, len, end - begin);
        TRBC_IVDEP
        for (Eigen::Index e = begin; e < end; ++e) {
            const double l = len[e - begin], lenTheta = l * kernels::dihedralAngle(args[e - begin], l);
            s_.edgeLenTheta[e] = lenTheta;
            s_.edgeThetaOverLen[e] = lenTheta / lenSq[e - begin];
        }
    };

    // Pass 3 on vertices [begin, end): A_i = 1/3 sum A_t, integrated mean curvature
    // M_i = 1/4 sum l theta, H_i = M_i / A_i, and the coefficients dU_b/dM_i / 4 = kb (H_i - H0)
    // and -dU_b/dA_i / 3 = 2 kb/3 (H_i^2 - H0^2).
    const auto vertexCurvature = [&](Eigen::Index begin, Eigen::Index end) {
        double areaSum[kBlock] = {}, m[kBlock] = {};
        for (int k = 0; k < ringWidth_; ++k) {
            const int *face = &ringFace_[k * nv], *edge = &ringEdge_[k * nv];
            TRBC_IVDEP
            for (Eigen::Index i = begin; i < end; ++i) {
                areaSum[i - begin] += s_.faceArea[face[i]];
                m[i - begin] += s_.edgeLenTheta[edge[i]];
            }
        }
        TRBC_IVDEP
        for (Eigen::Index i = begin; i < end; ++i) {
            const double a = areaSum[i - begin] * (1.0 / 3.0), H = 0.75 * m[i - begin] / areaSum[i - begin];
            s_.vertexArea[i] = a;
            s_.vertexH[i] = H;
            s_.vertexEnergy[i] = 2.0 * kb * a * (H - H0) * (H - H0);
            s_.vertexCoefM[i] = kb * (H - H0);
            s_.vertexCoefA[i] = (2.0 * kb / 3.0) * (H * H - H0 * H0);
        }
    };

    // Pass 4 on faces [begin, end): the gradient at the corners,
    // cArea dA_t/dx + cVolume dV_t/dx + cN dN_t/dx + the face's share of the l theta terms, with
    // cArea = global.area + in-plane cArea - 2 kb/3 sum_{k in t} (H_k^2 - H0^2) and, for each edge
    // (a, b), coef = global.edge + kb (H_a + H_b - 2 H0) (docs/MEMBRANE_MODEL.md, bending).
    const auto faceGradient = [&](Eigen::Index begin, Eigen::Index end, auto withCurvature, auto withInPlane) {
        const auto c = global;  // a local copy: not reloaded after each store
        TRBC_IVDEP
        for (Eigen::Index f = begin; f < end; ++f) {
            const Eigen::Index i = F(0, f), j = F(1, f), k = F(2, f);
            const kernels::Corner3 e = {row3(s_.faceEdge, f, 0), row3(s_.faceEdge, f, 3),
                                        row3(s_.faceEdge, f, 6)};
            const Real3 n = row3(s_.faceNormal, f);
            double cArea = c.area;
            kernels::Corner3 g{};
            if constexpr (withCurvature) {
                const auto &cM = s_.vertexCoefM, &thetaOverLen = s_.edgeThetaOverLen;
                const Eigen::Index ei = faceEdges_(0, f), ej = faceEdges_(1, f), ek = faceEdges_(2, f);
                cArea -= s_.vertexCoefA[i] + s_.vertexCoefA[j] + s_.vertexCoefA[k];
                g = kernels::lengthThetaGradient(
                    n, e, s_.faceInvTwiceArea[f],
                    {c.edge + cM[j] + cM[k], c.edge + cM[k] + cM[i], c.edge + cM[i] + cM[j]},
                    {thetaOverLen[ei], thetaOverLen[ej], thetaOverLen[ek]});
            }
            if constexpr (withInPlane) {
                cArea += s_.faceInPlaneCArea[f];
                g += kernels::limShearGradient(s_.faceInPlaneCN[f], limReference(f), e.k, -e.j);
            }
            g += kernels::areaVolumeGradient(cArea, c.volume, n, s_.faceArea[f], row3(s_.faceY, f), e);
            const Real3 corner[3] = {g.i, g.j, g.k};
            for (int m = 0; m < 3; ++m) {
                s_.faceGrad(0, m * rows + f) = corner[m].x;
                s_.faceGrad(1, m * rows + f) = corner[m].y;
                s_.faceGrad(2, m * rows + f) = corner[m].z;
            }
        }
    };

    // Pass 5 on vertices [begin, end): the sum of the corner gradients of each vertex.
    const auto vertexGradient = [&](Eigen::Index begin, Eigen::Index end) {
        double g[3][kBlock] = {};
        for (int k = 0; k < ringWidth_; ++k) {
            const int* column = &ringGradColumn_[k * nv];
            TRBC_IVDEP
            for (Eigen::Index i = begin; i < end; ++i)
                for (int c = 0; c < 3; ++c) g[c][i - begin] += s_.faceGrad(c, column[i]);
        }
        TRBC_IVDEP
        for (Eigen::Index i = begin; i < end; ++i)
            for (int c = 0; c < 3; ++c) (*grad)(c, i) = g[c][i - begin];
    };

#pragma omp parallel if (nf >= kParallelMinFaces)
    {
        withFaceLaw(P, [&](auto law) {
            forBlocks(nf, [&](Eigen::Index begin, Eigen::Index end) { faceGeometry(begin, end, law); });
        });
        if (curvature) {
            forBlocks(ne, edgeAngles);
            forBlocks(nv, vertexCurvature);
        }
#pragma omp single
        {
            areaTotal = fixedOrderSum(s_.faceArea, nf);
            volumeTotal = fixedOrderSum(s_.faceVolume, nf);
            if (bending) terms.bending = fixedOrderSum(s_.vertexEnergy, nv);
            if (lim) terms.lim = fixedOrderSum(s_.faceInPlaneEnergy, nf);
            if (capsule) terms.capsule = fixedOrderSum(s_.faceInPlaneEnergy, nf);
            if (ade) {
                const double d = fixedOrderSum(s_.edgeLenTheta, ne) - P.bending.DA0;
                terms.ade = std::numbers::pi * P.bending.kad / (2.0 * areaTotal) * d * d;
                global.edge = std::numbers::pi * P.bending.kad / areaTotal * d;
                global.area -= terms.ade / areaTotal;
            }
            if (P.hasArea()) {
                const double dA = areaTotal - P.penalty.A0;
                terms.area = 0.5 * P.penalty.kA * dA * dA / P.penalty.A0;
                global.area += P.penalty.kA * dA / P.penalty.A0;
            }
            if (P.hasVolume()) {
                const double dV = volumeTotal - P.penalty.V0;
                terms.volume = 0.5 * P.penalty.kV * dV * dV / P.penalty.V0;
                global.volume = P.penalty.kV * dV / P.penalty.V0;
            }
        }
        if (wantGrad) {
            withFlags(curvature, inPlane, [&](auto withCurvature, auto withInPlane) {
                forBlocks(nf, [&](Eigen::Index begin, Eigen::Index end) {
                    faceGradient(begin, end, withCurvature, withInPlane);
                });
            });
            forBlocks(nv, vertexGradient);
        }
    }
    if (termsOut) *termsOut = terms;
    return terms.total();
}

VertexDiagnostics MembraneModel::vertexDiagnostics(const Vertices& X) const {
    MembraneModel probe(*this);
    probe.params_.bending.kb = probe.params_.bending.kb != 0.0 ? probe.params_.bending.kb : 1.0;
    probe.params_.lim = {};
    probe.params_.capsule = {};
    probe.evaluate(X);
    return {probe.s_.vertexArea.head(numVertices_), probe.s_.vertexH.head(numVertices_)};
}

Eigen::Matrix3Xd unitEdgeVectors(const Vertices& X, const Topology& T) {
    Eigen::Matrix3Xd e(3, T.numEdges());
    for (Eigen::Index k = 0; k < T.numEdges(); ++k) e.col(k) = (X.col(T.edges(0, k)) - X.col(T.edges(1, k))).normalized();
    return e;
}

Vertices membraneViscousForceAlong(const Eigen::Matrix3Xd& unitEdges, const Vertices& V, double gamma, const Topology& T) {
    const auto ne = T.numEdges(), nv = V.cols();
    if (unitEdges.cols() != ne)
        throw std::invalid_argument(fmt::format("membraneViscousForceAlong: {} edge directions for {} edges",
                                                unitEdges.cols(), ne));
    Eigen::Matrix<double, 3, Eigen::Dynamic> fe(3, ne);
#pragma omp parallel for schedule(static) if (ne >= 3000)
    for (Eigen::Index e = 0; e < ne; ++e) {
        const int a = T.edges(0, e), b = T.edges(1, e);
        fe.col(e) = kernels::edgeViscousForceAlong(gamma, unitEdges.col(e), V.col(a), V.col(b));
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

Vertices membraneViscousForce(const Vertices& X, const Vertices& V, double gamma, const Topology& T) {
    return membraneViscousForceAlong(unitEdgeVectors(X, T), V, gamma, T);
}

}  // namespace trbc
