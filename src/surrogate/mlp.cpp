#include "surrogate/mlp.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>

#include "core/simd.hpp"
#include "surrogate/mlp_avx2.hpp"

namespace trbc {

// ---------------------------------------------------------------------------------------------
// tanh
//
// Eigen 3.4 vectorises tanh for float only; for double it calls std::tanh per element, which costs
// more than all matrix products of the network together. Branch-free packet version, a = |x|:
//   tanh a = m / (m + 2),  m = expm1(u),  u = 2 min(a, 20)   (tanh 20 = 1 - 8e-18 rounds to 1).
//   expm1(u) = 2^k (1 + p) - 1 = 2^k p + (2^k - 1) with k = rint(u / ln 2), r = u - k ln 2 in
//   [-ln2/2, ln2/2] (Cody-Waite: ln 2 = hi + lo, k hi exact) and p = expm1(r) by its Taylor
//   polynomial of degree 13 (remainder r^14/14! < 1e-17 |r|). For k = 0 (a < 0.173) m = p exactly,
//   so small arguments keep their relative accuracy without a second branch; for k >= 1 the sum
//   2^k p + (2^k - 1) >= 0.41 amplifies the error of p by at most 2^k |p| / m <= 1.42. One division
//   per element.
//   The sign of x is put back with a bitwise or.
// NaN propagates, +-inf gives +-1.
// A partial last packet is padded, so every element goes through the same packet code and its
// value does not depend on its position in the array.
namespace {

using Packet = Eigen::internal::packet_traits<double>::type;
constexpr int kPacketSize = Eigen::internal::packet_traits<double>::size;

/// 2^k for integer-valued k in [-1022, 1023]: k + 1023 lands in the low mantissa bits of
/// 1.5 2^52 + k + 1023, a shift by 52 moves it into the exponent field.
inline Packet exp2Integer(const Packet& k) {
    constexpr double kShift = 0x1.8p52 + 1023.0;
#if defined(EIGEN_VECTORIZE_AVX512)  // Packet = __m512d
    return _mm512_castsi512_pd(_mm512_slli_epi64(_mm512_castpd_si512(_mm512_add_pd(k, _mm512_set1_pd(kShift))), 52));
#elif defined(EIGEN_VECTORIZE_AVX2)  // Packet = __m256d
    return _mm256_castsi256_pd(_mm256_slli_epi64(_mm256_castpd_si256(_mm256_add_pd(k, _mm256_set1_pd(kShift))), 52));
#elif defined(EIGEN_VECTORIZE_SSE2) && !defined(EIGEN_VECTORIZE_AVX)  // Packet = __m128d
    return _mm_castsi128_pd(_mm_slli_epi64(_mm_castpd_si128(_mm_add_pd(k, _mm_set1_pd(kShift))), 52));
#else
    (void)kShift;
    return Eigen::internal::pldexp(Eigen::internal::pset1<Packet>(1.0), k);
#endif
}

inline Packet tanhPacket(const Packet& x) {
    using namespace Eigen::internal;
    const Packet u = pmul(pset1<Packet>(2.0), pmin<Eigen::PropagateNaN>(pabs(x), pset1<Packet>(20.0)));
    const Packet k = print(pmul(u, pset1<Packet>(1.4426950408889634)));  // u / ln 2
    const Packet minusK = pnegate(k);
    Packet r = pmadd(minusK, pset1<Packet>(0x1.62e42fee00000p-1), u);  // u - k ln2_hi (exact)
    r = pmadd(minusK, pset1<Packet>(0x1.a39ef35793c76p-33), r);        // - k ln2_lo
    // p = expm1(r) = r + r^2 (1/2! + r/3! + ... + r^11/13!); r enters exactly, the rounding of the
    // correction r^2 (...) <= 0.19 |r| weighs little
    Packet e = pset1<Packet>(1.0 / 6227020800.0);  // 1/13!
    for (const double c : {1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0, 1.0 / 40320.0,
                           1.0 / 5040.0, 1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5})
        e = pmadd(e, r, pset1<Packet>(c));
    const Packet p = pmadd(pmul(r, r), e, r);
    const Packet one = pset1<Packet>(1.0);
    const Packet twoK = exp2Integer(k);
    const Packet m = pmadd(twoK, p, psub(twoK, one));  // expm1(u)
    return por(pdiv(m, padd(m, pset1<Packet>(2.0))), pand(x, pset1<Packet>(-0.0)));  // sign of x
}

}  // namespace

void tanhInPlace(double* x, Eigen::Index n) {
#if defined(TRBC_MLP_AVX2_DISPATCH)
    if (simd::active() == simd::Path::avx2) return mlp_avx2::tanhInPlace(x, n);
#endif
    using namespace Eigen::internal;
    Eigen::Index i = 0;
    for (; i + kPacketSize <= n; i += kPacketSize) pstoreu(x + i, tanhPacket(ploadu<Packet>(x + i)));
    if (i < n) {
        double tail[kPacketSize] = {};
        std::copy(x + i, x + n, tail);
        pstoreu(tail, tanhPacket(ploadu<Packet>(tail)));
        std::copy(tail, tail + (n - i), x + i);
    }
}

// ---------------------------------------------------------------------------------------------
// Threading of Eigen's products

SerialEigenScope::SerialEigenScope() : saved_(omp_get_max_threads()) { omp_set_num_threads(1); }
SerialEigenScope::~SerialEigenScope() { omp_set_num_threads(saved_); }

// ---------------------------------------------------------------------------------------------
// Layout and initialisation

Mlp::Mlp(std::vector<int> layerSizes) : sizes_(std::move(layerSizes)) {
    if (sizes_.size() < 2) throw std::invalid_argument("Mlp: need at least input and output sizes");
    for (int s : sizes_)
        if (s < 1) throw std::invalid_argument("Mlp: layer sizes must be >= 1, got " + std::to_string(s));
    Eigen::Index offset = 0;
    for (int l = 0; l < numLayers(); ++l) {
        offsets_.push_back(offset);
        offset += Eigen::Index(sizes_[l + 1]) * (sizes_[l] + 1);  // W_l and b_l
    }
    params_ = Eigen::VectorXd::Zero(offset);
}

Mlp Mlp::glorotUniform(std::vector<int> layerSizes, std::uint64_t seed) {
    Mlp net(std::move(layerSizes));
    std::mt19937_64 rng(seed);
    // u in [0, 1) from the top 53 bits (the std distributions are implementation-defined)
    const auto uniform01 = [&rng] { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };
    for (int l = 0; l < net.numLayers(); ++l) {
        const double a = std::sqrt(6.0 / (net.sizes_[l] + net.sizes_[l + 1]));  // Glorot bound
        MatrixMap W = net.weights(l);
        for (Eigen::Index k = 0; k < W.size(); ++k) W.data()[k] = a * (2.0 * uniform01() - 1.0);
        net.biases(l).setConstant(0.01);
    }
    return net;
}

void Mlp::setParameters(const Eigen::VectorXd& p) {
    if (p.size() != params_.size())
        throw std::invalid_argument("Mlp::setParameters: expected " + std::to_string(params_.size()) +
                                    " values, got " + std::to_string(p.size()));
    params_ = p;
}

Mlp::ConstMatrixMap Mlp::weightsIn(const Eigen::VectorXd& flat, int l) const {
    return ConstMatrixMap(flat.data() + weightOffset(l), sizes_[l + 1], sizes_[l]);
}
Mlp::MatrixMap Mlp::weightsIn(Eigen::VectorXd& flat, int l) const {
    return MatrixMap(flat.data() + weightOffset(l), sizes_[l + 1], sizes_[l]);
}
Mlp::ConstVectorMap Mlp::biasesIn(const Eigen::VectorXd& flat, int l) const {
    return ConstVectorMap(flat.data() + biasOffset(l), sizes_[l + 1]);
}
Mlp::VectorMap Mlp::biasesIn(Eigen::VectorXd& flat, int l) const {
    return VectorMap(flat.data() + biasOffset(l), sizes_[l + 1]);
}

int Mlp::maxRows() const { return *std::max_element(sizes_.begin(), sizes_.end()); }

// ---------------------------------------------------------------------------------------------
// Forward pass

namespace {

/// Z = W A + b 1^T, then tanh in place if `hidden` (Z contiguous).
void affineLayer(const Eigen::Ref<const Eigen::MatrixXd>& W, const Eigen::Ref<const Eigen::VectorXd>& b,
                 const Eigen::Ref<const Eigen::MatrixXd>& A, Eigen::Ref<Eigen::MatrixXd> Z, bool hidden) {
    Z.noalias() = W * A;
    Z.colwise() += b;
    if (!hidden) return;
    if (Z.outerStride() == Z.rows())
        tanhInPlace(Z.data(), Z.size());
    else
        for (Eigen::Index j = 0; j < Z.cols(); ++j) tanhInPlace(Z.col(j).data(), Z.rows());
}

void checkShape(const char* what, Eigen::Index rows, Eigen::Index cols, Eigen::Index wantRows,
                Eigen::Index wantCols) {
    if (rows != wantRows || cols != wantCols)
        throw std::invalid_argument(std::string("Mlp: ") + what + " is " + std::to_string(rows) + " x " +
                                    std::to_string(cols) + ", expected " + std::to_string(wantRows) +
                                    " x " + std::to_string(wantCols));
}

}  // namespace

// The double-precision forward pass runs on blocks of kForwardBlock samples stored feature-major
// (element (feature f, sample j) at buf[f * kForwardBlock + j]), so that one packet holds one feature
// of kPacketSize samples. Z = W A + b is then a register-tiled product: a tile of kTileRows outputs
// x kTilePackets packets keeps its 4 x 3 accumulators in registers over the whole input loop, with
// kTilePackets loads and kTileRows broadcasts per 12 FMAs; the block (<= 32 x 96 doubles per
// activation buffer) stays in the L1/L2 cache through all layers. Eigen's general product packs
// its operands for every call, which costs more than the product itself at these sizes.
// A partial block is laid out with the stride of its width, the sample count rounded up to whole
// tiles of every kernel that may run, and padded with zero samples: a batch of 16 computes 24
// columns, not kForwardBlock. Every column goes through the same tile code, so a sample's value does
// not depend on its position in the batch, the batch size or the thread count.
namespace {

constexpr int kTileRows = 4;
constexpr int kTilePackets = 3;
constexpr Eigen::Index kTileSamples = Eigen::Index(kTilePackets) * kPacketSize;
constexpr Eigen::Index kForwardBlock = Mlp::kBlockColumns;
#if defined(TRBC_MLP_AVX2_DISPATCH)
constexpr Eigen::Index kWidthQuantum = std::lcm(kTileSamples, Eigen::Index(mlp_avx2::kTileSamples));
#else
constexpr Eigen::Index kWidthQuantum = kTileSamples;
#endif
static_assert(kForwardBlock % kWidthQuantum == 0, "a block is a whole number of tiles");

/// Columns the kernels compute for n <= kForwardBlock samples.
constexpr Eigen::Index blockWidth(Eigen::Index n) { return (n + kWidthQuantum - 1) / kWidthQuantum * kWidthQuantum; }

/// Rows [i0, i0 + R) of Z = W A + b on one block: W column-major nOut x nIn, A nIn x width and Z
/// nOut x width feature-major.
template <int R>
void affineRows(const double* W, const double* b, Eigen::Index nOut, Eigen::Index nIn, const double* A,
                double* Z, Eigen::Index i0, Eigen::Index width) {
    using namespace Eigen::internal;
    for (Eigen::Index j = 0; j < width; j += kTileSamples) {
        Packet acc[R][kTilePackets];
        for (int r = 0; r < R; ++r)
            for (int c = 0; c < kTilePackets; ++c) acc[r][c] = pset1<Packet>(b[i0 + r]);
        for (Eigen::Index k = 0; k < nIn; ++k) {
            const double* a = A + k * width + j;
            Packet in[kTilePackets];
            for (int c = 0; c < kTilePackets; ++c) in[c] = ploadu<Packet>(a + c * kPacketSize);
            const double* w = W + k * nOut + i0;
            for (int r = 0; r < R; ++r) {
                const Packet wr = pset1<Packet>(w[r]);
                for (int c = 0; c < kTilePackets; ++c) acc[r][c] = pmadd(wr, in[c], acc[r][c]);
            }
        }
        for (int r = 0; r < R; ++r)
            for (int c = 0; c < kTilePackets; ++c)
                pstoreu(Z + (i0 + r) * width + j + c * kPacketSize, acc[r][c]);
    }
}

/// Z = W A + b on one feature-major block of `width` columns, then tanh in place if `hidden`.
void affineBlock(const double* W, const double* b, Eigen::Index nOut, Eigen::Index nIn, const double* A, double* Z,
                 bool hidden, Eigen::Index width) {
#if defined(TRBC_MLP_AVX2_DISPATCH)
    if (simd::active() == simd::Path::avx2) return mlp_avx2::affineBlock(W, b, nOut, nIn, A, Z, hidden, width);
#endif
    Eigen::Index i = 0;
    for (; i + kTileRows <= nOut; i += kTileRows) affineRows<kTileRows>(W, b, nOut, nIn, A, Z, i, width);
    switch (nOut - i) {
        case 3: affineRows<3>(W, b, nOut, nIn, A, Z, i, width); break;
        case 2: affineRows<2>(W, b, nOut, nIn, A, Z, i, width); break;
        case 1: affineRows<1>(W, b, nOut, nIn, A, Z, i, width); break;
        default: break;
    }
    if (hidden) tanhInPlace(Z, nOut * width);
}

}  // namespace

void Mlp::forwardBlock(const Eigen::Ref<const Eigen::MatrixXd>& X, Eigen::Ref<Eigen::MatrixXd> Y,
                       Eigen::VectorXd& bufA, Eigen::VectorXd& bufB) const {
    const Eigen::Index n = X.cols();
    double* in = bufA.data();
    double* out = bufB.data();
    using FeatureMajor = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
    const Eigen::Index width = blockWidth(n);
    FeatureMajor A0(in, X.rows(), width);
    A0.leftCols(n) = X;
    A0.rightCols(width - n).setZero();
    const int L = numLayers();
    for (int l = 0; l < L; ++l) {
        affineBlock(weights(l).data(), biases(l).data(), sizes_[l + 1], sizes_[l], in, out, l + 1 < L, width);
        std::swap(in, out);
    }
    Y = FeatureMajor(in, numOutputs(), width).leftCols(n);
}

namespace {

/// Single-precision copy of the layers and the forward pass of one block with it.
struct FloatLayers {
    std::vector<Eigen::MatrixXf> W;
    std::vector<Eigen::VectorXf> b;
    Eigen::Index maxRows = 0;  ///< widest layer, input included

