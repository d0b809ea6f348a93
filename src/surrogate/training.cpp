#include "surrogate/training.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "core/error.hpp"

namespace trbc {

namespace {

/// Unbiased index in [0, k) from a 64-bit stream: reject the lowest 2^64 mod k raw values.
std::uint64_t uniformIndex(std::mt19937_64& rng, std::uint64_t k) {
    const std::uint64_t threshold = (0 - k) % k;  // = 2^64 mod k
    std::uint64_t x = rng();
    while (x < threshold) x = rng();
    return x % k;
}

/// Fisher-Yates shuffle in place.
template <typename T>
void shuffle(std::vector<T>& v, std::mt19937_64& rng) {
    for (std::size_t i = v.size(); i > 1; --i) std::swap(v[i - 1], v[uniformIndex(rng, i)]);
}

/// SplitMix64 finaliser: a seed for a second, unrelated stream from the user's seed.
std::uint64_t deriveSeed(std::uint64_t seed) {
    std::uint64_t z = seed + 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

Eigen::MatrixXd gatherColumns(const Eigen::Ref<const Eigen::MatrixXd>& A, const std::vector<Eigen::Index>& cols) {
    Eigen::MatrixXd out(A.rows(), static_cast<Eigen::Index>(cols.size()));
    for (std::size_t k = 0; k < cols.size(); ++k) out.col(static_cast<Eigen::Index>(k)) = A.col(cols[k]);
    return out;
}

}  // namespace

void checkTrainingOptions(const TrainingOptions& o) {
    const auto fail = [](const std::string& what) { throw InputError("training options: " + what); };
    if (o.batchSize < 1) fail("batch size must be >= 1");
    if (!(o.trainFraction > 0.0 && o.trainFraction <= 1.0)) fail("train fraction must be in (0, 1]");
    if (!(o.testFraction >= 0.0 && o.testFraction < 1.0)) fail("test fraction must be in [0, 1)");
    if (!(o.learningRate > 0.0)) fail("learning rate must be > 0");
    if (!(o.reductionFactor > 0.0 && o.reductionFactor < 1.0)) fail("reduction factor must be in (0, 1)");
    if (o.patience < 0 || o.maxReductions < 1 || o.maxEpochs < 1)
        fail("patience must be >= 0, max reductions and max epochs >= 1");
    for (int h : o.hiddenLayers)
        if (h < 1) fail("hidden layer widths must be >= 1");
}

namespace {

/// Adam step (PyTorch's form): m = b1 m + (1-b1) g, v = b2 v + (1-b2) g^2,
/// theta -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps).
struct Adam {
    Eigen::VectorXd m, v;
    long long t = 0;

    explicit Adam(Eigen::Index n) : m(Eigen::VectorXd::Zero(n)), v(Eigen::VectorXd::Zero(n)) {}

