#include "surrogate/flow_surrogate.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <tuple>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "surrogate/network_io.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

using T = VariableTransform;

/// The networks' inputs: each one's name, its value from the cell and the flow's groups, and the
/// transform training puts on it (the log of the positive groups that span decades).
struct NetworkInputAxis {
    const char* name;
    double (*value)(const CellParameters&, const FlowGroups&);
    VariableTransform transform;
};
constexpr std::array<NetworkInputAxis, 6> kNetworkInputs = {{
    {"v", [](const CellParameters& c, const FlowGroups&) { return c.v; }, T::Identity},
    {"FvK", [](const CellParameters&, const FlowGroups& g) { return g.FvK; }, T::Log},
    {"b2", [](const CellParameters& c, const FlowGroups&) { return c.b2; }, T::Identity},
    {"Ca", [](const CellParameters&, const FlowGroups& g) { return g.capillary; }, T::Log},
    {"eta_in_over_eta_out", [](const CellParameters&, const FlowGroups& g) { return g.viscosityRatio; }, T::Log},
    {"Bq", [](const CellParameters&, const FlowGroups& g) { return g.membraneViscosity; }, T::Log},
}};

std::vector<VariableTransform> networkInputTransforms() {
    std::vector<VariableTransform> t;
    for (const NetworkInputAxis& a : kNetworkInputs) t.push_back(a.transform);
    return t;
}
constexpr int kStressAxis = 6, kEtaOutAxis = 5;

/// Sums over held-out cases, from which FlowAccuracy follows (so that folds pool exactly).
struct AccuracySums {
    long cases = 0, tt = 0;
    double sqAngle = 0, sqSwing = 0, sqTtf = 0, sqBrier = 0;
    long far = 0, farWrong = 0, near = 0, nearWrong = 0;
    long steady = 0, withSe = 0;
    double sqAngleSteady = 0, sqTtfSteady = 0, sqAngleSe = 0, sqTtfSe = 0;

    void add(const AccuracySums& o) {
        cases += o.cases, tt += o.tt, sqAngle += o.sqAngle, sqSwing += o.sqSwing, sqTtf += o.sqTtf, sqBrier += o.sqBrier;
        far += o.far, farWrong += o.farWrong, near += o.near, nearWrong += o.nearWrong;
        steady += o.steady, withSe += o.withSe;
        sqAngleSteady += o.sqAngleSteady, sqTtfSteady += o.sqTtfSteady, sqAngleSe += o.sqAngleSe, sqTtfSe += o.sqTtfSe;
    }
    FlowAccuracy accuracy() const {
        FlowAccuracy a;
        a.cases = cases, a.tankTreading = tt;
        if (tt > 0) {
            a.inclinationRmseDeg = std::sqrt(sqAngle / double(tt));
            a.swingRmseDeg = std::sqrt(sqSwing / double(tt));
            a.ttfRelativeRmse = std::sqrt(sqTtf / double(tt));
        }
        a.steady = steady;
        if (steady > 0) a.inclinationRmseSteadyDeg = std::sqrt(sqAngleSteady / double(steady)), a.ttfRelativeRmseSteady = std::sqrt(sqTtfSteady / double(steady));
        if (withSe > 0) a.inclinationNoiseDeg = std::sqrt(sqAngleSe / double(withSe)), a.ttfRelativeNoise = std::sqrt(sqTtfSe / double(withSe));
        if (cases > 0) a.brier = sqBrier / double(cases);
        a.far = far, a.farMisclassified = farWrong, a.near = near, a.nearMisclassified = nearWrong;
        return a;
    }
};

std::vector<const ShearCampaignRow*> finishedRows(const std::vector<ShearCampaignRow>& rows) {
    std::vector<const ShearCampaignRow*> out;
    for (const ShearCampaignRow& r : rows)
        if (r.finished()) out.push_back(&r);
    return out;
}

bool hasTankTreadingValues(const ShearCampaignRow& r) {
    return r.tankTreading() && std::isfinite(r.inclinationDeg) && std::isfinite(r.swingDeg) && std::isfinite(r.ttf) && r.ttf > 0.0;
}

