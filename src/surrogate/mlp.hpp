#pragma once
// Fully connected network of the surrogates (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training): arbitrary layer sizes
// n_0 -> n_1 -> ... -> n_L, tanh after every hidden layer, linear output layer, biases everywhere.
//
// Data are column-major, one sample per column: a batch X is n_0 x n, the output n_L x n.
// Layer l (l = 0..L-1) maps a_l (n_l) to z_l = W_l a_l + b_l (n_{l+1}); a_{l+1} = tanh(z_l) for
// hidden layers, the network output is z_{L-1}.
//
// All parameters live in one flat vector [W_0 (column-major), b_0, W_1, b_1, ...] so that Adam,
// copies of the best weights and gradients are plain vector operations; weights(l) / biases(l) are
// views into it.
#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace trbc {

/// tanh of n contiguous doubles in place, vectorised (at most 2.4 ulp from the long-double value;
/// NaN propagates, +-inf gives +-1).
/// Used by every forward pass (training and evaluation), so both see the same function.
void tanhInPlace(double* x, Eigen::Index n);

/// While alive, Eigen's matrix products called from this thread run single-threaded (Eigen
/// otherwise starts its own OpenMP team for products as small as 32 x 32 x 128, which is slow and
/// would make the rounding depend on the thread count). Saves and restores omp_get_max_threads()
/// of the calling thread only.
class SerialEigenScope {
public:
    SerialEigenScope();
    ~SerialEigenScope();
    SerialEigenScope(const SerialEigenScope&) = delete;
    SerialEigenScope& operator=(const SerialEigenScope&) = delete;

private:
    int saved_;
};

/// Reusable buffers of the forward/backward pass of one mini-batch (no allocation in the loop).
struct MlpWorkspace {
    std::vector<Eigen::MatrixXd> activations;  ///< a_0 (input copy) .. a_L (output)
    Eigen::MatrixXd delta, deltaPrev;          ///< dLoss/dz of the current / previous layer
};

/// Arithmetic of a batched forward pass (see Mlp::forward).
enum class Precision { Double, Single };

class Mlp {
public:
    using MatrixMap = Eigen::Map<Eigen::MatrixXd>;
    using ConstMatrixMap = Eigen::Map<const Eigen::MatrixXd>;
    using VectorMap = Eigen::Map<Eigen::VectorXd>;
    using ConstVectorMap = Eigen::Map<const Eigen::VectorXd>;

    Mlp() = default;
    /// Network with layer sizes (n_0, ..., n_L), L >= 1, all n_l >= 1; all parameters zero.
    explicit Mlp(std::vector<int> layerSizes);
    /// Glorot/Xavier-uniform weights W_l ~ U[-a, a], a = sqrt(6 / (n_l + n_{l+1})), biases 0.01
    /// (SURROGATE 3.3). Drawn from a std::mt19937_64 seeded with `seed`, layer by layer, W_l in
    /// column-major order: bit-identical on every platform for a given seed.
    static Mlp glorotUniform(std::vector<int> layerSizes, std::uint64_t seed);

    const std::vector<int>& layerSizes() const { return sizes_; }
    int numInputs() const { return sizes_.empty() ? 0 : sizes_.front(); }
    int numOutputs() const { return sizes_.empty() ? 0 : sizes_.back(); }
    int numLayers() const { return static_cast<int>(sizes_.size()) - 1; }  ///< weight layers L
    Eigen::Index numParameters() const { return params_.size(); }

    /// All parameters as one vector (layout above); setParameters checks the size.
    const Eigen::VectorXd& parameters() const { return params_; }
    void setParameters(const Eigen::VectorXd& p);
    VectorMap mutableParameters() { return VectorMap(params_.data(), params_.size()); }

