#include "analysis/flow_data_sets.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "analysis/validation_data.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "sampling/shear_campaign_table.hpp"

namespace fs = std::filesystem;

namespace trbc {

namespace {

/// The points of `column` of a set with their abscissae, blanks dropped.
std::pair<std::vector<double>, std::vector<double>> columnPoints(const ValidationData& d, std::size_t column) {
    std::vector<double> x, y;
    for (std::size_t r = 0; r < d.points.x.size(); ++r)
        if (std::isfinite(d.points.y[r][column])) x.push_back(d.points.x[r]), y.push_back(d.points.y[r][column]);
    return {x, y};
}

Eigen::VectorXd vector(const std::vector<double>& v) { return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size())); }

/// Critical stresses, one curve per viscosity in increasing order.
FlowDataSet stressSet(const ValidationData& d, std::string name) {
    FlowDataSet s;
    s.name = std::move(name);
    s.observable = FlowObservable::CriticalStress;
    std::map<double, std::vector<double>> byViscosity;
    for (std::size_t r = 0; r < d.points.x.size(); ++r)
        if (std::isfinite(d.points.y[r][0])) byViscosity[d.points.x[r]].push_back(d.points.y[r][0]);
    for (const auto& [eta, tau] : byViscosity) s.curves.push_back({eta, Eigen::VectorXd(), vector(tau)});
    s.files = {d.set.file};
    return s;
}

/// A distilled student's error against its ensemble (training.json's `distillation.check`), added
/// in quadrature to the angle and TTF errors and to the regime's error rate.
void addDistillationError(const nlohmann::json& distillation, const fs::path& file, FlowNetworkErrors& e) {
    double angle = NAN, ttf = NAN, regime = NAN;
    try {
        const nlohmann::json& c = distillation.at("check");
        angle = c.at("inclination_rmse_deg").get<double>();
        ttf = c.at("ttf_relative_rmse").get<double>();
        regime = c.at("regime_disagreement").get<double>();
    } catch (const nlohmann::json::exception& x) {
        throw InputError(fmt::format("{}: distillation.check: {}", file.string(), x.what()));
    }
    if (!(angle >= 0.0 && ttf >= 0.0 && regime >= 0.0 && regime <= 0.5))
        throw InputError(fmt::format("{}: distillation.check gives an angle error {}, a TTF error {} (must be >= 0) or a regime "
                                     "disagreement {} (must lie in [0, 0.5])",
                                     file.string(), angle, ttf, regime));
    e.inclinationDeg = std::hypot(e.inclinationDeg, angle);
    e.ttfRelative = std::hypot(e.ttfRelative, ttf);
    e.regimeErrorRate = std::min(0.5, e.regimeErrorRate + regime);
}

}  // namespace

FlowNetworkErrors flowNetworkErrors(const fs::path& dir) {
    const fs::path file = dir / "training.json";
    std::ifstream in(file);
    if (!in) throw InputError(fmt::format("{}: cannot be read (a `trbc flow train` directory holds it)", file.string()));
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
        throw InputError(fmt::format("{}: not JSON ({})", file.string(), e.what()));
    }
    const auto cv = j.find("cross_validation");
    if (cv == j.end() || !cv->contains("pooled"))
        throw InputError(fmt::format("{}: no cross_validation (train the networks with --folds K)", file.string()));
    const nlohmann::json& p = (*cv)["pooled"];
    try {
        FlowNetworkErrors e;
        e.inclinationDeg = p.at("inclination_rmse_deg").get<double>();
        e.ttfRelative = p.at("ttf_relative_rmse").get<double>();
        e.regimeErrorRate = p.at("far_misclassified").get<double>() / p.at("far_cases").get<double>();
        e.criticalStressLog = std::log(j.at("boundary_factor").get<double>());
        if (!(e.inclinationDeg >= 0.0 && e.ttfRelative >= 0.0 && e.regimeErrorRate >= 0.0 && e.regimeErrorRate <= 0.5 &&
              e.criticalStressLog > 0.0))
            throw InputError(fmt::format("{}: cross_validation.pooled gives an angle error {}, a TTF error {}, a far "
                                         "misclassified share {} (must lie in [0, 0.5]) or a boundary factor <= 1",
                                         file.string(), e.inclinationDeg, e.ttfRelative, e.regimeErrorRate,
                                         std::exp(e.criticalStressLog)));
        if (j.contains("distillation")) addDistillationError(j.at("distillation"), file, e);
        return e;
    } catch (const nlohmann::json::exception& e) {
        throw InputError(fmt::format("{}: cross_validation.pooled: {}", file.string(), e.what()));
    }
}

