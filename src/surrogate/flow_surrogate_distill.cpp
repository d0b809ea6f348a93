// One network in place of each flow ensemble (distillFlowSurrogate, flow_surrogate.hpp): the
// student learns the ensemble's mean where the ensemble is defined, the campaign's box, and is
// compared with it at points of another design, so its own error can be added to the ensemble's.
#include <fmt/format.h>

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>

#include "core/error.hpp"
#include "core/version.hpp"
#include "surrogate/flow_surrogate.hpp"

namespace trbc {

Eigen::MatrixXd flowDesignInputs(DesignKind kind, long n, std::uint64_t seed, double etaIn) {
    const std::vector<ShearCampaignPoint> pts = shearCampaignDesign(kind, n, seed, etaIn);
    Eigen::MatrixXd x(7, n);
    for (long j = 0; j < n; ++j) x.col(j) = flowInput(pts[std::size_t(j)].cell, pts[std::size_t(j)].etaOut, pts[std::size_t(j)].shearRate);
    return x;
}

FlowDistillationCheck compareFlowSurrogates(const FlowSurrogate& student, const FlowSurrogate& teacher,
                                            const Eigen::Ref<const Eigen::MatrixXd>& x7) {
    const FlowPrediction s = student.predict(x7), t = teacher.predict(x7);
    FlowDistillationCheck c;
    c.points = long(x7.cols());
    double p2 = 0.0, a2 = 0.0, w2 = 0.0, f2 = 0.0;
    long disagree = 0;
    for (Eigen::Index j = 0; j < x7.cols(); ++j) {
        p2 += std::pow(s.pTankTreading(j) - t.pTankTreading(j), 2);
        disagree += (s.pTankTreading(j) >= 0.5) != (t.pTankTreading(j) >= 0.5);
        if (t.pTankTreading(j) < 0.5) continue;
        ++c.tankTreading;
        a2 += std::pow(s.inclinationDeg(j) - t.inclinationDeg(j), 2);
        w2 += std::pow(s.swingDeg(j) - t.swingDeg(j), 2);
        f2 += std::pow(s.ttf(j) / t.ttf(j) - 1.0, 2);
    }
    if (c.points > 0) {
        c.probabilityRmse = std::sqrt(p2 / double(c.points));
        c.regimeDisagreement = double(disagree) / double(c.points);
    }
    if (c.tankTreading > 0) {
        const double n = double(c.tankTreading);
        c.inclinationRmseDeg = std::sqrt(a2 / n);
        c.swingRmseDeg = std::sqrt(w2 / n);
        c.ttfRelativeRmse = std::sqrt(f2 / n);
    }
    return c;
}

FlowDistillation distillFlowSurrogate(const FlowSurrogate& teacher, const FlowDistillationOptions& opt) {
    if (teacher.multiLevel())
        throw InputError("flow distillation: the networks are multi-level; their level input would be one constant");
    for (const TrainedNetwork* n : {&teacher.regime, &teacher.tankTreading}) {
        if (n->distillation.members > 0)
            throw InputError("flow distillation: the networks are distilled already; distil their ensemble instead, whose error "
                             "against the data the student's adds to");
        if (n->ensemble.empty())
            throw InputError("flow distillation: the networks are single networks, not ensembles (trained with --restarts 1 or "
                             "--no-ensemble); there is nothing to distil");
    }
    if (opt.samples < 1000 || opt.samples > 10000000)
        throw InputError(fmt::format("flow distillation: {} samples (must lie in [1000, 1e7])", opt.samples));
    if (opt.checkSamples < 100 || opt.checkSamples > 10000000)
        throw InputError(fmt::format("flow distillation: {} check samples (must lie in [100, 1e7])", opt.checkSamples));
    if (opt.hiddenLayers.empty()) throw InputError("flow distillation: no hidden layer");
    for (int w : opt.hiddenLayers)
        if (w < 1 || w > 4096) throw InputError(fmt::format("flow distillation: a hidden layer of {} (must lie in [1, 4096])", w));
    const auto t0 = std::chrono::steady_clock::now();
    const Eigen::MatrixXd zn = teacher.networkInputs(flowDesignInputs(DesignKind::Sobol, opt.samples, opt.seed, teacher.etaIn));
    FlowDistillation d;
    d.model = teacher;
    const TrainedNetwork* teachers[2] = {&teacher.regime, &teacher.tankTreading};
    TrainedNetwork* students[2] = {&d.model.regime, &d.model.tankTreading};
    std::exception_ptr errors[2];
#pragma omp parallel for schedule(static, 1) num_threads(std::min(2, omp_get_max_threads()))
    for (int k = 0; k < 2; ++k) {
        try {
            TrainingOptions o = teachers[k]->options;
            o.hiddenLayers = opt.hiddenLayers;
            o.seed = opt.trainingSeed;
            o.testFraction = 0.0;
            TrainedNetwork s = distilledNetwork(*teachers[k], zn, opt.seed, o);
            s.dataHash = teachers[k]->dataHash;
            s.command = opt.command;
            *students[k] = std::move(s);
        } catch (...) {
            errors[k] = std::current_exception();
        }
    }
    for (const std::exception_ptr& e : errors)
        if (e) std::rethrow_exception(e);
    d.check = compareFlowSurrogates(d.model, teacher, flowDesignInputs(DesignKind::Uniform, opt.checkSamples, opt.seed + 1, teacher.etaIn));
    d.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return d;
}

nlohmann::json flowDistillationJson(const nlohmann::json& teacherTraining, const FlowDistillationOptions& opt,
                                    const FlowDistillation& d, const std::string& teacherDir, const std::string& command) {
    auto num = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(nullptr); };
    nlohmann::json j = teacherTraining;
    j["distillation"] = withBuild({{"command", command},
                         {"teacher", teacherDir},
                         {"samples", opt.samples},
                         {"seed", opt.seed},
                         {"training_seed", opt.trainingSeed},
                         {"hidden_layers", opt.hiddenLayers},
                         {"wall_s", d.wallSeconds},
                         {"check",
                          {{"design", "uniform"},
                           {"seed", opt.seed + 1},
                           {"points", d.check.points},
                           {"tank_treading", d.check.tankTreading},
                           {"probability_rmse", num(d.check.probabilityRmse)},
                           {"regime_disagreement", num(d.check.regimeDisagreement)},
                           {"inclination_rmse_deg", num(d.check.inclinationRmseDeg)},
                           {"swing_rmse_deg", num(d.check.swingRmseDeg)},
                           {"ttf_relative_rmse", num(d.check.ttfRelativeRmse)}}}});
    return j;
}

}  // namespace trbc