/// The predictions of the held-out rows of each network (FlowHeldOutPrediction), in the order of
/// `regimeRows`, then of the `ttRows` not among them.
std::vector<FlowHeldOutPrediction> heldOutPredictions(const FlowSurrogate& model, const std::vector<const ShearCampaignRow*>& regimeRows,
                                                      const std::vector<const ShearCampaignRow*>& ttRows, int fold) {
    std::vector<FlowHeldOutPrediction> out;
    std::map<const ShearCampaignRow*, std::size_t> at;
    const auto entry = [&](const ShearCampaignRow* r) -> FlowHeldOutPrediction& {
        const auto [it, added] = at.emplace(r, out.size());
        if (added) out.push_back({*r, fold});
        return out[it->second];
    };
    if (!regimeRows.empty()) {
        const Eigen::MatrixXd x = flowInputs(regimeRows);
        const Eigen::VectorXd p = model.predict(x).pTankTreading, tc = model.criticalStressPa(x);
        for (std::size_t k = 0; k < regimeRows.size(); ++k) {
            FlowHeldOutPrediction& e = entry(regimeRows[k]);
            e.regime = true;
            e.pTankTreading = p(Eigen::Index(k)), e.criticalStressPa = tc(Eigen::Index(k));
        }
    }
    if (ttRows.empty()) return out;
    const FlowPrediction p = model.predict(flowInputs(ttRows));
    for (std::size_t k = 0; k < ttRows.size(); ++k) {
        FlowHeldOutPrediction& e = entry(ttRows[k]);
        const Eigen::Index j = Eigen::Index(k);
        e.tankTreading = true;
        e.inclinationDeg = p.inclinationDeg(j), e.swingDeg = p.swingDeg(j), e.ttf = p.ttf(j);
    }
    return out;
}

/// The regime statistics over the regime network's rows, the angle, swing and TTF over the
/// tank-treading network's rows that tank-tread with values.
AccuracySums accuracySums(const std::vector<FlowHeldOutPrediction>& predictions, double boundaryFactor) {
    AccuracySums s;
    for (const FlowHeldOutPrediction& e : predictions) {
        if (!e.regime) continue;
        const ShearCampaignRow& r = e.row;
        ++s.cases;
        s.sqBrier += std::pow(e.pTankTreading - (r.tankTreading() ? 1.0 : 0.0), 2);
        const bool wrong = (e.pTankTreading > 0.5) != r.tankTreading();
        const double stress = shearStressPa(r.point.etaOut, r.point.shearRate), tc = e.criticalStressPa;
        const bool near = std::isfinite(tc) && std::abs(std::log(stress / tc)) <= std::log(boundaryFactor);
        (near ? s.near : s.far)++;
        if (wrong) (near ? s.nearWrong : s.farWrong)++;
    }
    for (const FlowHeldOutPrediction& e : predictions) {
        const ShearCampaignRow& r = e.row;
        if (!e.tankTreading || !hasTankTreadingValues(r)) continue;
        ++s.tt;
        s.sqAngle += std::pow(e.inclinationDeg - r.inclinationDeg, 2);
        s.sqSwing += std::pow(e.swingDeg - r.swingDeg, 2);
        s.sqTtf += std::pow(e.ttf / r.ttf - 1.0, 2);
        if (r.steady) {
            ++s.steady;
            s.sqAngleSteady += std::pow(e.inclinationDeg - r.inclinationDeg, 2);
            s.sqTtfSteady += std::pow(e.ttf / r.ttf - 1.0, 2);
        }
        if (std::isfinite(r.inclinationSeDeg) && std::isfinite(r.ttfSe)) {
            ++s.withSe;
            s.sqAngleSe += r.inclinationSeDeg * r.inclinationSeDeg;
            s.sqTtfSe += std::pow(r.ttfSe / r.ttf, 2);
        }
    }
    return s;
}