    void step(Eigen::Ref<Eigen::VectorXd> theta, const Eigen::VectorXd& g, double lr, const TrainingOptions& o) {
        ++t;
        m = o.beta1 * m + (1.0 - o.beta1) * g;
        v = o.beta2 * v + (1.0 - o.beta2) * g.cwiseAbs2();
        const double bc1 = 1.0 - std::pow(o.beta1, static_cast<double>(t));
        const double bc2 = 1.0 - std::pow(o.beta2, static_cast<double>(t));
        theta.array() -= (lr / bc1) * m.array() / (v.array().sqrt() / std::sqrt(bc2) + o.epsilon);
    }
};

}  // namespace

std::vector<Eigen::Index> seededPermutation(Eigen::Index n, std::uint64_t seed) {
    std::vector<Eigen::Index> p(static_cast<std::size_t>(n));
    for (Eigen::Index i = 0; i < n; ++i) p[static_cast<std::size_t>(i)] = i;
    std::mt19937_64 rng(seed);
    shuffle(p, rng);
    return p;
}

Eigen::Index trainingRowCount(Eigen::Index n, int batchSize, double trainFraction) {
    // ceil(0.8 n / B) B, in double like the reference's numpy expression
    const auto batches = static_cast<Eigen::Index>(std::ceil(trainFraction * static_cast<double>(n) / batchSize));
    return std::min(n, batches * batchSize);
}

DataSplit splitRows(Eigen::Index n, const TrainingOptions& o) {
    checkTrainingOptions(o);
    DataSplit s;
    // 5.2.1: test rows first, with their own seed, so the test set does not depend on B or splitSeed
    std::vector<Eigen::Index> rest;
    const auto nTest = static_cast<Eigen::Index>(std::llround(o.testFraction * static_cast<double>(n)));
    if (nTest > 0) {
        const std::vector<Eigen::Index> p = seededPermutation(n, o.testSeed);
        s.test.assign(p.begin(), p.begin() + nTest);
        rest.assign(p.begin() + nTest, p.end());
        std::sort(s.test.begin(), s.test.end());
        std::sort(rest.begin(), rest.end());
    } else {
        rest.resize(static_cast<std::size_t>(n));
        for (Eigen::Index i = 0; i < n; ++i) rest[static_cast<std::size_t>(i)] = i;
    }
    // 3.4 on the remaining m rows: permutation, first n_train train, the rest validate
    const auto m = static_cast<Eigen::Index>(rest.size());
    const std::vector<Eigen::Index> q = seededPermutation(m, o.splitSeed);
    const Eigen::Index nTrain = trainingRowCount(m, o.batchSize, o.trainFraction);
    for (Eigen::Index k = 0; k < m; ++k) (k < nTrain ? s.train : s.validation).push_back(rest[q[k]]);
    if (s.train.empty() || s.validation.empty())
        throw InputError("training split: " + std::to_string(n) + " rows give " + std::to_string(s.train.size()) +
                         " training and " + std::to_string(s.validation.size()) +
                         " validation rows (batch size " + std::to_string(o.batchSize) + "); need at least one each");
    return s;
}

TrainingHistory trainMlp(Mlp& net, const Eigen::Ref<const Eigen::MatrixXd>& Xtrain,
                         const Eigen::Ref<const Eigen::MatrixXd>& Ytrain, const Eigen::Ref<const Eigen::MatrixXd>& Xval,
                         const Eigen::Ref<const Eigen::MatrixXd>& Yval, const TrainingOptions& o) {
    checkTrainingOptions(o);
    if (Xtrain.cols() == 0 || Xval.cols() == 0) throw InputError("training: empty training or validation set");
    const SerialEigenScope serial;
    const Eigen::Index nTrain = Xtrain.cols();
    const Eigen::Index B = std::min<Eigen::Index>(o.batchSize, nTrain);
    const Eigen::Index nBatches = (nTrain + B - 1) / B;  // the 3.4 split makes every batch full

    std::mt19937_64 shuffleRng(deriveSeed(o.seed));
    std::vector<Eigen::Index> order(static_cast<std::size_t>(nTrain));
    for (Eigen::Index i = 0; i < nTrain; ++i) order[static_cast<std::size_t>(i)] = i;

    Adam adam(net.numParameters());
    MlpWorkspace ws;
    Eigen::VectorXd grad;
    Eigen::MatrixXd Xb(Xtrain.rows(), B), Yb(Ytrain.rows(), B);
    Eigen::VectorXd best = net.parameters();
    TrainingHistory h;
    int counter = 0;
    double lr = o.learningRate;

    for (int epoch = 0;; ++epoch) {
        EpochRecord r;
        r.epoch = epoch;
        r.validationLoss = net.loss(Xval, Yval);  // 1.
        r.improved = r.validationLoss < h.bestValidationLoss;  // 2.
        if (r.improved) {
            h.bestValidationLoss = r.validationLoss;
            h.bestEpoch = epoch;
            best = net.parameters();
            counter = 0;
        } else {
            ++counter;
        }
        const bool capped = epoch == o.maxEpochs;  // the check after the last allowed pass
        if (!capped && counter > o.patience) {      // 3.
            net.setParameters(best);
            counter = 0;
            lr *= o.reductionFactor;
            r.reduced = true;
            h.reductionEpochs.push_back(epoch);
            h.restoredValidationLoss.push_back(net.loss(Xval, Yval));
        }
        r.reductions = static_cast<int>(h.reductionEpochs.size());
        r.learningRate = lr;
        r.bestValidationLoss = h.bestValidationLoss;
        r.last = capped || r.reductions >= o.maxReductions;  // 4.
        r.trainLoss = std::numeric_limits<double>::quiet_NaN();

        if (!r.last) {  // 5. one pass over reshuffled mini-batches
            shuffle(order, shuffleRng);
            double sum = 0.0;
            for (Eigen::Index b = 0; b < nBatches; ++b) {
                const Eigen::Index c0 = b * B, nb = std::min(B, nTrain - c0);
                for (Eigen::Index k = 0; k < nb; ++k) {
                    const Eigen::Index c = order[static_cast<std::size_t>(c0 + k)];
                    Xb.col(k) = Xtrain.col(c);
                    Yb.col(k) = Ytrain.col(c);
                }
                sum += net.lossAndGradient(Xb.leftCols(nb), Yb.leftCols(nb), grad, ws);
                if (epoch > 0) adam.step(net.mutableParameters(), grad, lr, o);  // epoch 0: no step
            }
            r.trainLoss = sum / static_cast<double>(nBatches);
        }
        h.trainLoss.push_back(r.trainLoss);
        h.validationLoss.push_back(r.validationLoss);
        h.learningRate.push_back(r.learningRate);
        if (o.progress) o.progress(r);
        if (r.last) {
            h.hitEpochCap = capped;
            break;
        }
    }
    net.setParameters(best);
    return h;
}

TrainingOptions scheduleForRows(TrainingOptions o, Eigen::Index rows, int maxBatch) {
    o.batchSize = std::clamp(int(0.8 * double(rows) / 50.0), 8, std::max(8, maxBatch));
    // A table so small that whole batches would take every row: smaller batches leave validation rows.
    while (o.batchSize > 1 && trainingRowCount(rows, o.batchSize, o.trainFraction) >= rows) --o.batchSize;
    const double batchesPerEpoch = std::max(1.0, 0.8 * double(rows) / o.batchSize);
    o.patience = std::max(o.patience, int(std::ceil(3000.0 / batchesPerEpoch)));
    return o;
}

TrainingResult trainNetwork(const Eigen::Ref<const Eigen::MatrixXd>& X, const Eigen::Ref<const Eigen::MatrixXd>& Y,
                            const TrainingOptions& options, std::vector<std::string> inputNames,
                            std::vector<std::string> outputNames) {
    checkTrainingOptions(options);
    if (X.cols() != Y.cols())
        throw InputError("training: " + std::to_string(X.cols()) + " input rows but " + std::to_string(Y.cols()) +
                         " output rows");
    if (X.rows() == 0 || Y.rows() == 0) throw InputError("training: no input or no output variables");
    if (!inputNames.empty() && static_cast<Eigen::Index>(inputNames.size()) != X.rows())
        throw InputError("training: " + std::to_string(inputNames.size()) + " input names for " +
                         std::to_string(X.rows()) + " inputs");
    if (!outputNames.empty() && static_cast<Eigen::Index>(outputNames.size()) != Y.rows())
        throw InputError("training: " + std::to_string(outputNames.size()) + " output names for " +
                         std::to_string(Y.rows()) + " outputs");

    const auto defaultNames = [](std::vector<std::string>& names, Eigen::Index n, char letter) {
        for (auto i = static_cast<Eigen::Index>(names.size()); i < n; ++i) names.push_back(std::string(1, letter).append(std::to_string(i)));
    };
    defaultNames(inputNames, X.rows(), 'x');  // x0, x1, ...
    defaultNames(outputNames, Y.rows(), 'y');
    const auto checkTransforms = [](const std::vector<VariableTransform>& t, const Eigen::Ref<const Eigen::MatrixXd>& data,
                                    const std::vector<std::string>& names, const char* what) {
        if (!t.empty() && Eigen::Index(t.size()) != data.rows())
            throw InputError(fmt::format("training: {} {} transforms for {} {}s", t.size(), what, data.rows(), what));
        for (std::size_t i = 0; i < t.size(); ++i) {
            if (t[i] == VariableTransform::Identity) continue;
            const bool log = t[i] == VariableTransform::Log;
            for (Eigen::Index j = 0; j < data.cols(); ++j) {
                const double x = data(Eigen::Index(i), j);
                if (log ? !(x > 0) : !(x >= 0))
                    throw InputError(fmt::format("training: {} '{}' is trained as {}({}) but sample {} has {} (must be {} 0)",
                                                 what, names[i], log ? "log" : "sqrt", names[i], j, x, log ? ">" : ">="));
            }
        }
    };
    checkTransforms(options.inputTransforms, X, inputNames, "input");
    checkTransforms(options.outputTransforms, Y, outputNames, "output");

    TrainingResult result;
    TrainedNetwork& tn = result.network;
    tn.inputNames = std::move(inputNames);
    tn.outputNames = std::move(outputNames);
    tn.options = options;
    tn.options.progress = nullptr;
    tn.inputTransforms = options.inputTransforms;
    tn.outputTransforms = options.outputTransforms;
    // 3.2: scaling over all rows of the (transformed) data
    const Eigen::MatrixXd Xt = applyTransforms(X, tn.inputTransforms), Yt = applyTransforms(Y, tn.outputTransforms);
    tn.inputScaling = Standardisation::fit(Xt, tn.inputNames);
    tn.outputScaling = Standardisation::fit(Yt, tn.outputNames);
    const Eigen::MatrixXd Xs = tn.inputScaling.apply(Xt), Ys = tn.outputScaling.apply(Yt);

    result.split = splitRows(X.cols(), options);
    const DataSplit& s = result.split;
    std::vector<int> sizes{static_cast<int>(X.rows())};
    sizes.insert(sizes.end(), options.hiddenLayers.begin(), options.hiddenLayers.end());
    sizes.push_back(static_cast<int>(Y.rows()));
    tn.net = Mlp::glorotUniform(sizes, options.seed);
    tn.history = trainMlp(tn.net, gatherColumns(Xs, s.train), gatherColumns(Ys, s.train),
                          gatherColumns(Xs, s.validation), gatherColumns(Ys, s.validation), options);
    if (!s.test.empty()) tn.history.testLoss = tn.net.loss(gatherColumns(Xs, s.test), gatherColumns(Ys, s.test));
    return result;
}

Eigen::MatrixXd applyTransforms(const Eigen::Ref<const Eigen::MatrixXd>& x, const std::vector<VariableTransform>& transforms) {
    Eigen::MatrixXd out = x;
    for (std::size_t i = 0; i < transforms.size() && Eigen::Index(i) < x.rows(); ++i) {
        if (transforms[i] == VariableTransform::Log)
            out.row(Eigen::Index(i)) = x.row(Eigen::Index(i)).unaryExpr([](double v) { return v > 0 ? std::log(v) : NAN; });
        if (transforms[i] == VariableTransform::Sqrt)
            out.row(Eigen::Index(i)) = x.row(Eigen::Index(i)).unaryExpr([](double v) { return v >= 0 ? std::sqrt(v) : NAN; });
    }
    return out;
}

void invertTransformsInPlace(Eigen::Ref<Eigen::MatrixXd> y, const std::vector<VariableTransform>& transforms) {
    for (std::size_t i = 0; i < transforms.size() && Eigen::Index(i) < y.rows(); ++i) {
        if (transforms[i] == VariableTransform::Log) y.row(Eigen::Index(i)) = y.row(Eigen::Index(i)).array().exp().matrix();
        // max(0, .)^2: a negative network output is the boundary x = 0, not its mirror image
        if (transforms[i] == VariableTransform::Sqrt)
            y.row(Eigen::Index(i)) = y.row(Eigen::Index(i)).array().max(0.0).square().matrix();
    }
}

Eigen::MatrixXd TrainedNetwork::evaluate(const Eigen::Ref<const Eigen::MatrixXd>& X, Precision precision) const {
    // No copy of X for a network without input transforms (the equilibrium network).
    const Eigen::MatrixXd Xs = inputTransforms.empty() ? inputScaling.apply(X) : inputScaling.apply(applyTransforms(X, inputTransforms));
    Eigen::MatrixXd Y = net.forward(Xs, precision);
    if (!ensemble.empty()) {
        Eigen::MatrixXd Yk(Y.rows(), Y.cols());
        for (const EnsembleMember& m : ensemble) {
            m.net.forward(Xs, Yk, precision);
            Y += Yk;
        }
        Y /= double(1 + ensemble.size());
    }
    outputScaling.invertInPlace(Y);
    invertTransformsInPlace(Y, outputTransforms);
    return Y;
}

Eigen::MatrixXd TrainedNetwork::inputGradient(const Eigen::Ref<const Eigen::MatrixXd>& X,
                                              const Eigen::Ref<const Eigen::MatrixXd>& G) const {
    if (X.rows() != net.numInputs() || G.rows() != net.numOutputs() || G.cols() != X.cols())
        throw InputError(fmt::format("network input gradient: inputs {} x {} and output weights {} x {}, expected {} and {} rows "
                                     "with the same number of columns", X.rows(), X.cols(), G.rows(), G.cols(),
                                     net.numInputs(), net.numOutputs()));
    const Eigen::MatrixXd Xs = inputScaling.apply(applyTransforms(X, inputTransforms));
    // Output weights in the standardised network space: G .* dy/dy' .* s_y, y' = s_y NN + m_y.
    Eigen::MatrixXd Gs = G;
    bool transformedOutput = false;
    for (VariableTransform t : outputTransforms) transformedOutput = transformedOutput || t != VariableTransform::Identity;
    if (transformedOutput) {
        Eigen::MatrixXd Yt = net.forward(Xs);
        if (!ensemble.empty()) {
            Eigen::MatrixXd Yk(Yt.rows(), Yt.cols());
            for (const EnsembleMember& m : ensemble) {
                m.net.forward(Xs, Yk);
                Yt += Yk;
            }
            Yt /= double(1 + ensemble.size());
        }
        outputScaling.invertInPlace(Yt);
        for (std::size_t i = 0; i < outputTransforms.size() && Eigen::Index(i) < Gs.rows(); ++i) {
            const Eigen::Index r = Eigen::Index(i);
            if (outputTransforms[i] == VariableTransform::Log) Gs.row(r).array() *= Yt.row(r).array().exp();
            if (outputTransforms[i] == VariableTransform::Sqrt) Gs.row(r).array() *= 2.0 * Yt.row(r).array().max(0.0);
        }
    }
    Gs.array().colwise() *= outputScaling.sd.array();
    Eigen::MatrixXd g = net.inputGradient(Xs, Gs);
    if (!ensemble.empty()) {
        for (const EnsembleMember& m : ensemble) g += m.net.inputGradient(Xs, Gs);
        g /= double(1 + ensemble.size());
    }
    g.array().colwise() /= inputScaling.sd.array();
    for (std::size_t i = 0; i < inputTransforms.size() && Eigen::Index(i) < g.rows(); ++i) {
        const Eigen::Index r = Eigen::Index(i);
        if (inputTransforms[i] == VariableTransform::Log) g.row(r).array() /= X.row(r).array();
        if (inputTransforms[i] == VariableTransform::Sqrt) g.row(r).array() /= 2.0 * X.row(r).array().sqrt();
    }
    return g;
}

TrainedNetwork distilledNetwork(const TrainedNetwork& teacher, const Eigen::Ref<const Eigen::MatrixXd>& X, std::uint64_t designSeed,
                                TrainingOptions o) {
    const Eigen::MatrixXd Y = teacher.evaluate(X);
    o.batchSize = 128;
    o.patience = std::max(10, int(std::ceil(3000.0 / (0.8 * double(X.cols()) / o.batchSize))));
    o.progress = nullptr;
    TrainedNetwork student = trainNetwork(X, Y, o, teacher.inputNames, teacher.outputNames).network;
    student.distillation = {1 + int(teacher.ensemble.size()), long(X.cols()), designSeed, teacher.history.bestValidationLoss};
    return student;
}

}  // namespace trbc
