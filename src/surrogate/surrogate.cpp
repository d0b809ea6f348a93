#include "surrogate/surrogate.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "core/error.hpp"
#include "core/hash.hpp"
#include "sampling/design.hpp"
#include "surrogate/network_io.hpp"

namespace trbc {
namespace fs = std::filesystem;

const std::vector<std::string>& surrogateInputNames() {
    static const std::vector<std::string> n = {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um", "Fext_pN"};
    return n;
}

const std::vector<std::string>& surrogateOutputNames() {
    static const std::vector<std::string> n = {"D_um", "hmin_um", "hmax_um", "D0_um", "D1_um", "tc_s"};
    return n;
}

const std::vector<std::string>& surrogateNetworkNames() {
    static const std::vector<std::string> names = {"equilibrium", "stretching", "relaxation"};
    return names;
}

nlohmann::json surrogateNetworksJson(const Surrogate& s) {
    nlohmann::json networks = nlohmann::json::object();
    const std::pair<const char*, const TrainedNetwork*> nets[3] = {
        {"equilibrium", &s.equilibrium}, {"stretching", &s.stretching}, {"relaxation", &s.relaxation}};
    for (const auto& [name, net] : nets) networks[name] = {{"data_hash", net->dataHash}, {"command", net->command}};
    if (s.branched) networks["branch"] = {{"data_hash", s.branch.dataHash}, {"command", s.branch.command}};
    return networks;
}

/// (v, FvK) of a network's inputs: rows 0 and 2 of the stretching and relaxation inputs, the
/// equilibrium's two rows.
Eigen::MatrixXd vFvKOf(const Eigen::Ref<const Eigen::MatrixXd>& x) {
    if (x.rows() == 2) return x;
    Eigen::MatrixXd out(2, x.cols());
    out.row(0) = x.row(0);
    out.row(1) = x.row(2);
    return out;
}

/// b = [score > 0.5] of a branch classifier for the columns of (v, FvK) with v >= kCupMinV, 0 for the
/// others. Only the columns that can be cups are classified: the rest cost nothing (86 % of the
/// prior box's v range), and a classifier that said "cup" there would be wrong.
Eigen::RowVectorXd classifyBranch(const TrainedNetwork& classifier, const Eigen::Ref<const Eigen::MatrixXd>& vFvK,
                                  Precision precision) {
    Eigen::RowVectorXd b = Eigen::RowVectorXd::Zero(vFvK.cols());
    std::vector<Eigen::Index> cols;
    for (Eigen::Index j = 0; j < vFvK.cols(); ++j)
        if (vFvK(0, j) >= kCupMinV) cols.push_back(j);
    if (cols.empty()) return b;
    Eigen::MatrixXd x(2, Eigen::Index(cols.size()));
    for (std::size_t k = 0; k < cols.size(); ++k) x.col(Eigen::Index(k)) = vFvK.col(cols[k]);
    const Eigen::MatrixXd score = classifier.evaluate(x, precision);
    for (std::size_t k = 0; k < cols.size(); ++k) b(cols[k]) = score(0, Eigen::Index(k)) > 0.5 ? 1.0 : 0.0;
    return b;
}

/// x with the row b appended.
Eigen::MatrixXd withBranchRow(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::RowVectorXd& b) {
    Eigen::MatrixXd xb(x.rows() + 1, x.cols());
    xb.topRows(x.rows()) = x;
    xb.row(x.rows()) = b;
    return xb;
}

namespace {

const std::vector<std::string>& kNetworks = surrogateNetworkNames();
std::string networkFile(int k) { return kNetworks[std::size_t(k)] + ".json"; }

// Rows of the six-input batch that each network reads (SURROGATE 3.1).
const int kEqRows[2] = {0, 2};
const int kStretchRows[5] = {0, 1, 2, 3, 5};
const int kRelaxRows[5] = {0, 1, 2, 3, 4};

template <int N>
Eigen::MatrixXd pickRows(const Eigen::Ref<const Eigen::MatrixXd>& x, const int (&rows)[N]) {
    Eigen::MatrixXd out(N, x.cols());
    for (int k = 0; k < N; ++k) out.row(k) = x.row(rows[k]);
    return out;
}

void expectRows(const Eigen::Ref<const Eigen::MatrixXd>& x, int rows, const char* what) {
    if (x.rows() != rows) throw InputError(fmt::format("{}: a batch needs {} input rows, got {}", what, rows, x.rows()));
}

const char* kBranchFile = "branch.json";

/// The network evaluated on x with b appended as its last input row (x itself when b is empty).
Eigen::MatrixXd evaluateWithBranch(const TrainedNetwork& net, const Eigen::Ref<const Eigen::MatrixXd>& x,
                                   const Eigen::RowVectorXd* b, Precision precision) {
    return b ? net.evaluate(withBranchRow(x, *b), precision) : net.evaluate(x, precision);
}

/// Input gradient of a network on x with b appended; the row of b (piecewise constant) is dropped.
Eigen::MatrixXd gradientWithBranch(const TrainedNetwork& net, const Eigen::Ref<const Eigen::MatrixXd>& x,
                                   const Eigen::RowVectorXd* b, const Eigen::Ref<const Eigen::MatrixXd>& w) {
    return b ? Eigen::MatrixXd(net.inputGradient(withBranchRow(x, *b), w).topRows(x.rows())) : net.inputGradient(x, w);
}

}  // namespace

Surrogate Surrogate::load(const fs::path& dir) {
    Surrogate s;
    s.branched = fs::exists(dir / kBranchFile);
    const int extra = s.branched ? 1 : 0;
    if (s.branched) {
        const fs::path p = dir / kBranchFile;
        s.branch = loadNetwork(p.string());
        if (s.branch.net.numInputs() != 2 || s.branch.net.numOutputs() != 1)
            throw InputError(fmt::format("{}: the branch network must map 2 inputs (v, FvK) to 1 output, found {} -> {}", p.string(),
                                         s.branch.net.numInputs(), s.branch.net.numOutputs()));
    }
    TrainedNetwork* nets[3] = {&s.equilibrium, &s.stretching, &s.relaxation};
    const int inputs[3] = {2 + extra, 5 + extra, 5 + extra}, outputs[3] = {3, 2, 1};
    for (int k = 0; k < 3; ++k) {
        const fs::path p = dir / networkFile(k);
        if (!fs::exists(p))
            throw InputError(fmt::format("surrogate model {}: missing {} (train one with trbc surrogate train)", dir.string(), p.string()));
        *nets[k] = loadNetwork(p.string());
        if (nets[k]->net.numInputs() != inputs[k] || nets[k]->net.numOutputs() != outputs[k])
            throw InputError(fmt::format("{}: the {} network must map {} inputs to {} outputs{}, found {} -> {}", p.string(),
                                         kNetworks[std::size_t(k)], inputs[k], outputs[k],
                                         s.branched ? " (the branch input last, since branch.json is present)" : "",
                                         nets[k]->net.numInputs(), nets[k]->net.numOutputs()));
    }
    return s;
}

void Surrogate::save(const fs::path& dir) const {
    fs::create_directories(dir);
    const TrainedNetwork* nets[3] = {&equilibrium, &stretching, &relaxation};
    for (int k = 0; k < 3; ++k) saveNetwork(*nets[k], (dir / networkFile(k)).string());
    if (branched)
        saveNetwork(branch, (dir / kBranchFile).string());
    else
        fs::remove(dir / kBranchFile);
}

Eigen::RowVectorXd Surrogate::branchIndicator(const Eigen::Ref<const Eigen::MatrixXd>& vFvK) const {
    expectRows(vFvK, 2, "branch classifier");
    return branched ? classifyBranch(branch, vFvK, precision) : Eigen::RowVectorXd::Zero(vFvK.cols());
}

Eigen::MatrixXd Surrogate::equilibriumWith(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::RowVectorXd* b) const {
    Eigen::RowVectorXd own;
    if (branched && !b) own = branchIndicator(x), b = &own;
    return evaluateWithBranch(equilibrium, x, branched ? b : nullptr, precision);
}

Eigen::MatrixXd Surrogate::stretchingWith(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::RowVectorXd* b) const {
    Eigen::RowVectorXd own;
    if (branched && !b) own = branchIndicator(vFvKOf(x)), b = &own;
    return evaluateWithBranch(stretching, x, branched ? b : nullptr, precision);
}

Eigen::VectorXd Surrogate::relaxationWith(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::RowVectorXd* b) const {
    Eigen::RowVectorXd own;
    if (branched && !b) own = branchIndicator(vFvKOf(x)), b = &own;
    const Eigen::MatrixXd tcTilde = evaluateWithBranch(relaxation, x, branched ? b : nullptr, precision);
    return (tcTilde.row(0).array() * x.row(4).array() / x.row(1).array()).transpose();
}

Eigen::MatrixXd Surrogate::equilibriumOutputs(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    expectRows(x, 2, "equilibrium surrogate");
    return equilibriumWith(x, nullptr);
}

Eigen::MatrixXd Surrogate::stretchingOutputs(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    expectRows(x, 5, "stretching surrogate");
    return stretchingWith(x, nullptr);
}

Eigen::VectorXd Surrogate::relaxationTime(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    expectRows(x, 5, "relaxation surrogate");
    return relaxationWith(x, nullptr);
}

Eigen::MatrixXd Surrogate::evaluate(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    expectRows(x, 6, "surrogate");
    // In chunks of 4096 samples, so that the inputs picked for each network, their scaled copies and
    // the outputs stay in the cache between the three networks' passes instead of streaming through
    // memory several times; threads take whole chunks (a network pass inside sees one thread). Every
    // sample's value is independent of the chunking and the thread count (Mlp::forward).
    constexpr Eigen::Index kChunk = 4096;
    const Eigen::Index n = x.cols(), chunks = (n + kChunk - 1) / kChunk;
    Eigen::MatrixXd y(6, n);
    const int threads = static_cast<int>(std::min<Eigen::Index>(omp_get_max_threads(), chunks));
#pragma omp parallel for schedule(static) num_threads(std::max(threads, 1)) if (threads > 1)
    for (Eigen::Index c = 0; c < chunks; ++c) {
        const Eigen::Index c0 = c * kChunk, nc = std::min(kChunk, n - c0);
        const auto xc = x.middleCols(c0, nc);
        auto yc = y.middleCols(c0, nc);
        const Eigen::MatrixXd vFvK = pickRows(xc, kEqRows);
        const Eigen::RowVectorXd b = branchIndicator(vFvK);  // once for the three networks
        yc.topRows(3) = equilibriumWith(vFvK, &b);
        yc.middleRows(3, 2) = stretchingWith(pickRows(xc, kStretchRows), &b);
        yc.row(5) = relaxationWith(pickRows(xc, kRelaxRows), &b).transpose();
    }
    return y;
}

Eigen::MatrixXd Surrogate::inputGradient(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::Ref<const Eigen::MatrixXd>& w) const {
    expectRows(x, 6, "surrogate gradient");
    if (w.rows() != 6 || w.cols() != x.cols())
        throw InputError(fmt::format("surrogate gradient: output weights are {} x {}, expected 6 x {}", w.rows(), w.cols(), x.cols()));
    Eigen::MatrixXd g = Eigen::MatrixXd::Zero(6, x.cols());
    // The branch b is piecewise constant in (v, FvK): the gradient is that of the branch's networks
    // (the jump across the switch line has no derivative).
    const Eigen::RowVectorXd bRow = branchIndicator(pickRows(x, kEqRows));
    const Eigen::RowVectorXd* b = branched ? &bRow : nullptr;
    if (!w.topRows(3).isZero(0.0)) {
        const Eigen::MatrixXd ge = gradientWithBranch(equilibrium, pickRows(x, kEqRows), b, w.topRows(3));
        for (int k = 0; k < 2; ++k) g.row(kEqRows[k]) += ge.row(k);
    }
    if (!w.middleRows(3, 2).isZero(0.0)) {
        const Eigen::MatrixXd gs = gradientWithBranch(stretching, pickRows(x, kStretchRows), b, w.middleRows(3, 2));
        for (int k = 0; k < 5; ++k) g.row(kStretchRows[k]) += gs.row(k);
    }
    if (!w.row(5).isZero(0.0)) {
        // tc = h(x) etam / mu with h the relaxation network's output tc mu / etam.
        const Eigen::MatrixXd xr = pickRows(x, kRelaxRows);
        const Eigen::ArrayXd h = evaluateWithBranch(relaxation, xr, b, Precision::Double).row(0).transpose().array();
        const Eigen::ArrayXd mu = x.row(1).transpose().array(), etam = x.row(4).transpose().array();
        const Eigen::ArrayXd w5 = w.row(5).transpose().array();
        const Eigen::MatrixXd gr = gradientWithBranch(relaxation, xr, b, (w5 * etam / mu).matrix().transpose());
        for (int k = 0; k < 5; ++k) g.row(kRelaxRows[k]) += gr.row(k);
        g.row(4).array() += (w5 * h / mu).transpose();
        g.row(1).array() -= (w5 * h * etam / mu.square()).transpose();
    }
    return g;
}

Eigen::MatrixXd Surrogate::inputJacobian(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    expectRows(x, 6, "surrogate Jacobian");
    Eigen::MatrixXd J(36, x.cols());
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(6, x.cols());
    for (int i = 0; i < 6; ++i) {
        w.row(i).setOnes();
        J.middleRows(6 * i, 6) = inputGradient(x, w);
        w.row(i).setZero();
    }
    return J;
}

std::vector<bool> outsideTrainingBox(const Eigen::Ref<const Eigen::MatrixXd>& x) {
    const PriorRange box[6] = {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam, kPriorFext};
    std::vector<bool> out(x.cols(), false);
    for (Eigen::Index j = 0; j < x.cols(); ++j)
        for (int k = 0; k < 6; ++k)
            if (!(x(k, j) >= box[k].lo && x(k, j) <= box[k].hi)) out[j] = true;
    return out;
}

}  // namespace trbc
