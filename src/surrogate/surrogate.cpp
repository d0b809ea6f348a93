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

OutputAccuracy outputAccuracy(const std::string& name, const Eigen::VectorXd& truth, const Eigen::VectorXd& predicted) {
    OutputAccuracy a;
    a.name = name;
    a.n = truth.size();
    if (a.n == 0) return a;
    const Eigen::ArrayXd e = (predicted - truth).array();
    const Eigen::ArrayXd rel = e / truth.array();
    a.rmse = std::sqrt(e.square().mean());
    a.relativeRmse = std::sqrt(rel.square().mean());
    a.mae = e.abs().mean();
    a.maxAbs = e.abs().maxCoeff();
    a.meanRelative = rel.abs().mean();
    const double var = (truth.array() - truth.mean()).square().mean();
    a.r2 = var > 0 ? 1.0 - e.square().mean() / var : NAN;
    return a;
}

namespace {

struct NetworkData {
    Eigen::MatrixXd X, Y;  ///< physical units (relaxation: Y = tc mu / etam)
};

Eigen::VectorXd rowInputs(const CampaignRow& r) {
    Eigen::VectorXd x(6);
    x << r.point.p.v, r.point.p.mu, r.point.p.FvK, r.point.p.b2, r.point.p.etam, r.point.fext;
    return x;
}

/// Where the dropped rows lie: per input, counts in five equal bins of its range.
std::vector<std::string> describeDropped(const std::vector<const CampaignRow*>& dropped) {
    std::vector<std::string> lines;
    if (dropped.empty()) return lines;
    const PriorRange box[6] = {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam, kPriorFext};
    for (int k = 0; k < 6; ++k) {
        int bins[5] = {0, 0, 0, 0, 0};
        for (const CampaignRow* r : dropped) {
            const double u = (rowInputs(*r)(k) - box[k].lo) / (box[k].hi - box[k].lo);
            ++bins[std::clamp(int(u * 5), 0, 4)];
        }
        lines.push_back(fmt::format("{}: {} {} {} {} {} (five equal bins of [{}, {}])", box[k].name, bins[0], bins[1],
                                    bins[2], bins[3], bins[4], box[k].lo, box[k].hi));
    }
    return lines;
}

// Inputs of each network in its row order (equilibrium, stretching, relaxation).
const std::vector<PriorRange> kNetworkBoxes[3] = {{kPriorV, kPriorFvK},
                                                  {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorFext},
                                                  {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam}};

/// n points drawn uniformly from the box (columns), the campaigns' uniform design mapped onto it.
Eigen::MatrixXd uniformBoxPoints(const std::vector<PriorRange>& box, long n, std::uint64_t seed) {
    const Eigen::MatrixXd u = unitDesign(DesignKind::Uniform, n, int(box.size()), seed);
    Eigen::MatrixXd X(Eigen::Index(box.size()), n);
    for (long j = 0; j < n; ++j)
        for (std::size_t i = 0; i < box.size(); ++i)
            X(Eigen::Index(i), j) = box[i].lo + (box[i].hi - box[i].lo) * u(j, Eigen::Index(i));
    return X;
}

/// One network trained to reproduce an ensemble's predictions (the ensemble's mean in its
/// transformed output space) on uniform points of the box, with the teacher's transforms and the
/// training schedule `o` (its batch size and patience re-derived for the larger table).
/// With a branch classifier the points carry its branch as the last input (the teacher's branch input).
TrainedNetwork distilledNetwork(const TrainedNetwork& teacher, const std::vector<PriorRange>& box, long samples,
                                std::uint64_t seed, TrainingOptions o, const TrainedNetwork* classifier) {
    if (samples < 1000) throw InputError(fmt::format("surrogate distillation: {} box samples; at least 1000 are needed", samples));
    Eigen::MatrixXd X = uniformBoxPoints(box, samples, seed);
    if (classifier) {
        const Eigen::MatrixXd vFvK = vFvKOf(X);
        X = withBranchRow(X, classifyBranch(*classifier, vFvK, Precision::Double));
    }
    const Eigen::MatrixXd Y = teacher.evaluate(X);
    o.batchSize = 128;
    o.patience = std::max(10, int(std::ceil(3000.0 / (0.8 * double(samples) / o.batchSize))));
    o.progress = nullptr;
    TrainedNetwork student = trainNetwork(X, Y, o, teacher.inputNames, teacher.outputNames).network;
    student.distillation = {1 + int(teacher.ensemble.size()), samples, seed, teacher.history.bestValidationLoss};
    return student;
}

}  // namespace