std::vector<FlowDataSet> flowDataSets(const fs::path& dir, const FlowNetworkErrors& errors, double etaIn) {
    std::vector<ValidationData> inclination;
    const ValidationData *ttf = nullptr, *fischer2013 = nullptr, *abkarian = nullptr;
    const std::vector<ValidationData> all = readValidationDataSets(dir);
    for (const ValidationData& d : all) {
        if (d.set.observable == "inclination_deg") inclination.push_back(d);
        else if (d.set.observable == "ttf_4pi_f_over_rate") ttf = &d;
        else if (d.set.observable == "critical_stress_Pa")
            (d.set.source.starts_with("Abkarian") ? abkarian : fischer2013) = &d;
    }
    if (inclination.empty() || !ttf || !fischer2013 || !abkarian)
        throw InputError(fmt::format("{}: the shear-flow data (inclination, TTF and both critical-stress files) are incomplete",
                                     dir.string()));
    std::vector<FlowDataSet> sets;
    const std::size_t donors = inclination.front().set.yColumns.size();
    for (std::size_t k = 0; k < donors; ++k) {
        FlowDataSet s;
        s.name = fmt::format("fischer_2015_donor{}", k + 1);
        for (const ValidationData& d : inclination) {
            const auto [rate, angle] = columnPoints(d, k);
            if (!angle.empty()) {
                s.curves.push_back({d.set.etaOutMPaS, vector(rate), vector(angle)});
                s.files.push_back(d.set.file);
            }
        }
        if (!s.curves.empty()) sets.push_back(std::move(s));
    }
    for (FlowDataSet& s : sets) s.modelErrorSd = errors.inclinationDeg;

    FlowDataSet t;
    t.name = "fischer_ttf_donors12";
    t.observable = FlowObservable::Ttf;
    const auto [rate, value] = columnPoints(*ttf, 0);
    t.curves.push_back({ttf->set.etaOutMPaS, vector(rate), vector(value)});
    t.modelErrorSd = errors.ttfRelative;
    t.files = {ttf->set.file};
    sets.push_back(std::move(t));

    sets.push_back(stressSet(*fischer2013, "fischer_2013_critical_stress"));
    sets.push_back(stressSet(*abkarian, "abkarian_2007_critical_stress"));
    const DesignAxis& etam = kShearCampaignAxes[4];
    for (FlowDataSet& s : sets) {
        s.etaInMPaS = etaIn;
        s.etamRange = {etam.lo, etam.hi};
        if (s.observable == FlowObservable::CriticalStress) s.modelErrorSd = errors.criticalStressLog;
        else s.regimeErrorRate = errors.regimeErrorRate;
    }
    return sets;
}

std::string dataSetSummary(const RbcDataSet& d) {
    switch (d.experiment) {
        case RbcExperiment::Equilibrium: return fmt::format("{:<32} equilibrium: resting D, hmin, hmax", d.name);
        case RbcExperiment::Stretching:
            return fmt::format("{:<32} stretching: D0, D1 at {} bead forces up to {:g} pN", d.name, d.force.size(),
                               d.force.size() ? d.force.maxCoeff() : 0.0);
        case RbcExperiment::Relaxation: return fmt::format("{:<32} relaxation: L/W at {} times", d.name, d.time.size());
        case RbcExperiment::Flow: {
            std::vector<std::string> curves;
            long points = 0;
            for (const FlowCurve& c : d.flow->curves) curves.push_back(fmt::format("{:g}", c.etaOutMPaS)), points += c.value.size();
            return fmt::format("{:<32} flow: {}, {} points at eta_out {} mPa s", d.name, flowObservableName(d.flow->observable), points,
                               fmt::join(curves, ", "));
        }
    }
    return d.name;
}

DataSetChoice DataSetChoice::parse(const std::string& spec) {
    const std::vector<std::string> items = splitList(spec);
    DataSetChoice c;
    if (items.size() == 1 && items[0] == "paper") return c;
    if (items.size() == 1 && items[0] == "all") return c.kind = Kind::All, c;
    if (items.size() == 1 && items[0] == "list") return c.kind = Kind::List, c;
    c.kind = Kind::Names;
    for (const std::string& name : items) {
        if (name.empty()) throw InputError(fmt::format("--datasets '{}': an empty name; give paper, all, list or names separated by commas", spec));
        if (name == "paper" || name == "all" || name == "list")
            throw InputError(fmt::format("--datasets '{}': the keyword '{}' stands alone, not in a list of names", spec, name));
        if (std::find(c.names.begin(), c.names.end(), name) != c.names.end())
            throw InputError(fmt::format("--datasets: '{}' is given twice", name));
        c.names.push_back(name);
    }
    return c;
}

bool DataSetChoice::mayChooseFlow(const std::vector<RbcDataSet>& singleCell) const {
    if (kind != Kind::Names) return kind != Kind::Paper;
    return std::any_of(names.begin(), names.end(), [&](const std::string& name) {
        return std::none_of(singleCell.begin(), singleCell.end(), [&](const RbcDataSet& d) { return d.name == name; });
    });
}

std::vector<RbcDataSet> selectDataSets(const DataSetChoice& choice, const std::vector<RbcDataSet>& singleCell,
                                       const std::vector<RbcDataSet>& flow) {
    if (choice.kind == DataSetChoice::Kind::Paper) return singleCell;
    std::vector<RbcDataSet> all = singleCell;
    all.insert(all.end(), flow.begin(), flow.end());
    if (choice.kind != DataSetChoice::Kind::Names) return all;
    std::vector<RbcDataSet> chosen;
    for (const std::string& name : choice.names) {
        const auto it = std::find_if(all.begin(), all.end(), [&](const RbcDataSet& d) { return d.name == name; });
        if (it == all.end()) {
            std::vector<std::string> names;
            for (const RbcDataSet& d : all) names.push_back(d.name);
            throw InputError(fmt::format("--datasets: '{}' is not a data set; give paper, all, list or names from: {}", name,
                                         fmt::join(names, ", ")));
        }
        chosen.push_back(*it);
    }
    return chosen;
}

}  // namespace trbc
