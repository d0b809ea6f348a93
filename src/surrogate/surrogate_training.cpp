// Training the surrogates from a campaign table (trainSurrogate, surrogate/surrogate.hpp).
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

Eigen::VectorXd campaignRowInputs(const CampaignRow& r) {
    Eigen::VectorXd x(6);
    x << r.point.p.v, r.point.p.mu, r.point.p.FvK, r.point.p.b2, r.point.p.etam, r.point.fext;
    return x;
}

namespace {

struct NetworkData {
    Eigen::MatrixXd X, Y;  ///< physical units (relaxation: Y = tc mu / etam)
};

/// Where the dropped rows lie: per input, counts in five equal bins of its range.
std::vector<std::string> describeDropped(const std::vector<const CampaignRow*>& dropped) {
    std::vector<std::string> lines;
    if (dropped.empty()) return lines;
    const PriorRange box[6] = {kPriorV, kPriorMu, kPriorFvK, kPriorB2, kPriorEtam, kPriorFext};
    for (int k = 0; k < 6; ++k) {
        int bins[5] = {0, 0, 0, 0, 0};
        for (const CampaignRow* r : dropped) {
            const double u = (campaignRowInputs(*r)(k) - box[k].lo) / (box[k].hi - box[k].lo);
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

/// The ensemble's student on uniform points of the box (distilledNetwork). With a branch classifier
/// the points carry its branch as the last input (the teacher's branch input).
TrainedNetwork distilledNetwork(const TrainedNetwork& teacher, const std::vector<PriorRange>& box, long samples,
                                std::uint64_t seed, const TrainingOptions& o, const TrainedNetwork* classifier) {
    if (samples < 1000) throw InputError(fmt::format("surrogate distillation: {} box samples; at least 1000 are needed", samples));
    Eigen::MatrixXd X = uniformBoxPoints(box, samples, seed);
    if (classifier) {
        const Eigen::MatrixXd vFvK = vFvKOf(X);
        X = withBranchRow(X, classifyBranch(*classifier, vFvK, Precision::Double));
    }
    return distilledNetwork(teacher, X, seed, o);
}

void checkSplitOptions(const SurrogateTrainingOptions& opt) {
    if (!(opt.testFraction >= 0.0 && opt.testFraction < 0.5))
        throw InputError(fmt::format("surrogate training: test fraction {} is outside [0, 0.5)", opt.testFraction));
    if (opt.folds == 1 || opt.folds < 0 || (opt.folds >= 2 && (opt.fold < 0 || opt.fold >= opt.folds)))
        throw InputError(fmt::format("surrogate training: fold {} of {} folds (folds must be 0 or >= 2, fold in [0, folds))", opt.fold,
                                     opt.folds));
}

/// The table's cells and which of them are held out as test cells.
struct CellSplit {
    std::map<long, std::vector<const CampaignRow*>> byCell;
    std::vector<long> cellIds;  ///< ascending
    std::vector<bool> isTest;   ///< per entry of cellIds
};

/// Groups the rows by cell and holds out the test cells of a seeded permutation perm of the cells:
/// perm[k] for k = fold (mod folds) with K-fold cross-validation, else perm[0 .. ceil(testFraction x
/// cells) - 1]. Sets rep.dataHash, rep.cells and rep.testCells.
CellSplit splitCells(const std::vector<CampaignRow>& rows, const SurrogateTrainingOptions& opt, SurrogateTrainingReport& rep) {
    CellSplit s;
    for (const CampaignRow& r : rows) s.byCell[r.point.cellId].push_back(&r);
    rep.dataHash = campaignDataHash(rows);
    rep.cells = long(s.byCell.size());
    if (rep.cells < 10) throw InputError(fmt::format("surrogate training: {} cells in the table; at least 10 are needed", rep.cells));

    for (const auto& [id, v] : s.byCell) s.cellIds.push_back(id);
    const auto perm = seededPermutation(Eigen::Index(s.cellIds.size()), opt.testSeed);
    s.isTest.assign(s.cellIds.size(), false);
    if (opt.folds >= 2) {
        for (std::size_t k = 0; k < s.cellIds.size(); ++k) s.isTest[perm[Eigen::Index(k)]] = int(k % std::size_t(opt.folds)) == opt.fold;
        rep.testCells = long(std::count(s.isTest.begin(), s.isTest.end(), true));
    } else {
        rep.testCells = long(std::ceil(opt.testFraction * double(s.cellIds.size())));
        for (long k = 0; k < rep.testCells; ++k) s.isTest[perm[k]] = true;
    }
    return s;
}

/// The equilibrium branch label of each cell (0 disc, 1 cup) and whether the networks take it as an
/// input (branched: the training cells hold both branches).
struct CellBranches {
    const SurrogateTrainingOptions& opt;
    const std::map<long, int>& labels;
    bool branched = false;

    int of(long cellId) const {
        if (!opt.cellBranch.count(cellId))
            throw InputError(fmt::format("surrogate training: cell {} has no equilibrium branch record (the campaign's "
                                         "equilibria.csv lacks it)", cellId));
        return labels.at(cellId);
    }
    Eigen::VectorXd withBranch(Eigen::VectorXd x, long cellId) const {
        if (!branched) return x;
        x.conservativeResize(x.size() + 1);
        x(x.size() - 1) = of(cellId);
        return x;
    }
};

bool trainingCellsHoldBothBranches(const CellSplit& split, const CellBranches& branches) {
    if (branches.opt.cellBranch.empty()) return false;
    bool seen[2] = {false, false};
    for (std::size_t c = 0; c < split.cellIds.size(); ++c)
        if (!split.isTest[c]) seen[branches.of(split.cellIds[c]) != 0] = true;
    return seen[0] && seen[1];
}

/// Input and output columns of each network (equilibrium, stretching, relaxation, branch), the
/// rows with failed outputs and the rows of the test cells.
struct TrainingSamples {
    std::vector<Eigen::VectorXd> xs[4], ys[4];
    std::vector<const CampaignRow*> droppedRows, testRows;
};

/// Equilibrium and relaxation once per training cell (from its first row), stretching once per row;
/// counts the samples without a finite output in rep.dropped.
TrainingSamples collectSamples(const CellSplit& split, const CellBranches& branches, SurrogateTrainingReport& rep) {
    auto eqOk = [](const CampaignRow& r) { return std::isfinite(r.D) && std::isfinite(r.hmin) && std::isfinite(r.hmax); };
    auto stOk = [](const CampaignRow& r) { return std::isfinite(r.D0) && std::isfinite(r.D1); };
    auto rxOk = [](const CampaignRow& r) { return std::isfinite(r.tc) && r.tc > 0; };
    const bool branched = branches.branched;

    TrainingSamples s;
    auto& xs = s.xs;
    auto& ys = s.ys;
    for (std::size_t c = 0; c < split.cellIds.size(); ++c) {
        const auto& cell = split.byCell.at(split.cellIds[c]);
        if (split.isTest[c]) {
            s.testRows.insert(s.testRows.end(), cell.begin(), cell.end());
            continue;
        }
        const CampaignRow& first = *cell.front();
        const Eigen::VectorXd x0 = campaignRowInputs(first);
        const long id = split.cellIds[c];
        if (eqOk(first)) {
            xs[0].push_back(branches.withBranch((Eigen::VectorXd(2) << x0(0), x0(2)).finished(), id));
            ys[0].push_back((Eigen::VectorXd(3) << first.D, first.hmin, first.hmax).finished());
            if (branched && x0(0) >= kCupMinV) {
                xs[3].push_back((Eigen::VectorXd(2) << x0(0), x0(2)).finished());
                ys[3].push_back(Eigen::VectorXd::Constant(1, branches.of(id)));
            } else if (branched && branches.of(id) != 0) {
                throw InputError(fmt::format("surrogate training: cell {} is a cup at v {} < {}, where a branched "
                                             "surrogate takes the disc (kCupMinV)", id, x0(0), kCupMinV));
            }
        } else {
            ++rep.dropped[0];
        }
        if (rxOk(first)) {
            xs[2].push_back(branches.withBranch(x0.head(5), id));
            ys[2].push_back(Eigen::VectorXd::Constant(1, first.tc * first.point.p.mu / first.point.p.etam));
        } else {
            ++rep.dropped[2];
        }
        for (const CampaignRow* r : cell) {
            if (!r->ok()) s.droppedRows.push_back(r);
            if (!stOk(*r)) {
                ++rep.dropped[1];
                continue;
            }
            const Eigen::VectorXd x = campaignRowInputs(*r);
            xs[1].push_back(branches.withBranch((Eigen::VectorXd(5) << x(0), x(1), x(2), x(3), x(5)).finished(), id));
            ys[1].push_back((Eigen::VectorXd(2) << r->D0, r->D1).finished());
        }
    }
    return s;
}

std::string networkName(int k) { return k == 3 ? std::string("branch") : surrogateNetworkNames()[std::size_t(k)]; }

/// The samples of the first `networks` networks as matrices (one column per sample); sets rep.used
/// and rep.branchUsed.
void assembleNetworkData(const TrainingSamples& s, int networks, NetworkData (&data)[4], SurrogateTrainingReport& rep) {
    for (int k = 0; k < networks; ++k) {
        (k < 3 ? rep.used[k] : rep.branchUsed) = long(s.xs[k].size());
        if (s.xs[k].size() < 10)
            throw InputError(fmt::format("surrogate training: only {} usable samples for the {} network", s.xs[k].size(), networkName(k)));
        data[k].X.resize(s.xs[k].front().size(), Eigen::Index(s.xs[k].size()));
        data[k].Y.resize(s.ys[k].front().size(), Eigen::Index(s.ys[k].size()));
        for (std::size_t j = 0; j < s.xs[k].size(); ++j) data[k].X.col(Eigen::Index(j)) = s.xs[k][j], data[k].Y.col(Eigen::Index(j)) = s.ys[k][j];
    }
}

/// Input and output names of each network (equilibrium, stretching, relaxation, branch).
struct NetworkColumns {
    std::vector<std::string> in[4];
    std::vector<std::string> out[4];
};

NetworkColumns networkColumns(bool branched) {
    NetworkColumns n{{{"v", "FvK"},
                      {"v", "mu_uN_per_m", "FvK", "b2", "Fext_pN"},
                      {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um"},
                      {"v", "FvK"}},
                     {{"D_um", "hmin_um", "hmax_um"}, {"D0_um", "D1_um"}, {"tc_mu_over_etam"}, {kBranchInputName}}};
    if (branched)
        for (int k = 0; k < 3; ++k) n.in[k].push_back(kBranchInputName);
    return n;
}

/// The training schedule and variable transforms of network k.
TrainingOptions networkTrainingOptions(int k, Eigen::Index samples, const SurrogateTrainingOptions& opt, bool branched) {
    TrainingOptions o = scheduleForRows(opt.network, samples, k == 0 || k == 3 ? 256 : 128);
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
    if (opt.progress) o.progress = [&opt, k](const EpochRecord& e) {
#pragma omp critical(trbc_surrogate_progress)
        opt.progress(networkName(k), e);
    };
    return o;
}

/// Restarts from different initial weights (seeds seed, seed+1, ...); the one with the lowest
/// validation loss is the network (the test cells play no part in the choice), the others are its
/// ensemble members when opt.ensemble[k].
TrainingResult trainWithRestarts(int k, const NetworkData& d, const TrainingOptions& o, const SurrogateTrainingOptions& opt,
                                 const NetworkColumns& columns) {
    TrainingResult best;
    std::vector<EnsembleMember> others;
    for (int r = 0; r < std::max(1, opt.restarts); ++r) {
        TrainingOptions ro = o;
        ro.seed = o.seed + std::uint64_t(r);
        TrainingResult t = trainNetwork(d.X, d.Y, ro, columns.in[k], columns.out[k]);
        const double loss = t.network.history.bestValidationLoss, bestLoss = best.network.history.bestValidationLoss;
        if (r == 0 || loss < bestLoss || (!std::isfinite(bestLoss) && std::isfinite(loss))) std::swap(best, t);
        // a diverged restart (non-finite validation loss) is not averaged in
        if (r > 0 && k < 3 && opt.ensemble[k] && std::isfinite(t.network.history.bestValidationLoss))
            others.push_back({std::move(t.network.net), t.network.options.seed, t.network.history.bestValidationLoss});
    }
    std::sort(others.begin(), others.end(), [](const EnsembleMember& a, const EnsembleMember& b) { return a.seed < b.seed; });
    best.network.ensemble = std::move(others);
    return best;
}

/// Trains the networks concurrently, largest first; an unbranched ensemble is distilled at once, a
/// branched one keeps its schedule in distillOptions for distillBranched. All networks finish before
/// the first error (in network order) is thrown.
void trainNetworks(const NetworkData (&data)[4], int networks, bool branched, const SurrogateTrainingOptions& opt,
                   TrainingResult (&results)[4], TrainingOptions (&distillOptions)[4], SurrogateTrainingReport& rep) {
    const NetworkColumns columns = networkColumns(branched);
    std::string errors[4];
    // Largest first so that two threads finish together: stretching, relaxation, equilibrium, branch.
    const int order[4] = {1, 2, 0, 3};
#pragma omp parallel for schedule(dynamic, 1) num_threads(std::min(networks, omp_get_max_threads()))
    for (int i = 0; i < networks; ++i) {
        const int k = order[i];
        try {
            const TrainingOptions o = networkTrainingOptions(k, data[k].X.cols(), opt, branched);
            const auto t0 = std::chrono::steady_clock::now();
            results[k] = trainWithRestarts(k, data[k], o, opt, columns);
            // A branched network is distilled once the classifier is trained (distillBranched).
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
}

/// The ensembles of a branched surrogate distilled with the classifier's branch as the last input.
void distillBranched(const SurrogateTrainingOptions& opt, const TrainingOptions (&distillOptions)[4], TrainingResult (&results)[4],
                     SurrogateTrainingReport& rep) {
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

/// Accuracy of each network on its validation split (the rows its early stopping saw), physical units.
void addValidationAccuracy(const NetworkData (&data)[4], const TrainingResult (&results)[4], SurrogateTrainingReport& rep) {
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
}

/// Every output of every row of the held-out cells (equilibrium and relaxation once per cell).
void addTestAccuracy(std::vector<const CampaignRow*> testRows, SurrogateTrainingReport& rep) {
    if (testRows.empty()) return;
    SurrogateTest t = testSurrogate(rep.model, std::move(testRows));
    rep.testInputs = std::move(t.inputs);
    rep.testTruth = std::move(t.truth);
    rep.testPredicted = std::move(t.predicted);
    rep.testBranch = std::move(t.branch);
    rep.testCellIds = std::move(t.cellIds);
    rep.test = std::move(t.accuracy);
}

}  // namespace

SurrogateTrainingReport trainSurrogate(const std::vector<CampaignRow>& rows, const SurrogateTrainingOptions& opt) {
    checkSplitOptions(opt);
    SurrogateTrainingReport rep;
    rep.rows = long(rows.size());
    const CellSplit split = splitCells(rows, opt, rep);

    // Branched when the training cells hold both branches (the test cells play no part in the choice).
    rep.cellLabel = cupLabels(rows, opt.cellBranch, opt.cupHminUm);
    CellBranches branches{opt, rep.cellLabel, false};
    branches.branched = trainingCellsHoldBothBranches(split, branches);
    const bool branched = branches.branched;

    TrainingSamples samples = collectSamples(split, branches, rep);
    rep.droppedWhere = describeDropped(samples.droppedRows);

    const int networks = branched ? 4 : 3;
    NetworkData data[4];
    assembleNetworkData(samples, networks, data, rep);

    TrainingResult results[4];
    TrainingOptions distillOptions[4];
    trainNetworks(data, networks, branched, opt, results, distillOptions, rep);
    if (branched) {
        rep.model.branch = results[3].network;
        rep.model.branched = true;
        distillBranched(opt, distillOptions, results, rep);
    }
    rep.model.equilibrium = results[0].network;
    rep.model.stretching = results[1].network;
    rep.model.relaxation = results[2].network;

    addValidationAccuracy(data, results, rep);
    addTestAccuracy(std::move(samples.testRows), rep);
    return rep;
}

}  // namespace trbc