SurrogateTrainingReport trainSurrogate(const std::vector<CampaignRow>& rows, const SurrogateTrainingOptions& opt) {
    if (!(opt.testFraction >= 0.0 && opt.testFraction < 0.5))
        throw InputError(fmt::format("surrogate training: test fraction {} is outside [0, 0.5)", opt.testFraction));
    if (opt.folds == 1 || opt.folds < 0 || (opt.folds >= 2 && (opt.fold < 0 || opt.fold >= opt.folds)))
        throw InputError(fmt::format("surrogate training: fold {} of {} folds (folds must be 0 or >= 2, fold in [0, folds))", opt.fold,
                                     opt.folds));
    SurrogateTrainingReport rep;
    rep.rows = long(rows.size());
    std::map<long, std::vector<const CampaignRow*>> byCell;
    for (const CampaignRow& r : rows) byCell[r.point.cellId].push_back(&r);
    rep.dataHash = campaignDataHash(rows);
    rep.cells = long(byCell.size());
    if (rep.cells < 10) throw InputError(fmt::format("surrogate training: {} cells in the table; at least 10 are needed", rep.cells));

    std::vector<long> cellIds;
    for (const auto& [id, v] : byCell) cellIds.push_back(id);
    const auto perm = seededPermutation(Eigen::Index(cellIds.size()), opt.testSeed);
    std::vector<bool> isTest(cellIds.size(), false);
    if (opt.folds >= 2) {
        for (std::size_t k = 0; k < cellIds.size(); ++k) isTest[perm[Eigen::Index(k)]] = int(k % std::size_t(opt.folds)) == opt.fold;
        rep.testCells = long(std::count(isTest.begin(), isTest.end(), true));
    } else {
        rep.testCells = long(std::ceil(opt.testFraction * double(cellIds.size())));
        for (long k = 0; k < rep.testCells; ++k) isTest[perm[k]] = true;
    }

    // Branched when the training cells hold both branches (the test cells play no part in the choice).
    rep.cellLabel = cupLabels(rows, opt.cellBranch, opt.cupHminUm);
    const std::map<long, int>& labels = rep.cellLabel;
    const auto branchOf = [&](long cellId) {
        if (!opt.cellBranch.count(cellId))
            throw InputError(fmt::format("surrogate training: cell {} has no equilibrium branch record (the campaign's "
                                         "equilibria.csv lacks it)", cellId));
        return labels.at(cellId);
    };
    bool branched = false;
    if (!opt.cellBranch.empty()) {
        bool seen[2] = {false, false};
        for (std::size_t c = 0; c < cellIds.size(); ++c)
            if (!isTest[c]) seen[branchOf(cellIds[c]) != 0] = true;
        branched = seen[0] && seen[1];
    }
    const auto withBranch = [&](Eigen::VectorXd x, long cellId) {
        if (!branched) return x;
        x.conservativeResize(x.size() + 1);
        x(x.size() - 1) = branchOf(cellId);
        return x;
    };

    auto eqOk = [](const CampaignRow& r) { return std::isfinite(r.D) && std::isfinite(r.hmin) && std::isfinite(r.hmax); };
    auto stOk = [](const CampaignRow& r) { return std::isfinite(r.D0) && std::isfinite(r.D1); };
    auto rxOk = [](const CampaignRow& r) { return std::isfinite(r.tc) && r.tc > 0; };

    std::vector<Eigen::VectorXd> xs[4], ys[4];  // equilibrium, stretching, relaxation, branch
    std::vector<const CampaignRow*> droppedRows, testRows;
    for (std::size_t c = 0; c < cellIds.size(); ++c) {
        const auto& cell = byCell[cellIds[c]];
        if (isTest[c]) {
            testRows.insert(testRows.end(), cell.begin(), cell.end());
            continue;
        }
        const CampaignRow& first = *cell.front();
        const Eigen::VectorXd x0 = rowInputs(first);
        const long id = cellIds[c];
        if (eqOk(first)) {
            xs[0].push_back(withBranch((Eigen::VectorXd(2) << x0(0), x0(2)).finished(), id));
            ys[0].push_back((Eigen::VectorXd(3) << first.D, first.hmin, first.hmax).finished());
            if (branched && x0(0) >= kCupMinV) {
                xs[3].push_back((Eigen::VectorXd(2) << x0(0), x0(2)).finished());
                ys[3].push_back(Eigen::VectorXd::Constant(1, branchOf(id)));
            } else if (branched && branchOf(id) != 0) {
                throw InputError(fmt::format("surrogate training: cell {} is a cup at v {} < {}, where a branched "
                                             "surrogate takes the disc (kCupMinV)", id, x0(0), kCupMinV));
            }
        } else {
            ++rep.dropped[0];
        }
        if (rxOk(first)) {
            xs[2].push_back(withBranch(x0.head(5), id));
            ys[2].push_back(Eigen::VectorXd::Constant(1, first.tc * first.point.p.mu / first.point.p.etam));
        } else {
            ++rep.dropped[2];
        }
        for (const CampaignRow* r : cell) {
            if (!r->ok()) droppedRows.push_back(r);
            if (!stOk(*r)) {
                ++rep.dropped[1];
                continue;
            }
            const Eigen::VectorXd x = rowInputs(*r);
            xs[1].push_back(withBranch((Eigen::VectorXd(5) << x(0), x(1), x(2), x(3), x(5)).finished(), id));
            ys[1].push_back((Eigen::VectorXd(2) << r->D0, r->D1).finished());
        }
    }
    rep.droppedWhere = describeDropped(droppedRows);

    const int networks = branched ? 4 : 3;
    const auto networkName = [](int k) { return k == 3 ? std::string("branch") : kNetworks[std::size_t(k)]; };
    NetworkData data[4];
    for (int k = 0; k < networks; ++k) {
        (k < 3 ? rep.used[k] : rep.branchUsed) = long(xs[k].size());
        if (xs[k].size() < 10)
            throw InputError(fmt::format("surrogate training: only {} usable samples for the {} network", xs[k].size(), networkName(k)));
        data[k].X.resize(xs[k].front().size(), Eigen::Index(xs[k].size()));
        data[k].Y.resize(ys[k].front().size(), Eigen::Index(ys[k].size()));
        for (std::size_t j = 0; j < xs[k].size(); ++j) data[k].X.col(Eigen::Index(j)) = xs[k][j], data[k].Y.col(Eigen::Index(j)) = ys[k][j];
    }

    std::vector<std::string> inNames[4] = {{"v", "FvK"},
                                           {"v", "mu_uN_per_m", "FvK", "b2", "Fext_pN"},
                                           {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um"},
                                           {"v", "FvK"}};
    if (branched)
        for (int k = 0; k < 3; ++k) inNames[k].push_back(kBranchInputName);
    const std::vector<std::string> outNames[4] = {
        {"D_um", "hmin_um", "hmax_um"}, {"D0_um", "D1_um"}, {"tc_mu_over_etam"}, {kBranchInputName}};
    TrainingResult results[4];
    TrainingOptions distillOptions[4];
    std::string errors[4];
    // Largest first so that two threads finish together: stretching, relaxation, equilibrium, branch.
    const int order[4] = {1, 2, 0, 3};
#pragma omp parallel for schedule(dynamic, 1) num_threads(std::min(networks, omp_get_max_threads()))
    for (int i = 0; i < networks; ++i) {
        const int k = order[i];
        try {
            TrainingOptions o = scheduleForRows(opt.network, data[k].X.cols(), k == 0 || k == 3 ? 256 : 128);
            o.testFraction = 0.0;              // the test cells are already out
            if (k == 1 && opt.sqrtB2Stretching) {
                using T = VariableTransform;
                o.inputTransforms = {T::Identity, T::Identity, T::Identity, T::Sqrt, T::Identity};
            }
            if (k == 2 && opt.logRelaxation) {
                // tc mu / eta_m > 0 spans two decades and depends on mu and eta_m through tc's
                // sampling window and the vertex-mass group Pi ~ mu / eta_m^2 (docs/FORWARD_MODEL.md, relaxation): products
                // and powers that are sums in log space.
                using T = VariableTransform;
                o.inputTransforms = {T::Identity, T::Log, T::Log, T::Identity, T::Log};
                o.outputTransforms = {T::Log};
            }
            // The branch input (0 or 1) enters as it is.
            if (branched && k < 3 && !o.inputTransforms.empty()) o.inputTransforms.push_back(VariableTransform::Identity);
            if (opt.progress) o.progress = [&, k](const EpochRecord& e) {
#pragma omp critical(trbc_surrogate_progress)
                opt.progress(networkName(k), e);
            };
            const auto t0 = std::chrono::steady_clock::now();
            // Restarts from different initial weights (seeds seed, seed+1, ...); the one with the
            // lowest validation loss is the network (the test cells play no part in the choice), the
            // others are its ensemble members when opt.ensemble[k].
            std::vector<EnsembleMember> others;
            for (int r = 0; r < std::max(1, opt.restarts); ++r) {
                TrainingOptions ro = o;
                ro.seed = o.seed + std::uint64_t(r);
                TrainingResult t = trainNetwork(data[k].X, data[k].Y, ro, inNames[k], outNames[k]);
                const double loss = t.network.history.bestValidationLoss, best = results[k].network.history.bestValidationLoss;
                if (r == 0 || loss < best || (!std::isfinite(best) && std::isfinite(loss))) std::swap(results[k], t);
                // a diverged restart (non-finite validation loss) is not averaged in
                if (r > 0 && k < 3 && opt.ensemble[k] && std::isfinite(t.network.history.bestValidationLoss))
                    others.push_back({std::move(t.network.net), t.network.options.seed, t.network.history.bestValidationLoss});
            }
            std::sort(others.begin(), others.end(), [](const EnsembleMember& a, const EnsembleMember& b) { return a.seed < b.seed; });
            results[k].network.ensemble = std::move(others);
            // A branched network is distilled once the classifier is trained (below).
            if (!branched && k < 3 && opt.distill[k] && !results[k].network.ensemble.empty())
                results[k].network = distilledNetwork(results[k].network, kNetworkBoxes[k], opt.distillSamples,
                                                      opt.distillSeed, o, nullptr);
            distillOptions[k] = o;
            (k < 3 ? rep.wallSeconds[k] : rep.branchWallSeconds) =
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            results[k].network.dataHash = rep.dataHash;
            results[k].network.command = opt.command;
        } catch (const std::exception& e) {
            errors[k] = fmt::format("{} network: {}", networkName(k), e.what());
        }
    }
    for (const std::string& e : errors)
        if (!e.empty()) throw InputError(e);
    if (branched) {
        rep.model.branch = results[3].network;
        rep.model.branched = true;
        for (int k = 0; k < 3; ++k) {
            if (!opt.distill[k] || results[k].network.ensemble.empty()) continue;
            const auto t0 = std::chrono::steady_clock::now();
            TrainedNetwork student = distilledNetwork(results[k].network, kNetworkBoxes[k], opt.distillSamples, opt.distillSeed,
                                                      distillOptions[k], &rep.model.branch);
            student.dataHash = rep.dataHash;
            student.command = opt.command;
            results[k].network = std::move(student);
            rep.wallSeconds[k] += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        }
    }
    rep.model.equilibrium = results[0].network;
    rep.model.stretching = results[1].network;
    rep.model.relaxation = results[2].network;

    // Validation split of each network (the rows its early stopping saw), physical units.
    const int firstOutput[3] = {0, 3, 5};
    for (int k = 0; k < 3; ++k) {
        const auto& val = results[k].split.validation;
        Eigen::MatrixXd Xv(data[k].X.rows(), Eigen::Index(val.size())), Yv(data[k].Y.rows(), Eigen::Index(val.size()));
        for (std::size_t j = 0; j < val.size(); ++j) Xv.col(Eigen::Index(j)) = data[k].X.col(val[j]), Yv.col(Eigen::Index(j)) = data[k].Y.col(val[j]);
        Eigen::MatrixXd P = results[k].network.evaluate(Xv);
        if (k == 2) {  // back to seconds
            const Eigen::ArrayXd scale = Xv.row(4).array() / Xv.row(1).array();
            P.row(0).array() *= scale.transpose();
            Yv.row(0).array() *= scale.transpose();
        }
        for (Eigen::Index o = 0; o < P.rows(); ++o)
            rep.validation.push_back(outputAccuracy(surrogateOutputNames()[firstOutput[k] + o], Yv.row(o).transpose(), P.row(o).transpose()));
    }

    // Held-out cells: every output of every test row (equilibrium and relaxation once per cell).
    if (!testRows.empty()) {
        SurrogateTest t = testSurrogate(rep.model, std::move(testRows));
        rep.testInputs = std::move(t.inputs);
        rep.testTruth = std::move(t.truth);
        rep.testPredicted = std::move(t.predicted);
        rep.testBranch = std::move(t.branch);
        rep.testCellIds = std::move(t.cellIds);
        rep.test = std::move(t.accuracy);
    }
    return rep;
}

SurrogateTest testSurrogate(const Surrogate& s, std::vector<const CampaignRow*> rows) {
    std::stable_sort(rows.begin(), rows.end(), [](const CampaignRow* a, const CampaignRow* b) {
        return std::pair(a->point.cellId, a->point.sampleId) < std::pair(b->point.cellId, b->point.sampleId);
    });
    SurrogateTest t;
    t.inputs.resize(6, Eigen::Index(rows.size()));
    t.truth.resize(6, Eigen::Index(rows.size()));
    for (std::size_t j = 0; j < rows.size(); ++j) {
        const CampaignRow& r = *rows[j];
        t.inputs.col(Eigen::Index(j)) = rowInputs(r);
        t.truth.col(Eigen::Index(j)) << r.D, r.hmin, r.hmax, r.D0, r.D1, r.tc;
        t.cellIds.push_back(r.point.cellId);
    }
    t.predicted = s.evaluate(t.inputs);
    t.branch = s.branchIndicator((Eigen::MatrixXd(2, t.inputs.cols()) << t.inputs.row(0), t.inputs.row(2)).finished());
    t.accuracy = heldOutAccuracy(t.cellIds, t.truth, t.predicted);
    return t;
}

std::string campaignDataHash(const std::vector<CampaignRow>& rows) {
    std::uint64_t h = fnv1a("");
    for (const CampaignRow& r : rows) {
        const std::string line = formatCampaignRow(r);
        h = fnv1a(line.substr(0, line.rfind(',')), h);  // without wall_s
    }
    return fmt::format("fnv1a:{:016x}", h);
}

std::vector<OutputAccuracy> heldOutAccuracy(const std::vector<long>& cellIds, const Eigen::MatrixXd& truth,
                                            const Eigen::MatrixXd& predicted) {
    std::vector<OutputAccuracy> acc;
    for (int o = 0; o < 6; ++o) {
        const bool perCell = o < 3 || o == 5;
        std::vector<double> t, p;
        for (std::size_t j = 0; j < cellIds.size(); ++j) {
            if (perCell && j > 0 && cellIds[j] == cellIds[j - 1]) continue;
            if (!std::isfinite(truth(o, Eigen::Index(j)))) continue;
            t.push_back(truth(o, Eigen::Index(j)));
            p.push_back(predicted(o, Eigen::Index(j)));
        }
        acc.push_back(outputAccuracy(surrogateOutputNames()[o], Eigen::Map<Eigen::VectorXd>(t.data(), Eigen::Index(t.size())),
                                     Eigen::Map<Eigen::VectorXd>(p.data(), Eigen::Index(p.size()))));
    }
    return acc;
}

std::map<long, int> cupLabels(const std::vector<CampaignRow>& rows, const std::map<long, int>& cellBranch, double cupHminUm) {
    std::map<long, int> labels;
    for (const CampaignRow& r : rows) {
        if (labels.count(r.point.cellId)) continue;
        const auto it = cellBranch.find(r.point.cellId);
        labels[r.point.cellId] = it != cellBranch.end() && it->second != 0 && r.hmin >= cupHminUm ? 1 : 0;
    }
    return labels;
}

SwitchAccuracy switchAccuracy(const std::vector<long>& cellIds, const Eigen::MatrixXd& inputs, const Eigen::MatrixXd& truth,
                              const Eigen::MatrixXd& predicted, const std::map<long, int>& cellBranch,
                              const Eigen::RowVectorXd* predictedBranch, const std::map<long, int>* labels, double band) {
    SwitchAccuracy a;
    a.band = band;
    for (const auto& [id, b] : cellBranch)
        if (b != 0)
            for (std::size_t j = 0; j < cellIds.size(); ++j)
                if (cellIds[j] == id) {
                    a.vSwitch = std::isfinite(a.vSwitch) ? std::min(a.vSwitch, inputs(0, Eigen::Index(j))) : inputs(0, Eigen::Index(j));
                    break;
                }
    if (!std::isfinite(a.vSwitch)) return a;  // no kicked cell among these rows
    std::vector<Eigen::Index> near, kicked;
    for (std::size_t j = 0; j < cellIds.size(); ++j) {
        const auto it = cellBranch.find(cellIds[j]);
        if (inputs(0, Eigen::Index(j)) >= a.vSwitch - band) near.push_back(Eigen::Index(j));
        if (it != cellBranch.end() && it->second != 0) kicked.push_back(Eigen::Index(j));
    }
    const auto subset = [&](const std::vector<Eigen::Index>& cols, std::vector<OutputAccuracy>& out, long& cells) {
        std::vector<long> ids;
        Eigen::MatrixXd t(6, Eigen::Index(cols.size())), p(6, Eigen::Index(cols.size()));
        for (std::size_t k = 0; k < cols.size(); ++k) {
            ids.push_back(cellIds[std::size_t(cols[k])]);
            t.col(Eigen::Index(k)) = truth.col(cols[k]);
            p.col(Eigen::Index(k)) = predicted.col(cols[k]);
        }
        cells = 0;
        for (std::size_t k = 0; k < ids.size(); ++k) cells += k == 0 || ids[k] != ids[k - 1];
        out = heldOutAccuracy(ids, t, p);
    };
    subset(near, a.nearSwitch, a.cells);
    subset(kicked, a.kicked, a.kickedCells);
    if (predictedBranch && labels) {
        a.misclassified = 0;
        std::vector<Eigen::Index> right;
        for (const Eigen::Index j : near) {
            const auto it = labels->find(cellIds[std::size_t(j)]);
            const bool wrong = it != labels->end() && (it->second != 0) != ((*predictedBranch)(j) > 0.5);
            const bool first = j == 0 || cellIds[std::size_t(j)] != cellIds[std::size_t(j - 1)];
            if (wrong && first) ++a.misclassified;
            if (!wrong) right.push_back(j);
        }
        subset(right, a.rightBranch, a.rightBranchCells);
    }
    return a;
}

CrossValidationReport crossValidateSurrogate(const std::vector<CampaignRow>& rows, SurrogateTrainingOptions opt, int folds) {
    if (folds < 2) throw InputError(fmt::format("surrogate cross-validation: {} folds; at least 2 are needed", folds));
    const auto t0 = std::chrono::steady_clock::now();
    CrossValidationReport cv;
    cv.folds = folds;
    std::vector<Eigen::MatrixXd> in, truth, pred, branch;
    for (int f = 0; f < folds; ++f) {
        opt.folds = folds;
        opt.fold = f;
        SurrogateTrainingReport rep = trainSurrogate(rows, opt);
        cv.perFold.push_back(rep.test);
        cv.branched = cv.branched || rep.model.branched;
        in.push_back(std::move(rep.testInputs));
        truth.push_back(std::move(rep.testTruth));
        pred.push_back(std::move(rep.testPredicted));
        branch.push_back(rep.testBranch);
        cv.cellIds.insert(cv.cellIds.end(), rep.testCellIds.begin(), rep.testCellIds.end());
    }
    const auto stack = [](const std::vector<Eigen::MatrixXd>& parts) {
        Eigen::Index n = 0;
        for (const auto& m : parts) n += m.cols();
        Eigen::MatrixXd out(parts.empty() ? 6 : parts.front().rows(), n);
        Eigen::Index c = 0;
        for (const auto& m : parts) out.middleCols(c, m.cols()) = m, c += m.cols();
        return out;
    };
    cv.inputs = stack(in);
    cv.branch = stack(branch).row(0);
    cv.truth = stack(truth);
    cv.predicted = stack(pred);
    cv.pooled = heldOutAccuracy(cv.cellIds, cv.truth, cv.predicted);
    cv.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return cv;
}

}  // namespace trbc
