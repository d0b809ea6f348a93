#include "surrogate/network_io.hpp"

#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/version.hpp"

namespace trbc {

using nlohmann::json;

namespace {

constexpr const char* kFormat = "trbc-mlp";
constexpr int kFormatVersion = 1;
/// Files with ensemble members: an older reader, which would silently use the first member
/// alone, rejects them by the version instead.
constexpr int kEnsembleFormatVersion = 2;

json vectorToJson(const Eigen::Ref<const Eigen::VectorXd>& v) { return std::vector<double>(v.begin(), v.end()); }

json transformsToJson(const std::vector<VariableTransform>& t, std::size_t n) {
    json a = json::array();
    for (std::size_t i = 0; i < n; ++i) {
        const VariableTransform ti = i < t.size() ? t[i] : VariableTransform::Identity;
        a.push_back(ti == VariableTransform::Log ? "log" : ti == VariableTransform::Sqrt ? "sqrt" : "identity");
    }
    return a;
}

/// Loss values: NaN/inf (no value) as null.
json lossesToJson(const std::vector<double>& v) {
    json a = json::array();
    for (double x : v) a.push_back(std::isfinite(x) ? json(x) : json(nullptr));
    return a;
}
json lossToJson(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }

/// Reads one document, every failure an InputError "<source>: key '<path>': <problem>".
class Reader {
public:
    explicit Reader(std::string source) : source_(std::move(source)) {}

    [[noreturn]] void fail(const std::string& path, const std::string& what) const {
        throw InputError(source_ + ": key '" + path + "': " + what);
    }

    const json& key(const json& obj, const std::string& name, const std::string& parent = "") const {
        const std::string path = parent.empty() ? name : parent + "." + name;
        if (!obj.is_object()) fail(parent.empty() ? "(top level)" : parent, "must be a JSON object");
        const auto it = obj.find(name);
        if (it == obj.end()) fail(path, "missing");
        return *it;
    }

    const json& array(const json& v, const std::string& path, std::size_t size) const {
        if (!v.is_array()) fail(path, "must be an array");
        if (v.size() != size)
            fail(path, "has " + std::to_string(v.size()) + " entries, expected " + std::to_string(size));
        return v;
    }

    const json& anyArray(const json& v, const std::string& path) const {
        if (!v.is_array()) fail(path, "must be an array");
        return v;
    }

    double number(const json& v, const std::string& path) const {
        if (!v.is_number()) fail(path, "must be a number");
        const double x = v.get<double>();
        if (!std::isfinite(x)) fail(path, "must be finite");
        return x;
    }

    /// A number, or null for "no value" (NaN).
    double loss(const json& v, const std::string& path) const {
        if (v.is_null()) return std::numeric_limits<double>::quiet_NaN();
        return number(v, path);
    }