/// Restarts from seeds seed, seed + 1, ...; the lowest validation loss is the network, the others
/// its ensemble members when asked.
TrainedNetwork trainWithRestarts(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, TrainingOptions o, int restarts, bool ensemble,
                                 const std::vector<std::string>& inNames, const std::vector<std::string>& outNames) {
    TrainingResult best;
    std::vector<EnsembleMember> others;
    for (int r = 0; r < std::max(1, restarts); ++r) {
        TrainingOptions ro = o;
        ro.seed = o.seed + std::uint64_t(r);
        TrainingResult t = trainNetwork(X, Y, ro, inNames, outNames);
        const double loss = t.network.history.bestValidationLoss, bestLoss = best.network.history.bestValidationLoss;
        if (r == 0 || loss < bestLoss || (!std::isfinite(bestLoss) && std::isfinite(loss))) std::swap(best, t);
        if (r > 0 && ensemble && std::isfinite(t.network.history.bestValidationLoss))
            others.push_back({std::move(t.network.net), t.network.options.seed, t.network.history.bestValidationLoss});
    }
    std::sort(others.begin(), others.end(), [](const EnsembleMember& a, const EnsembleMember& b) { return a.seed < b.seed; });
    best.network.ensemble = std::move(others);
    return std::move(best.network);
}

/// One network's finished rows: those of the finest mesh level (the test and accuracy set) and the
/// coarser ones (always trained on).
struct NetworkRows {
    std::string start;
    std::vector<const ShearCampaignRow*> finest, coarser;
};

/// Finished rows split by network and mesh level. With one start both networks share its rows;
/// with random and in-plane starts the regime takes the random rows (the ensemble protocol) and the
/// tank-treading network the in-plane ones. `levels` ascending, empty when every row is of one
/// level; `ids` the finest level's case ids over both starts, ascending: the test mask's positions.
struct RowSplit {
    std::vector<int> levels;
    NetworkRows regime, tankTreading;
    std::vector<long> ids;
};

std::vector<int> levelsOf(const std::vector<const ShearCampaignRow*>& rows) {
    std::set<int> levels;
    for (const ShearCampaignRow* r : rows) levels.insert(r->meshLevel);
    return {levels.begin(), levels.end()};
}

/// Whether a row of start `rowStart` belongs to the network of start `networkStart`: the same start,
/// or a table or a model that does not record it (one start then serves both networks).
bool ofStart(const std::string& rowStart, const std::string& networkStart) {
    return rowStart.empty() || networkStart.empty() || rowStart == networkStart;
}

RowSplit splitRows(const std::vector<const ShearCampaignRow*>& done) {
    RowSplit s;
    if (done.empty()) return s;
    const auto named = [](const std::string& start) { return start.empty() ? std::string("not recorded (a table without campaign.json)") : start; };
    std::set<std::string> starts;
    for (const ShearCampaignRow* r : done) starts.insert(r->start);
    // A regime network is one protocol's probability, and the in-plane rows are its regressors' only
    // other use: any other mix of starts is refused.
    const bool both = starts == std::set<std::string>{"random", "in-plane"};
    if (starts.size() > 1 && !both)
        throw InputError(fmt::format("flow surrogate: campaigns with the starts '{}' and '{}'; train on one, or on random and in-plane "
                                     "starts of the same design",
                                     named(*starts.begin()), named(*std::next(starts.begin()))));
    // The networks have no cytosol input, and a case given twice would sit in training and test.
    std::set<std::tuple<int, long, std::string>> seen;
    for (const ShearCampaignRow* r : done) {
        if (!sameDesignValue(r->point.etaIn, done.front()->point.etaIn))
            throw InputError(fmt::format("flow surrogate: campaigns with cytosol viscosities {} and {} mPa s; train on one", done.front()->point.etaIn,
                                         r->point.etaIn));
        if (!seen.insert({r->meshLevel, r->point.caseId, r->start}).second)
            throw InputError(fmt::format("flow surrogate: case {} of level {}{} given twice (the same campaign named twice?)", r->point.caseId,
                                         r->meshLevel, r->start.empty() ? "" : fmt::format(" from {} starts", r->start)));
    }
    s.regime.start = both ? "random" : *starts.begin();
    s.tankTreading.start = both ? "in-plane" : s.regime.start;
    std::vector<const ShearCampaignRow*> regimeRows, ttRows;
    for (const ShearCampaignRow* r : done) {
        if (ofStart(r->start, s.regime.start)) regimeRows.push_back(r);
        if (ofStart(r->start, s.tankTreading.start)) ttRows.push_back(r);
    }
    s.levels = levelsOf(done);
    if (both && levelsOf(regimeRows) != levelsOf(ttRows))
        throw InputError(fmt::format("flow surrogate: the random starts' campaigns are of the levels [{}], the in-plane ones' of [{}]; "
                                     "each network needs every level of the model",
                                     fmt::join(levelsOf(regimeRows), ", "), fmt::join(levelsOf(ttRows), ", ")));
    if (s.levels.size() > 1 && s.levels.front() == 0)
        throw InputError("flow surrogate: rows of several campaigns, some without a recorded mesh level (campaign.json)");
    const bool multi = s.levels.size() > 1;
    if (!multi && s.levels.front() == 0) s.levels.clear();
    std::set<long> ids;
    for (auto [rows, net] : {std::pair{&regimeRows, &s.regime}, std::pair{&ttRows, &s.tankTreading}})
        for (const ShearCampaignRow* r : *rows) {
            const bool finest = !multi || r->meshLevel == s.levels.back();
            (finest ? net->finest : net->coarser).push_back(r);
            if (finest) ids.insert(r->point.caseId);
        }
    s.ids.assign(ids.begin(), ids.end());
    return s;
}