    explicit FloatLayers(const Mlp& net) {
        for (int l = 0; l < net.numLayers(); ++l) {
            W.push_back(net.weights(l).cast<float>());
            b.push_back(net.biases(l).cast<float>());
        }
        maxRows = *std::max_element(net.layerSizes().begin(), net.layerSizes().end());
    }

    /// Same layer recursion as Mlp::forwardBlock in float arithmetic; bufA, bufB hold
    /// maxRows x block columns.
    void forwardBlock(const Eigen::Ref<const Eigen::MatrixXd>& X, Eigen::Ref<Eigen::MatrixXd> Y, Eigen::VectorXf& bufA,
                      Eigen::VectorXf& bufB) const {
        using MapF = Eigen::Map<Eigen::MatrixXf>;
        const Eigen::Index n = X.cols();
        float* in = bufA.data();
        float* out = bufB.data();
        MapF(in, X.rows(), n) = X.cast<float>();
        for (std::size_t l = 0; l < W.size(); ++l) {
            MapF Z(out, W[l].rows(), n);
            Z.noalias() = W[l] * MapF(in, W[l].cols(), n);
            Z.colwise() += b[l];
            if (l + 1 < W.size()) Z = Z.array().tanh();  // Eigen's vectorised float tanh
            std::swap(in, out);
        }
        Y = MapF(in, Y.rows(), n).cast<double>();
    }
};

}  // namespace

Eigen::MatrixXd Mlp::forward(const Eigen::Ref<const Eigen::MatrixXd>& X, Precision precision) const {
    Eigen::MatrixXd Y(numOutputs(), X.cols());
    forward(X, Y, precision);
    return Y;
}

void Mlp::forward(const Eigen::Ref<const Eigen::MatrixXd>& X, Eigen::Ref<Eigen::MatrixXd> Y,
                  Precision precision) const {
    checkShape("input", X.rows(), X.cols(), numInputs(), X.cols());
    checkShape("output", Y.rows(), Y.cols(), numOutputs(), X.cols());
    const Eigen::Index n = X.cols();
    const bool single = precision == Precision::Single;
    const Eigen::Index blocks = (n + kBlockColumns - 1) / kBlockColumns;
    const int threads = static_cast<int>(std::min<Eigen::Index>(omp_get_max_threads(), blocks));
    std::optional<FloatLayers> floatLayers;
    if (single) floatLayers.emplace(*this);
    const SerialEigenScope serial;  // our threads run whole blocks; Eigen must not nest its own
    (void)simd::active();            // its first call may throw (a bad TRBC_SIMD): not inside the region
#pragma omp parallel num_threads(std::max(threads, 1)) if (threads > 1)
    {
        Eigen::VectorXd bufA(single ? 0 : Eigen::Index(maxRows()) * kBlockColumns), bufB(bufA.size());
        Eigen::VectorXf fa(single ? floatLayers->maxRows * kBlockColumns : 0), fb(fa.size());
#pragma omp for schedule(static)
        for (Eigen::Index b = 0; b < blocks; ++b) {
            const Eigen::Index c0 = b * kBlockColumns, nc = std::min(kBlockColumns, n - c0);
            if (single)
                floatLayers->forwardBlock(X.middleCols(c0, nc), Y.middleCols(c0, nc), fa, fb);
            else
                forwardBlock(X.middleCols(c0, nc), Y.middleCols(c0, nc), bufA, bufB);
        }
    }
}

Eigen::MatrixXd Mlp::inputGradient(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& G) const {
    checkShape("input", X.rows(), X.cols(), numInputs(), X.cols());
    checkShape("output weight", G.rows(), G.cols(), numOutputs(), X.cols());
    const Eigen::Index n = X.cols();
    const int L = numLayers();
    Eigen::MatrixXd out(numInputs(), n);
    const Eigen::Index blocks = (n + kBlockColumns - 1) / kBlockColumns;
    const int threads = static_cast<int>(std::min<Eigen::Index>(omp_get_max_threads(), blocks));
    const SerialEigenScope serial;
#pragma omp parallel num_threads(std::max(threads, 1)) if (threads > 1)
    {
        std::vector<Eigen::MatrixXd> a(L);  // a[l] = a_l, the hidden activations (l = 1..L-1)
        Eigen::MatrixXd delta, back;
#pragma omp for schedule(static)
        for (Eigen::Index b = 0; b < blocks; ++b) {
            const Eigen::Index c0 = b * kBlockColumns, nc = std::min(kBlockColumns, n - c0);
            for (int l = 1; l < L; ++l) {
                a[l].resize(sizes_[l], nc);
                if (l == 1)
                    affineLayer(weights(0), biases(0), X.middleCols(c0, nc), a[1], true);
                else
                    affineLayer(weights(l - 1), biases(l - 1), a[l - 1], a[l], true);
            }
            delta = G.middleCols(c0, nc);
            for (int l = L - 1; l >= 1; --l) {
                back.noalias() = weights(l).transpose() * delta;
                delta = back.array() * (1.0 - a[l].array().square());
            }
            out.middleCols(c0, nc).noalias() = weights(0).transpose() * delta;
        }
    }
    return out;
}

double Mlp::loss(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& Y) const {
    checkShape("input", X.rows(), X.cols(), numInputs(), X.cols());
    checkShape("target", Y.rows(), Y.cols(), numOutputs(), X.cols());
    const Eigen::Index n = X.cols();
    const SerialEigenScope serial;
    Eigen::VectorXd bufA(Eigen::Index(maxRows()) * kBlockColumns), bufB(bufA.size());
    Eigen::MatrixXd out(numOutputs(), kBlockColumns);
    double sum = 0.0;
    for (Eigen::Index c0 = 0; c0 < n; c0 += kBlockColumns) {
        const Eigen::Index nc = std::min(kBlockColumns, n - c0);
        auto o = out.leftCols(nc);
        forwardBlock(X.middleCols(c0, nc), o, bufA, bufB);
        sum += (o - Y.middleCols(c0, nc)).squaredNorm();
    }
    return sum / (static_cast<double>(numOutputs()) * static_cast<double>(n));
}

// ---------------------------------------------------------------------------------------------
// Back-propagation of the MSE loss
//
// L = 1/(m n) sum (a_L - y)^2,  m = n_L outputs, n samples.
// delta_{L-1} = dL/dz_{L-1} = 2 (a_L - y) / (m n);
// dL/dW_l = delta_l a_l^T,  dL/db_l = delta_l 1;
// delta_{l-1} = (W_l^T delta_l) .* (1 - a_l^2)      (tanh' = 1 - tanh^2).

double Mlp::lossAndGradient(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& Y,
                            Eigen::VectorXd& grad, MlpWorkspace& ws) const {
    checkShape("input", X.rows(), X.cols(), numInputs(), X.cols());
    checkShape("target", Y.rows(), Y.cols(), numOutputs(), X.cols());
    const Eigen::Index n = X.cols();
    const int L = numLayers();
    const SerialEigenScope serial;
    ws.activations.resize(L + 1);  // [0] unused: a_0 is X itself
    for (int l = 0; l < L; ++l) {
        Eigen::MatrixXd& Z = ws.activations[l + 1];
        Z.resize(sizes_[l + 1], n);
        if (l == 0)
            affineLayer(weights(0), biases(0), X, Z, L > 1);
        else
            affineLayer(weights(l), biases(l), ws.activations[l], Z, l < L - 1);
    }
    const double scale = 1.0 / (static_cast<double>(numOutputs()) * static_cast<double>(n));
    ws.delta = ws.activations[L] - Y;
    const double lossValue = ws.delta.squaredNorm() * scale;
    ws.delta *= 2.0 * scale;

    grad.resize(params_.size());
    for (int l = L - 1; l >= 0; --l) {
        if (l == 0)
            weightsIn(grad, 0).noalias() = ws.delta * X.transpose();
        else
            weightsIn(grad, l).noalias() = ws.delta * ws.activations[l].transpose();
        biasesIn(grad, l) = ws.delta.rowwise().sum();
        if (l > 0) {
            ws.deltaPrev.resize(sizes_[l], n);
            ws.deltaPrev.noalias() = weights(l).transpose() * ws.delta;
            ws.deltaPrev.array() *= 1.0 - ws.activations[l].array().square();
            std::swap(ws.delta, ws.deltaPrev);
        }
    }
    return lossValue;
}

}  // namespace trbc