    ConstMatrixMap weights(int l) const { return weightsIn(params_, l); }  ///< W_l, n_{l+1} x n_l
    MatrixMap weights(int l) { return weightsIn(params_, l); }
    ConstVectorMap biases(int l) const { return biasesIn(params_, l); }  ///< b_l, n_{l+1}
    VectorMap biases(int l) { return biasesIn(params_, l); }
    /// Views of layer l inside any vector with the parameter layout (e.g. a gradient).
    ConstMatrixMap weightsIn(const Eigen::VectorXd& flat, int l) const;
    MatrixMap weightsIn(Eigen::VectorXd& flat, int l) const;
    ConstVectorMap biasesIn(const Eigen::VectorXd& flat, int l) const;
    VectorMap biasesIn(Eigen::VectorXd& flat, int l) const;

    /// Y = NN(X) for X n_0 x n. Processed in blocks of kBlockColumns columns, OpenMP-parallel over
    /// blocks (omp_get_max_threads() threads); every column's value is independent of the thread
    /// count and of the other columns.
    /// Precision::Single evaluates with a float copy of the weights and Eigen's float tanh (inputs
    /// and outputs stay double): about 3x the throughput, relative deviation ~1e-6 from the double
    /// result (the reference implementation ran in float). Training always uses double.
    Eigen::MatrixXd forward(const Eigen::Ref<const Eigen::MatrixXd>& X, Precision precision = Precision::Double) const;
    void forward(const Eigen::Ref<const Eigen::MatrixXd>& X, Eigen::Ref<Eigen::MatrixXd> Y,
                 Precision precision = Precision::Double) const;

    /// Mean squared error of NN(X) against Y, averaged over outputs and samples (SURROGATE 3.4):
    /// sum_{i,j} (NN(X)_ij - Y_ij)^2 / (n_L n). Serial, blockwise, fixed summation order.
    double loss(const Eigen::Ref<const Eigen::MatrixXd>& X,
                const Eigen::Ref<const Eigen::MatrixXd>& Y) const;

    /// The same loss for one batch and its gradient with respect to all parameters (back-propagation;
    /// `grad` gets the parameter layout). Serial.
    double lossAndGradient(const Eigen::Ref<const Eigen::MatrixXd>& X,
                           const Eigen::Ref<const Eigen::MatrixXd>& Y, Eigen::VectorXd& grad,
                           MlpWorkspace& ws) const;

    /// Input gradient of sum_i G_ij NN(X)_ij for every column j, i.e. J_j^T G_j with J_j = dNN/dx at
    /// column j (n_0 x n; G is n_L x n). Back-propagation through the layers: delta_{L-1} = G,
    /// delta_{l-1} = (W_l^T delta_l) .* (1 - a_l^2), result W_0^T delta_0. Double precision, in blocks
    /// of kBlockColumns columns, OpenMP-parallel over blocks like forward().
    Eigen::MatrixXd inputGradient(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& G) const;

    /// Samples per block: 8 register tiles of 3 packets (96 with AVX2, 192 with AVX-512), see the
    /// forward kernel; a smaller batch computes only the tiles it fills.
    static constexpr Eigen::Index kBlockColumns = 24 * Eigen::internal::packet_traits<double>::size;

private:
    Eigen::Index weightOffset(int l) const { return offsets_[l]; }
    Eigen::Index biasOffset(int l) const { return offsets_[l] + Eigen::Index(sizes_[l + 1]) * sizes_[l]; }
    /// Forward pass of one block of at most kBlockColumns columns, serial; buffers hold
    /// maxRows() x kBlockColumns.
    void forwardBlock(const Eigen::Ref<const Eigen::MatrixXd>& X, Eigen::Ref<Eigen::MatrixXd> Y,
                      Eigen::VectorXd& bufA, Eigen::VectorXd& bufB) const;
    int maxRows() const;  ///< widest layer, input included

    std::vector<int> sizes_;
    std::vector<Eigen::Index> offsets_;  ///< start of W_l in params_
    Eigen::VectorXd params_;
};

}  // namespace trbc
