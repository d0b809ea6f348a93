// The accuracy of the surrogates: per-output errors, held-out tests, the branch switch and
// cross-validation (surrogate/surrogate.hpp).
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

SurrogateTest testSurrogate(const Surrogate& s, std::vector<const CampaignRow*> rows) {
    std::stable_sort(rows.begin(), rows.end(), [](const CampaignRow* a, const CampaignRow* b) {
        return std::pair(a->point.cellId, a->point.sampleId) < std::pair(b->point.cellId, b->point.sampleId);
    });
    SurrogateTest t;
    t.inputs.resize(6, Eigen::Index(rows.size()));
    t.truth.resize(6, Eigen::Index(rows.size()));
    for (std::size_t j = 0; j < rows.size(); ++j) {
        const CampaignRow& r = *rows[j];
        t.inputs.col(Eigen::Index(j)) = campaignRowInputs(r);
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
