#pragma once
// Training of a surrogate network with the schedule of docs/CAMPAIGN_AND_SURROGATE.md, surrogate training (the reference
// implementation's, marked "used" there):
//
//  * loss: MSE on standardised outputs, averaged over outputs and samples;
//  * split: a seeded permutation of all rows; the first n_train = ceil(0.8 n / B) B rows train,
//    the rest validate (B = mini-batch size), so every training mini-batch is full;
//    optionally a test set drawn first with its own seed, used neither for training nor
//    for early stopping (the 3.4 split is then applied to the remaining rows);
//  * Adam (beta1 0.9, beta2 0.999, eps 1e-8, no weight decay), learning rate 0.1, mini-batches
//    reshuffled every epoch;
//  * epoch loop, at most maxEpochs (5000), at the start of every epoch:
//      1. validation loss of the current weights;
//      2. below the best so far: keep a copy of the weights, counter = 0; else counter += 1;
//      3. counter > patience (10): restore the best weights, counter = 0, rate /= 10 (the Adam
//         moments are not reset), one more reduction;
//      4. after the 5th reduction stop (the restored best weights are the result);
//      5. otherwise one pass over the mini-batches (epoch 0: gradients but no optimiser step).
//    If the epoch cap is reached, the weights after the last pass are validated once more and the
//    best weights seen are returned with hitEpochCap = true (the reference returned the last ones).
//
// Determinism: everything runs on the calling thread (Eigen's products are kept serial), the
// random streams are std::mt19937_64 with explicit integer-to-index/real maps, so for fixed seeds
// split, initial weights, mini-batch order and final weights are bit-identical on every run and
// independent of the OpenMP thread count.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "surrogate/mlp.hpp"
#include "surrogate/scaling.hpp"