/// The test case ids of a seeded permutation of the n ids: every position p with p % folds == fold,
/// or the first testFraction n without folds.
std::set<long> testIds(const std::vector<long>& ids, const FlowSurrogateTrainingOptions& opt) {
    const std::size_t n = ids.size();
    const auto perm = seededPermutation(Eigen::Index(n), opt.testSeed);
    std::set<long> test;
    const std::size_t nTest = opt.folds >= 2 ? 0 : std::size_t(std::llround(opt.testFraction * double(n)));
    for (std::size_t p = 0; p < n; ++p)
        if (opt.folds >= 2 ? int(p % std::size_t(opt.folds)) == opt.fold : p < nTest) test.insert(ids[std::size_t(perm[p])]);
    return test;
}

/// A network's finest-level rows split into training (with the coarser rows) and held-out ones.
struct HeldOut {
    std::vector<const ShearCampaignRow*> train, held;
};

HeldOut holdOut(const NetworkRows& rows, const std::set<long>& test) {
    HeldOut h;
    h.train = rows.coarser;
    for (const ShearCampaignRow* r : rows.finest) (test.count(r->point.caseId) ? h.held : h.train).push_back(r);
    return h;
}

}  // namespace

const std::vector<std::string>& flowSurrogateInputNames() {
    static const std::vector<std::string> names = {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um", "eta_out_mPa_s", "shear_rate_per_s"};
    return names;
}

Eigen::Matrix<double, 7, 1> flowInput(const CellParameters& cell, double etaOutMPaS, double shearRatePerS) {
    Eigen::Matrix<double, 7, 1> x;
    x << cell.v, cell.mu, cell.FvK, cell.b2, cell.etam, etaOutMPaS, shearRatePerS;
    return x;
}

Eigen::MatrixXd flowInputs(const std::vector<const ShearCampaignRow*>& rows) {
    Eigen::MatrixXd x(7, Eigen::Index(rows.size()));
    for (std::size_t k = 0; k < rows.size(); ++k) {
        const ShearCampaignPoint& q = rows[k]->point;
        x.col(Eigen::Index(k)) = flowInput(q.cell, q.etaOut, q.shearRate);
    }
    return x;
}

const std::vector<std::string>& flowNetworkInputNames() {
    static const std::vector<std::string> names = [] {
        std::vector<std::string> n;
        for (const NetworkInputAxis& a : kNetworkInputs) n.emplace_back(a.name);
        return n;
    }();
    return names;
}

Eigen::Matrix<double, 6, 1> flowNetworkInput(const Eigen::Ref<const Eigen::Matrix<double, 7, 1>>& x, double etaInMPaS) {
    const CellParameters cell{x(0), x(1), x(2), x(3), x(4)};
    const FlowGroups g = flowGroups(cell, x(kEtaOutAxis), etaInMPaS, x(kStressAxis));
    Eigen::Matrix<double, 6, 1> out;
    for (std::size_t k = 0; k < kNetworkInputs.size(); ++k) out(Eigen::Index(k)) = kNetworkInputs[k].value(cell, g);
    return out;
}

std::vector<std::string> FlowSurrogate::inputNames() const {
    std::vector<std::string> names = flowNetworkInputNames();
    if (multiLevel()) names.push_back(kFlowLevelInput);
    return names;
}

Eigen::MatrixXd FlowSurrogate::networkInputs(const Eigen::Ref<const Eigen::MatrixXd>& x7) const {
    if (x7.rows() != 7) throw InputError(fmt::format("flow surrogate: inputs have {} rows, expected 7", x7.rows()));
    const Eigen::Index groups = Eigen::Index(flowNetworkInputNames().size());
    Eigen::MatrixXd x(groups + (multiLevel() ? 1 : 0), x7.cols());
    for (Eigen::Index j = 0; j < x7.cols(); ++j) x.col(j).head(groups) = flowNetworkInput(x7.col(j), etaIn);
    if (multiLevel()) x.row(groups).setConstant(level);
    return x;
}

std::string flowSurrogateProtocol(const FlowSurrogate& s) {
    return s.start == "random" ? "ensemble" : s.start == "in-plane" ? "in-plane" : "not recorded";
}

std::string FlowSurrogate::fingerprint(const fs::path& dir) {
    return fingerprintOf({fileFingerprint(dir / "flow_regime.json"), fileFingerprint(dir / "flow_tank_treading.json"),
                          fileFingerprint(dir / "flow_surrogate.json"), fileFingerprint(dir / "training.json")});
}

FlowSurrogate FlowSurrogate::load(const fs::path& dir) {
    FlowSurrogate s;
    s.regime = loadNetwork((dir / "flow_regime.json").string());
    s.tankTreading = loadNetwork((dir / "flow_tank_treading.json").string());
    const fs::path meta = dir / "flow_surrogate.json";
    try {
        std::ifstream in(meta);
        if (!in) throw std::runtime_error("cannot open it");
        const nlohmann::json meta = nlohmann::json::parse(in);
        s.etaIn = meta.at("eta_in_mPa_s").get<double>();
        if (meta.contains("levels")) s.levels = meta.at("levels").get<std::vector<int>>();
        s.start = meta.value("start", std::string());
        s.tankTreadingStart = meta.value("tank_treading_start", s.start);
        if (!s.levels.empty()) s.level = *std::max_element(s.levels.begin(), s.levels.end());
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: not the description of flow networks ({})", meta.string(), e.what()));
    }
    if (!(s.etaIn > 0.0)) throw InputError(fmt::format("{}: eta_in_mPa_s {} must be > 0", meta.string(), s.etaIn));
    for (const TrainedNetwork* n : {&s.regime, &s.tankTreading})
        if (n->net.numInputs() != int(s.inputNames().size()) || n->inputNames != s.inputNames())
            throw InputError(fmt::format("{}: networks with the inputs {}; flow networks of the levels [{}] take the {} inputs {} "
                                         "(train them again with `trbc flow train`)",
                                         dir.string(), fmt::join(n->inputNames, ", "), fmt::join(s.levels, ", "), s.inputNames().size(),
                                         fmt::join(s.inputNames(), ", ")));
    if (s.regime.net.numOutputs() != 1 || s.tankTreading.net.numOutputs() != 3)
        throw InputError(fmt::format("{}: flow_regime.json needs 1 output and flow_tank_treading.json 3", dir.string()));
    return s;
}

void FlowSurrogate::save(const fs::path& dir) const {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw InputError(fmt::format("cannot create {}: {}", dir.string(), ec.message()));
    saveNetwork(regime, (dir / "flow_regime.json").string());
    saveNetwork(tankTreading, (dir / "flow_tank_treading.json").string());
    nlohmann::json meta = {{"eta_in_mPa_s", etaIn},
                                 {"inputs", inputNames()},
                                 {"levels", levels},
                                 {"predicts_level", level},
                                 {"networks", {{"flow_regime", fmt::format("probability of tank-treading; threshold protocol: {}",
                                                                           flowSurrogateProtocol(*this))},
                                               {"flow_tank_treading", fmt::format("inclination_deg, swing_deg, ttf_4pi_f_over_rate; start: {}",
                                                                                  tankTreadingStart.empty() ? "not recorded" : tankTreadingStart)}}},
                                 {"trbc_version", kVersion}};
    if (!start.empty()) meta["start"] = start;
    if (!tankTreadingStart.empty()) meta["tank_treading_start"] = tankTreadingStart;
    writeFileAtomically(dir / "flow_surrogate.json", meta.dump(2) + "\n");
}

namespace {

/// The inputs mapped to the campaign's cytosol viscosity campaignEtaIn (the exact rescaling of
/// FlowSurrogate::predict): every viscosity times s = campaignEtaIn / eta_in, the rate over s.
Eigen::MatrixXd atCampaignCytosol(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::Ref<const Eigen::VectorXd>& etaIn,
                                  double campaignEtaIn) {
    if (x.rows() != 7) throw InputError(fmt::format("flow surrogate: inputs have {} rows, expected 7", x.rows()));
    if (etaIn.size() != x.cols())
        throw InputError(fmt::format("flow surrogate: {} cytosol viscosities for {} inputs", etaIn.size(), x.cols()));
    Eigen::MatrixXd z = x;
    for (Eigen::Index j = 0; j < x.cols(); ++j) {
        if (!(etaIn(j) > 0.0)) throw InputError(fmt::format("flow surrogate: eta_in_mPa_s {} must be > 0", etaIn(j)));
        const double s = campaignEtaIn / etaIn(j);
        z(4, j) *= s, z(kEtaOutAxis, j) *= s, z(kStressAxis, j) /= s;
    }
    return z;
}

}  // namespace

FlowPrediction FlowSurrogate::predict(const Eigen::Ref<const Eigen::MatrixXd>& x, const Eigen::Ref<const Eigen::VectorXd>& etaInCol) const {
    const Eigen::MatrixXd z = atCampaignCytosol(x, etaInCol, etaIn);
    FlowPrediction p;
    p.outsideBox.assign(std::size_t(x.cols()), false);
    for (Eigen::Index j = 0; j < x.cols(); ++j) {
        for (int i = 0; i < 7; ++i) {
            const DesignAxis& a = kShearCampaignAxes[i];
            const double v = i == kStressAxis ? shearStressPa(z(kEtaOutAxis, j), z(kStressAxis, j)) : z(i, j);
            if (!(v >= a.lo && v <= a.hi)) p.outsideBox[std::size_t(j)] = true;
        }
    }
    const Eigen::MatrixXd zn = networkInputs(z);
    p.pTankTreading = regime.evaluate(zn).row(0).transpose().cwiseMax(0.0).cwiseMin(1.0);
    const Eigen::MatrixXd tt = tankTreading.evaluate(zn);
    p.inclinationDeg = tt.row(0).transpose();
    p.swingDeg = tt.row(1).transpose();
    p.ttf = tt.row(2).transpose();
    return p;
}

FlowPrediction FlowSurrogate::predict(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
    return predict(x, Eigen::VectorXd::Constant(x.cols(), etaIn));
}

Eigen::VectorXd FlowSurrogate::criticalStressPa(const Eigen::Ref<const Eigen::MatrixXd>& x, double probability, bool clampToRange) const {
    return criticalStressPa(x, Eigen::VectorXd::Constant(x.cols(), etaIn), probability, clampToRange);
}

Eigen::VectorXd FlowSurrogate::criticalStressPa(const Eigen::Ref<const Eigen::MatrixXd>& xIn, const Eigen::Ref<const Eigen::VectorXd>& etaInOf,
                                                double probability, bool clampToRange) const {
    const DesignAxis& axis = kShearCampaignAxes[kStressAxis];
    const Eigen::Index n = xIn.cols();
    const Eigen::MatrixXd x = atCampaignCytosol(xIn, etaInOf, etaIn);  // the critical stress does not change
    Eigen::VectorXd lo = Eigen::VectorXd::Constant(n, std::log(axis.lo)), hi = Eigen::VectorXd::Constant(n, std::log(axis.hi));
    auto pAt = [&](const Eigen::VectorXd& logStress) {
        Eigen::MatrixXd z = x;
        for (Eigen::Index j = 0; j < n; ++j) z(6, j) = shearRateFromStress(z(kEtaOutAxis, j), std::exp(logStress(j)));
        return Eigen::VectorXd(regime.evaluate(networkInputs(z)).row(0).transpose());
    };
    const Eigen::VectorXd pLo = pAt(lo), pHi = pAt(hi);
    // 40 halvings of 7 decades: far below the networks' resolution.
    for (int it = 0; it < 40; ++it) {
        const Eigen::VectorXd mid = 0.5 * (lo + hi);
        const Eigen::VectorXd pm = pAt(mid);
        for (Eigen::Index j = 0; j < n; ++j) ((pm(j) < probability) == (pLo(j) < probability) ? lo(j) : hi(j)) = mid(j);
    }
    Eigen::VectorXd out(n);
    for (Eigen::Index j = 0; j < n; ++j) {
        if ((pLo(j) < probability) != (pHi(j) < probability))
            out(j) = std::exp(0.5 * (lo(j) + hi(j)));
        else
            out(j) = !clampToRange ? NAN : pLo(j) >= probability ? axis.lo : axis.hi;
    }
    return out;
}

FlowAccuracy flowAccuracy(const FlowSurrogate& model, const std::vector<const ShearCampaignRow*>& rows, double boundaryFactor) {
    std::vector<const ShearCampaignRow*> regimeRows, ttRows;
    for (const ShearCampaignRow* r : rows) {
        if (!r->finished()) continue;
        if (ofStart(r->start, model.start)) regimeRows.push_back(r);
        if (ofStart(r->start, model.tankTreadingStart.empty() ? model.start : model.tankTreadingStart)) ttRows.push_back(r);
    }
    return accuracySums(heldOutPredictions(model, regimeRows, ttRows, 0), boundaryFactor).accuracy();
}

std::string flowCampaignDataHash(const std::vector<ShearCampaignRow>& rows) {
    std::uint64_t h = fnv1a("");
    for (const ShearCampaignRow& r : rows) {
        ShearCampaignRow copy = r;
        copy.wallSeconds = 0.0;  // timings differ between runs of the same campaign
        h = fnv1a(formatShearCampaignRow(copy) + (r.meshLevel > 0 ? fmt::format(",level {}", r.meshLevel) : "") + "\n", h);
    }
    return fmt::format("{:016x}", h);
}

FlowSurrogateTrainingReport trainFlowSurrogate(const std::vector<ShearCampaignRow>& rows, const FlowSurrogateTrainingOptions& opt) {
    const auto t0 = std::chrono::steady_clock::now();
    if (opt.folds == 1 || opt.folds < 0 || (opt.folds >= 2 && (opt.fold < 0 || opt.fold >= opt.folds)))
        throw InputError(fmt::format("flow surrogate: fold {} of {} folds (folds 0 or >= 2, fold in [0, folds))", opt.fold, opt.folds));
    if (!(opt.testFraction >= 0.0 && opt.testFraction < 1.0))
        throw InputError(fmt::format("flow surrogate: test fraction {} is outside [0, 1)", opt.testFraction));
    checkTrainingOptions(opt.network);
    FlowSurrogateTrainingReport rep;
    rep.rows = long(rows.size());
    rep.dataHash = flowCampaignDataHash(rows);
    const auto done = finishedRows(rows);
    rep.used = long(done.size());
    const RowSplit split = splitRows(done);
    for (const NetworkRows* net : {&split.regime, &split.tankTreading})
        if (net->finest.size() < 20)
            throw InputError(fmt::format("flow surrogate: {} finished cases{}{}, at least 20 needed", net->finest.size(),
                                         split.regime.start != split.tankTreading.start ? fmt::format(" from {} starts", net->start) : "",
                                         split.levels.size() > 1 ? fmt::format(" at the finest level {}", split.levels.back()) : ""));
    const std::set<long> test = testIds(split.ids, opt);
    const HeldOut regimeRows = holdOut(split.regime, test), ttRows = holdOut(split.tankTreading, test);
    const std::vector<const ShearCampaignRow*>& train = regimeRows.train;
    std::vector<const ShearCampaignRow*> tt;
    for (const ShearCampaignRow* r : ttRows.train)
        if (hasTankTreadingValues(*r)) tt.push_back(r);
    FlowSurrogate& model = rep.model;
    model.levels = split.levels;
    model.level = split.levels.empty() ? 0 : split.levels.back();
    rep.testCases = long(test.size());
    rep.regimeRows = long(train.size());
    rep.tankTreadingRows = long(tt.size());
    const long ttCount = long(tt.size());
    const long regimeTt = std::count_if(train.begin(), train.end(), [](const ShearCampaignRow* r) { return r->tankTreading(); });
    if (ttCount < 10 || regimeTt < 1 || long(train.size()) - regimeTt < 1)
        throw InputError(fmt::format("flow surrogate: {} tank-treading cases with values, and {} tank-treading and {} other cases for the "
                                     "regime, in training; at least 10, 1 and 1 needed",
                                     ttCount, regimeTt, long(train.size()) - regimeTt));

    model.etaIn = done.front()->point.etaIn;  // the viscosity ratio of every row (one cytosol, splitRows)
    // Each row at its own level (networkInputs puts the model's level in the last row).
    auto inputsAtOwnLevel = [&](const std::vector<const ShearCampaignRow*>& rs) {
        Eigen::MatrixXd x = model.networkInputs(flowInputs(rs));
        if (model.multiLevel())
            for (std::size_t k = 0; k < rs.size(); ++k) x(x.rows() - 1, Eigen::Index(k)) = rs[k]->meshLevel;
        return x;
    };
    const Eigen::MatrixXd Xr = inputsAtOwnLevel(train), Xt = inputsAtOwnLevel(tt);
    Eigen::MatrixXd Yr(1, Xr.cols()), Yt(3, Xt.cols());
    for (std::size_t k = 0; k < train.size(); ++k) Yr(0, Eigen::Index(k)) = train[k]->tankTreading() ? 1.0 : 0.0;
    for (std::size_t k = 0; k < tt.size(); ++k) Yt.col(Eigen::Index(k)) << tt[k]->inclinationDeg, tt[k]->swingDeg, tt[k]->ttf;

    TrainedNetwork nets[2];
    std::string errors[2];
#pragma omp parallel for schedule(dynamic, 1) num_threads(std::min(2, omp_get_max_threads()))
    for (int k = 0; k < 2; ++k) {
        try {
            TrainingOptions o = scheduleForRows(opt.network, k == 0 ? Xr.cols() : Xt.cols(), 128);
            o.testFraction = 0.0;  // the test cases are already out
            o.inputTransforms = networkInputTransforms();
            if (model.multiLevel()) o.inputTransforms.push_back(T::Identity);
            o.outputTransforms = k == 0 ? std::vector<VariableTransform>{T::Identity}
                                        : std::vector<VariableTransform>{T::Identity, T::Identity, T::Log};
            const std::vector<std::string> in = model.inputNames();
            nets[k] = k == 0 ? trainWithRestarts(Xr, Yr, o, opt.restarts, opt.ensemble, in, {"p_tank_treading"})
                             : trainWithRestarts(Xt, Yt, o, opt.restarts, opt.ensemble, in, {"inclination_deg", "swing_deg", "ttf_4pi_f_over_rate"});
            nets[k].dataHash = rep.dataHash;
            nets[k].command = opt.command;
        } catch (const std::exception& e) {
            errors[k] = fmt::format("{} network: {}", k == 0 ? "regime" : "tank-treading", e.what());
        }
    }
    for (const std::string& e : errors)
        if (!e.empty()) throw InputError(e);
    model.regime = std::move(nets[0]);
    model.tankTreading = std::move(nets[1]);
    model.start = split.regime.start;
    model.tankTreadingStart = split.tankTreading.start;
    rep.heldOut = heldOutPredictions(rep.model, regimeRows.held, ttRows.held, opt.fold);
    rep.test = accuracySums(rep.heldOut, opt.boundaryFactor).accuracy();
    rep.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return rep;
}

FlowCrossValidation crossValidateFlowSurrogate(const std::vector<ShearCampaignRow>& rows, FlowSurrogateTrainingOptions opt, int folds) {
    if (folds < 2) throw InputError(fmt::format("flow surrogate: {} folds (at least 2)", folds));
    FlowCrossValidation cv;
    cv.folds = folds;
    cv.rows = long(rows.size());
    opt.folds = folds;
    AccuracySums pooled;
    for (int f = 0; f < folds; ++f) {
        opt.fold = f;
        const FlowSurrogateTrainingReport rep = trainFlowSurrogate(rows, opt);
        const AccuracySums s = accuracySums(rep.heldOut, opt.boundaryFactor);
        cv.predictions.insert(cv.predictions.end(), rep.heldOut.begin(), rep.heldOut.end());
        pooled.add(s);
        cv.perFold.push_back(s.accuracy());
    }
    cv.pooled = pooled.accuracy();
    return cv;
}

}  // namespace trbc