    long long integer(const json& v, const std::string& path, long long lo, long long hi) const {
        if (!v.is_number_integer()) fail(path, "must be an integer");
        if (v.is_number_unsigned() && v.get<std::uint64_t>() > static_cast<std::uint64_t>(hi))
            fail(path, "must be <= " + std::to_string(hi));
        const long long x = v.get<long long>();
        if (x < lo || x > hi) fail(path, "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
        return x;
    }

    std::uint64_t unsignedInteger(const json& v, const std::string& path) const {
        if (!v.is_number_unsigned()) fail(path, "must be a non-negative integer");
        return v.get<std::uint64_t>();
    }

    std::string string(const json& v, const std::string& path) const {
        if (!v.is_string()) fail(path, "must be a string");
        return v.get<std::string>();
    }

    bool boolean(const json& v, const std::string& path) const {
        if (!v.is_boolean()) fail(path, "must be true or false");
        return v.get<bool>();
    }

    Eigen::VectorXd vector(const json& v, const std::string& path, std::size_t size) const {
        array(v, path, size);
        Eigen::VectorXd out(static_cast<Eigen::Index>(size));
        for (std::size_t i = 0; i < size; ++i) out[static_cast<Eigen::Index>(i)] = number(v[i], path + "[" + std::to_string(i) + "]");
        return out;
    }

    std::vector<double> losses(const json& v, const std::string& path) const {
        anyArray(v, path);
        std::vector<double> out;
        for (std::size_t i = 0; i < v.size(); ++i) out.push_back(loss(v[i], path + "[" + std::to_string(i) + "]"));
        return out;
    }

    std::vector<std::string> strings(const json& v, const std::string& path, std::size_t size) const {
        array(v, path, size);
        std::vector<std::string> out;
        for (std::size_t i = 0; i < size; ++i) out.push_back(string(v[i], path + "[" + std::to_string(i) + "]"));
        return out;
    }

private:
    std::string source_;
};

std::string index(const std::string& path, std::size_t i) { return path + "[" + std::to_string(i) + "]"; }

Standardisation readScaling(const Reader& r, const json& j, const std::string& prefix, std::size_t size) {
    Standardisation s;
    s.mean = r.vector(r.key(j, prefix + "_mean"), prefix + "_mean", size);
    s.sd = r.vector(r.key(j, prefix + "_sd"), prefix + "_sd", size);
    for (Eigen::Index i = 0; i < s.sd.size(); ++i)
        if (!(s.sd[i] > 0.0)) r.fail(index(prefix + "_sd", static_cast<std::size_t>(i)), "must be > 0");
    return s;
}

TrainingOptions readTraining(const Reader& r, const json& j) {
    const std::string p = "training";
    const json& t = r.key(j, p);
    const auto num = [&](const char* name) { return r.number(r.key(t, name, p), p + "." + name); };
    const auto integer = [&](const char* name, long long lo, long long hi) {
        return r.integer(r.key(t, name, p), p + "." + name, lo, hi);
    };
    TrainingOptions o;
    o.batchSize = static_cast<int>(integer("batch_size", 1, std::numeric_limits<int>::max()));
    o.seed = r.unsignedInteger(r.key(t, "seed", p), p + ".seed");
    o.trainFraction = num("train_fraction");
    o.testFraction = num("test_fraction");
    o.testSeed = r.unsignedInteger(r.key(t, "test_seed", p), p + ".test_seed");
    o.learningRate = num("learning_rate");
    o.beta1 = num("beta1");
    o.beta2 = num("beta2");
    o.epsilon = num("epsilon");
    o.patience = static_cast<int>(integer("patience", 0, std::numeric_limits<int>::max()));
    o.reductionFactor = num("reduction_factor");
    o.maxReductions = static_cast<int>(integer("max_reductions", 1, std::numeric_limits<int>::max()));
    o.maxEpochs = static_cast<int>(integer("max_epochs", 1, std::numeric_limits<int>::max()));
    try {
        checkTrainingOptions(o);
    } catch (const InputError& e) {
        r.fail(p, e.what());
    }
    return o;
}

TrainingHistory readHistory(const Reader& r, const json& j) {
    const std::string p = "history";
    const json& h = r.key(j, p);
    const auto sub = [&](const char* name) -> const json& { return r.key(h, name, p); };
    const auto path = [&](const char* name) { return p + "." + name; };
    TrainingHistory out;
    out.trainLoss = r.losses(sub("train_loss"), path("train_loss"));
    out.validationLoss = r.losses(sub("validation_loss"), path("validation_loss"));
    out.learningRate = r.losses(sub("learning_rate"), path("learning_rate"));
    const std::size_t epochs = out.trainLoss.size();
    if (out.validationLoss.size() != epochs)
        r.fail(path("validation_loss"), "has " + std::to_string(out.validationLoss.size()) +
                                            " entries, train_loss " + std::to_string(epochs));
    if (out.learningRate.size() != epochs)
        r.fail(path("learning_rate"), "has " + std::to_string(out.learningRate.size()) +
                                          " entries, train_loss " + std::to_string(epochs));
    const json& red = r.anyArray(sub("reduction_epochs"), path("reduction_epochs"));
    for (std::size_t i = 0; i < red.size(); ++i)
        out.reductionEpochs.push_back(static_cast<int>(
            r.integer(red[i], index(path("reduction_epochs"), i), 0, static_cast<long long>(epochs))));
    out.restoredValidationLoss = r.losses(sub("restored_validation_loss"), path("restored_validation_loss"));
    if (out.restoredValidationLoss.size() != out.reductionEpochs.size())
        r.fail(path("restored_validation_loss"), "has " + std::to_string(out.restoredValidationLoss.size()) +
                                                     " entries, reduction_epochs " +
                                                     std::to_string(out.reductionEpochs.size()));
    out.bestEpoch = static_cast<int>(r.integer(sub("best_epoch"), path("best_epoch"), -1, static_cast<long long>(epochs)));
    out.bestValidationLoss = r.loss(sub("best_validation_loss"), path("best_validation_loss"));
    out.hitEpochCap = r.boolean(sub("hit_epoch_cap"), path("hit_epoch_cap"));
    out.testLoss = r.loss(sub("test_loss"), path("test_loss"));
    return out;
}

/// Writes net's layers as obj["weights"], obj["biases"] (format in network_io.hpp).
void writeLayers(const Mlp& net, json& obj) {
    json weights = json::array(), biases = json::array();
    for (int l = 0; l < net.numLayers(); ++l) {
        json rows = json::array();
        const auto W = net.weights(l);
        for (Eigen::Index i = 0; i < W.rows(); ++i) rows.push_back(vectorToJson(W.row(i).transpose()));
        weights.push_back(std::move(rows));
        biases.push_back(vectorToJson(net.biases(l)));
    }
    obj["weights"] = std::move(weights);
    obj["biases"] = std::move(biases);
}

/// A network of the given layer sizes from obj["weights"], obj["biases"]; key paths below `parent`.
Mlp readLayers(const Reader& r, const json& obj, const std::vector<int>& sizes, const std::string& parent) {
    const std::size_t L = sizes.size() - 1;
    const auto path = [&](const char* name) { return parent.empty() ? std::string(name) : parent + "." + name; };
    // weights[l]: n_{l+1} rows of n_l numbers; biases[l]: n_{l+1} numbers. The shapes that the
    // file holds are checked before the network is allocated: layer_sizes cannot ask for more
    // memory than the file's own numbers take (a 100-byte file cannot claim a million-wide layer).
    const json& weights = r.array(r.key(obj, "weights", parent), path("weights"), L);
    const json& biases = r.array(r.key(obj, "biases", parent), path("biases"), L);
    for (std::size_t l = 0; l < L; ++l) {
        const std::string wp = index(path("weights"), l);
        const json& rows = r.array(weights[l], wp, static_cast<std::size_t>(sizes[l + 1]));
        for (std::size_t i = 0; i < rows.size(); ++i) r.array(rows[i], index(wp, i), static_cast<std::size_t>(sizes[l]));
        r.array(biases[l], index(path("biases"), l), static_cast<std::size_t>(sizes[l + 1]));
    }
    Mlp net(sizes);
    for (std::size_t l = 0; l < L; ++l) {
        const int li = static_cast<int>(l);
        const std::string wp = index(path("weights"), l);
        const json& rows = r.array(weights[l], wp, static_cast<std::size_t>(sizes[l + 1]));
        auto W = net.weights(li);
        for (std::size_t i = 0; i < rows.size(); ++i)
            W.row(static_cast<Eigen::Index>(i)) =
                r.vector(rows[i], index(wp, i), static_cast<std::size_t>(sizes[l])).transpose();
        net.biases(li) = r.vector(biases[l], index(path("biases"), l), static_cast<std::size_t>(sizes[l + 1]));
    }
    return net;
}

}  // namespace

json networkToJson(const TrainedNetwork& tn) {
    const Mlp& net = tn.net;
    const TrainingOptions& o = tn.options;
    const TrainingHistory& h = tn.history;
    json j;
    j["format"] = kFormat;
    j["version"] = tn.ensemble.empty() ? kFormatVersion : kEnsembleFormatVersion;
    j["trbc_version"] = trbc::kVersion;  // provenance only, not read back
    j["layer_sizes"] = net.layerSizes();
    j["activation"] = "tanh";
    writeLayers(net, j);
    j["input_mean"] = vectorToJson(tn.inputScaling.mean);
    j["input_sd"] = vectorToJson(tn.inputScaling.sd);
    j["output_mean"] = vectorToJson(tn.outputScaling.mean);
    j["output_sd"] = vectorToJson(tn.outputScaling.sd);
    j["input_transform"] = transformsToJson(tn.inputTransforms, tn.inputNames.size());
    j["output_transform"] = transformsToJson(tn.outputTransforms, tn.outputNames.size());
    j["input_names"] = tn.inputNames;
    j["output_names"] = tn.outputNames;
    j["data_hash"] = tn.dataHash;
    j["split_seed"] = o.splitSeed;
    j["command"] = tn.command;
    j["training"] = {{"batch_size", o.batchSize},       {"seed", o.seed},
                     {"train_fraction", o.trainFraction}, {"test_fraction", o.testFraction},
                     {"test_seed", o.testSeed},         {"learning_rate", o.learningRate},
                     {"beta1", o.beta1},                {"beta2", o.beta2},
                     {"epsilon", o.epsilon},            {"patience", o.patience},
                     {"reduction_factor", o.reductionFactor}, {"max_reductions", o.maxReductions},
                     {"max_epochs", o.maxEpochs}};
    j["history"] = {{"train_loss", lossesToJson(h.trainLoss)},
                    {"validation_loss", lossesToJson(h.validationLoss)},
                    {"learning_rate", lossesToJson(h.learningRate)},
                    {"reduction_epochs", h.reductionEpochs},
                    {"restored_validation_loss", lossesToJson(h.restoredValidationLoss)},
                    {"best_epoch", h.bestEpoch},
                    {"best_validation_loss", lossToJson(h.bestValidationLoss)},
                    {"hit_epoch_cap", h.hitEpochCap},
                    {"test_loss", lossToJson(h.testLoss)}};
    if (!tn.ensemble.empty()) {
        json members = json::array();
        for (const EnsembleMember& m : tn.ensemble) {
            if (m.net.layerSizes() != net.layerSizes())
                throw std::invalid_argument("networkToJson: an ensemble member's layer sizes differ from the network's");
            json e = {{"seed", m.seed}, {"best_validation_loss", lossToJson(m.bestValidationLoss)}};
            writeLayers(m.net, e);
            members.push_back(std::move(e));
        }
        j["ensemble"] = std::move(members);
    }
    if (tn.distillation.members > 0)
        j["distillation"] = {{"members", tn.distillation.members},
                             {"samples", tn.distillation.samples},
                             {"seed", tn.distillation.seed},
                             {"teacher_validation_loss", lossToJson(tn.distillation.teacherValidationLoss)}};
    return j;
}

TrainedNetwork networkFromJson(const json& j, const std::string& source) {
    const Reader r(source);
    if (r.string(r.key(j, "format"), "format") != kFormat) r.fail("format", std::string("must be \"") + kFormat + "\"");
    const long long version = r.integer(r.key(j, "version"), "version", 0, 1 << 30);
    if (version != kFormatVersion && version != kEnsembleFormatVersion)
        r.fail("version", "unsupported, expected " + std::to_string(kFormatVersion) + " or " + std::to_string(kEnsembleFormatVersion));
    if (version == kFormatVersion && j.contains("ensemble")) r.fail("ensemble", "needs format version 2");
    if (r.string(r.key(j, "activation"), "activation") != "tanh") r.fail("activation", "must be \"tanh\"");

    // layer sizes
    const json& ls = r.anyArray(r.key(j, "layer_sizes"), "layer_sizes");
    if (ls.size() < 2) r.fail("layer_sizes", "needs at least 2 entries (inputs and outputs)");
    std::vector<int> sizes;
    for (std::size_t i = 0; i < ls.size(); ++i)
        sizes.push_back(static_cast<int>(r.integer(ls[i], index("layer_sizes", i), 1, 1 << 20)));

    TrainedNetwork tn;
    tn.net = readLayers(r, j, sizes, "");
    // Optional (single networks have none): further members with the same layer sizes.
    if (j.contains("ensemble")) {
        const json& members = r.anyArray(j.at("ensemble"), "ensemble");
        for (std::size_t k = 0; k < members.size(); ++k) {
            const std::string p = index("ensemble", k);
            EnsembleMember m;
            m.net = readLayers(r, members[k], sizes, p);
            m.seed = r.unsignedInteger(r.key(members[k], "seed", p), p + ".seed");
            m.bestValidationLoss = r.loss(r.key(members[k], "best_validation_loss", p), p + ".best_validation_loss");
            tn.ensemble.push_back(std::move(m));
        }
    }

    const auto nIn = static_cast<std::size_t>(sizes.front()), nOut = static_cast<std::size_t>(sizes.back());
    tn.inputScaling = readScaling(r, j, "input", nIn);
    tn.outputScaling = readScaling(r, j, "output", nOut);
    tn.inputNames = r.strings(r.key(j, "input_names"), "input_names", nIn);
    // Optional (files written before the transforms existed: identity).
    const auto transforms = [&](const char* key, std::size_t n) {
        std::vector<VariableTransform> t;
        if (!j.contains(key)) return t;
        for (const std::string& name : r.strings(j.at(key), key, n)) {
            if (name != "identity" && name != "log" && name != "sqrt")
                r.fail(key, "entries must be \"identity\", \"log\" or \"sqrt\", found \"" + name + "\"");
            t.push_back(name == "log" ? VariableTransform::Log : name == "sqrt" ? VariableTransform::Sqrt : VariableTransform::Identity);
        }
        return t;
    };
    tn.inputTransforms = transforms("input_transform", nIn);
    tn.outputTransforms = transforms("output_transform", nOut);
    tn.outputNames = r.strings(r.key(j, "output_names"), "output_names", nOut);
    tn.dataHash = r.string(r.key(j, "data_hash"), "data_hash");
    tn.command = r.string(r.key(j, "command"), "command");
    tn.options = readTraining(r, j);
    tn.options.inputTransforms = tn.inputTransforms;  // the run's settings, as in a freshly trained network
    tn.options.outputTransforms = tn.outputTransforms;
    tn.options.splitSeed = r.unsignedInteger(r.key(j, "split_seed"), "split_seed");
    tn.options.hiddenLayers.assign(sizes.begin() + 1, sizes.end() - 1);
    tn.history = readHistory(r, j);
    // Optional (networks trained directly have none): where a distilled network came from.
    if (j.contains("distillation")) {
        const json& d = j.at("distillation");
        tn.distillation.members = int(r.integer(r.key(d, "members", "distillation"), "distillation.members", 2, 1 << 20));
        tn.distillation.samples = long(r.integer(r.key(d, "samples", "distillation"), "distillation.samples", 1, 1LL << 40));
        tn.distillation.seed = r.unsignedInteger(r.key(d, "seed", "distillation"), "distillation.seed");
        tn.distillation.teacherValidationLoss =
            r.loss(r.key(d, "teacher_validation_loss", "distillation"), "distillation.teacher_validation_loss");
        if (!tn.ensemble.empty()) r.fail("distillation", "a distilled network has no ensemble members");
    }
    return tn;
}

void saveNetwork(const TrainedNetwork& network, const std::string& path) {
    const json j = networkToJson(network);
    std::ofstream out(path);
    if (!out) throw InputError(path + ": cannot open for writing");
    out << j.dump(1) << '\n';
    if (!out) throw InputError(path + ": write failed");
}

TrainedNetwork loadNetwork(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw InputError(path + ": cannot open network file");
    json j;
    try {
        j = json::parse(in);
    } catch (const json::exception& e) {  // syntax errors, and numbers beyond a double (out_of_range)
        throw InputError(path + ": not valid JSON: " + e.what());
    }
    try {
        return networkFromJson(j, path);
    } catch (const json::exception& e) {  // a field of the wrong JSON type that no check above caught
        throw InputError(path + ": " + e.what());
    }
}

}  // namespace trbc