namespace trbc {

/// What the progress callback receives once per epoch record (see TrainingHistory).
struct EpochRecord {
    int epoch = 0;
    double trainLoss = 0.0;           ///< NaN for the final record (no pass ran)
    double validationLoss = 0.0;      ///< at the start of the epoch
    double bestValidationLoss = 0.0;  ///< best so far, including this epoch
    double learningRate = 0.0;        ///< rate of this epoch's pass
    bool improved = false;            ///< this epoch's validation loss is a new best
    bool reduced = false;             ///< best weights restored and rate divided at this epoch
    int reductions = 0;               ///< reductions so far
    bool last = false;                ///< training ends with this record
};

/// Transform of one network variable before its z-score scaling: the network sees log(x) for
/// `Log` (x > 0; scale parameters spanning decades such as mu, eta_m and FvK, and positive outputs
/// whose relative error matters), sqrt(x) for `Sqrt` (x >= 0; a parameter whose effect sets in
/// at a scale ~ 1/sqrt(x), such as the Lim hardening b2 in stretching). Applied inside
/// TrainedNetwork::evaluate, so callers always pass and receive physical values.
enum class VariableTransform { Identity, Log, Sqrt };

struct TrainingOptions {
    std::vector<int> hiddenLayers{32, 32, 32};  ///< SURROGATE 3.3
    /// Per input / output row; empty means Identity for every row.
    std::vector<VariableTransform> inputTransforms, outputTransforms;
    int batchSize = 128;                        ///< B (3.1: 256 equilibrium, 128 otherwise)
    std::uint64_t splitSeed = 12345;            ///< permutation of the rows
    std::uint64_t seed = 1;                     ///< initial weights and mini-batch order
    double trainFraction = 0.8;                 ///< n_train = ceil(trainFraction n / B) B
    double testFraction = 0.0;                  ///< held-out test rows, 0: none
    std::uint64_t testSeed = 2718281828;        ///< permutation choosing the test rows
    double learningRate = 0.1;
    double beta1 = 0.9, beta2 = 0.999, epsilon = 1e-8;  ///< Adam
    int patience = 10;            ///< reduce when the no-improvement counter exceeds this
    double reductionFactor = 0.1; ///< rate *= factor at each reduction
    int maxReductions = 5;        ///< stop after this many reductions
    int maxEpochs = 5000;
    std::function<void(const EpochRecord&)> progress;  ///< called after every epoch record
};

/// Row indices (into the columns of the data) of the three sets. Training and validation rows are in
/// permutation order, test rows ascending.
struct DataSplit {
    std::vector<Eigen::Index> train, validation, test;
};

/// Per-epoch record of a training run. Entry e of the three loss/rate vectors belongs to epoch e;
/// the last entry is the validation at which training stopped (5th reduction, or the check after
/// the epoch cap) and has no pass, so its trainLoss is NaN.
struct TrainingHistory {
    std::vector<double> trainLoss;       ///< mean of the mini-batch losses of pass e
    std::vector<double> validationLoss;  ///< validation loss at the start of epoch e
    std::vector<double> learningRate;    ///< rate of pass e (after a reduction at its start)
    std::vector<int> reductionEpochs;    ///< epochs at whose start best weights were restored, rate / 10
    std::vector<double> restoredValidationLoss;  ///< validation loss recomputed after each restore
    int bestEpoch = -1;  ///< returned weights = those validated at the start of this epoch
    double bestValidationLoss = std::numeric_limits<double>::infinity();
    bool hitEpochCap = false;  ///< stopped by maxEpochs, not by the 5th reduction
    double testLoss = std::numeric_limits<double>::quiet_NaN();  ///< standardised MSE on the test rows
    int passes() const { return static_cast<int>(trainLoss.size()) - 1; }  ///< training passes run
};

/// A further member of an ensemble network: another training of the same data, scalings and
/// transforms from other initial weights.
struct EnsembleMember {
    Mlp net;
    std::uint64_t seed = 0;                 ///< its initial-weight seed
    double bestValidationLoss = 0.0;        ///< its early-stopping loss (standardised MSE)
};

/// A trained network with everything needed to evaluate it in physical units and to trace it back
/// (SURROGATE 3.6): y = T_y^-1(s_y .* NN((T_x(x) - m_x) ./ s_x) + m_y), T the per-variable
/// transforms (identity unless the network was trained with log variables).
/// With ensemble members, NN is the mean of the K = 1 + ensemble.size() networks' standardised
/// outputs, NN = (NN_net + sum_k NN_k) / K: the arithmetic mean of the members' predictions of an
/// identity output, their geometric mean for a log output.
struct TrainedNetwork {
    Mlp net;                              ///< the member with the lowest validation loss
    std::vector<EnsembleMember> ensemble;  ///< further members (empty: a single network)
    Standardisation inputScaling, outputScaling;  ///< of the transformed variables
    std::vector<VariableTransform> inputTransforms, outputTransforms;  ///< one per row, or empty (identity)
    std::vector<std::string> inputNames, outputNames;
    std::string dataHash;  ///< hash of the data file the network was trained on
    std::string command;   ///< command line that made it
    TrainingOptions options;  ///< settings of the run (progress callback not kept)
    TrainingHistory history;
    /// Set (members > 0) when this single network was distilled from an ensemble: trained on the
    /// ensemble's predictions at `samples` points of a design of seed `seed` (uniform over the prior
    /// box for the cell surrogates, Sobol' over the campaign's box for the flow networks); history and
    /// options are then the student's, `teacherValidationLoss` the best member's early-stopping loss.
    struct Distillation {
        int members = 0;
        long samples = 0;
        std::uint64_t seed = 0;
        double teacherValidationLoss = 0.0;
    } distillation;

    /// Physical outputs for physical inputs, X numInputs x n (one sample per column); batched and
    /// OpenMP-parallel like Mlp::forward (whose precision option it passes on).
    Eigen::MatrixXd evaluate(const Eigen::Ref<const Eigen::MatrixXd>& X,
                             Precision precision = Precision::Double) const;

    /// Input gradient of sum_i G_ij y_ij for every column j of physical inputs X (numInputs x n),
    /// G numOutputs x n, in double precision: back-propagation through the output transform
    /// (dy/dy' = 1, y for log, 2 max(0, y') for sqrt), the output scaling (s_y), the network (mean
    /// over the ensemble members, Mlp::inputGradient), the input scaling (1/s_x) and the input
    /// transform (1, 1/x for log, 1/(2 sqrt x) for sqrt). Returns numInputs x n.
    Eigen::MatrixXd inputGradient(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& G) const;
};

struct TrainingResult {
    TrainedNetwork network;
    DataSplit split;
};

/// InputError "training options: ..." unless batch size >= 1, 0 < trainFraction <= 1,
/// 0 <= testFraction < 1, learning rate > 0, 0 < reduction factor < 1, patience >= 0,
/// maxReductions, maxEpochs >= 1, hidden widths >= 1.
void checkTrainingOptions(const TrainingOptions& options);

/// Uniformly random permutation of 0..n-1 (Fisher-Yates, std::mt19937_64(seed), unbiased
/// rejection sampling of the indices): the same on every platform.
std::vector<Eigen::Index> seededPermutation(Eigen::Index n, std::uint64_t seed);

/// n_train = min(n, ceil(trainFraction n / B) B), evaluated in double as the reference does.
Eigen::Index trainingRowCount(Eigen::Index n, int batchSize, double trainFraction = 0.8);

/// The split of 3.4 (and 5.2.1 if options.testFraction > 0) of n rows. Depends only on n and the
/// options' batch size, fractions and seeds. Throws InputError if a set would be empty.
DataSplit splitRows(Eigen::Index n, const TrainingOptions& options);

/// The schedule of `o` for a table of `rows` rows. SURROGATE 3.1's batches (256 / 128) and patience
/// (10 epochs) are for the paper's 50,000 rows; patience counts epochs, so a small table needs
/// smaller batches to take enough optimiser steps per epoch: at least 50 mini-batches per epoch,
/// batches of 8 to maxBatch (smaller only where whole batches of 8 would leave no validation row),
/// and at least ~3000 optimiser steps without improvement before a rate reduction (the paper's 11
/// epochs of 50,000 rows are ~3400 steps).
TrainingOptions scheduleForRows(TrainingOptions o, Eigen::Index rows, int maxBatch);

/// The epoch loop on already standardised, already split data (columns = samples). `net` holds the
/// initial weights on entry and the best weights on return. Serial.
TrainingHistory trainMlp(Mlp& net, const Eigen::Ref<const Eigen::MatrixXd>& Xtrain,
                         const Eigen::Ref<const Eigen::MatrixXd>& Ytrain,
                         const Eigen::Ref<const Eigen::MatrixXd>& Xval,
                         const Eigen::Ref<const Eigen::MatrixXd>& Yval, const TrainingOptions& options);

/// `x` with row i replaced by log(x_i) where transforms[i] is Log (NaN for x <= 0), and the inverse.
Eigen::MatrixXd applyTransforms(const Eigen::Ref<const Eigen::MatrixXd>& x, const std::vector<VariableTransform>& transforms);
void invertTransformsInPlace(Eigen::Ref<Eigen::MatrixXd> y, const std::vector<VariableTransform>& transforms);

/// Whole procedure on physical data X (inputs x n), Y (outputs x n): options' transforms, then standardisation over all n
/// columns, split, Glorot initialisation with options.seed, trainMlp, test loss. Names are
/// stored with the network (and used in error messages; default x0.., y0..); dataHash/command are left empty for the
/// caller. Throws InputError on inconsistent sizes, non-finite values or constant columns.
TrainingResult trainNetwork(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& Y,
                            const TrainingOptions& options, std::vector<std::string> inputNames = {},
                            std::vector<std::string> outputNames = {});

/// One network trained to reproduce an ensemble's predictions at the points X (physical inputs, one
/// per column): the ensemble's mean is the target, with the teacher's transforms and the schedule
/// `o` (its layers; batch 128 and the patience re-derived for the larger table, at least ~3000
/// steps). `designSeed` (the seed of the points) is recorded in `distillation`.
TrainedNetwork distilledNetwork(const TrainedNetwork& teacher, const Eigen::Ref<const Eigen::MatrixXd>& X, std::uint64_t designSeed,
                                TrainingOptions o);

}  // namespace trbc
