#include "analysis/validation_data.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <iterator>
#include <regex>

#include "core/csv.hpp"
#include "core/error.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

constexpr const char* kAngleDir = "shear_flow/inclination_angle";
const std::vector<std::string> kDonorColumns = {"angle1", "angle2", "angle3", "angle4", "angle5", "angle6", "angle7"};

ValidationDataSet inclinationSet(const fs::path& file, double etaOut) {
    ValidationDataSet s;
    s.observable = "inclination_deg", s.x = "shear_rate_per_s", s.source = "Fischer & Korzeniewski 2015";
    s.file = file, s.xColumn = "shear_rate", s.yColumns = kDonorColumns, s.etaOutMPaS = etaOut;
    return s;
}

/// The sets of one file each, in the order of validationDataSets.
std::vector<ValidationDataSet> fixedSets(const fs::path& dataDir) {
    const fs::path shear = dataDir / "shear_flow", tube = dataDir / "microtube";
    auto set = [](const char* observable, const char* x, const char* source, fs::path file, const char* xColumn,
                  std::vector<std::string> yColumns) {
        ValidationDataSet s;
        s.observable = observable, s.x = x, s.source = source, s.file = std::move(file), s.xColumn = xColumn;
        s.yColumns = std::move(yColumns);
        return s;
    };
    std::vector<ValidationDataSet> sets;
    // The donors' TTF is f / rate at 28.9 mPa s; trbc reports 4 pi f / rate.
    sets.push_back(set("ttf_4pi_f_over_rate", "shear_rate_per_s", "Fischer, donors 1-2", shear / "ttf" / "data_donors12.csv", "shear_rate",
                       {"TTF"}));
    sets.back().yScale = 4.0 * M_PI, sets.back().etaOutMPaS = 28.9;
    sets.push_back(set("critical_stress_Pa", "eta_out_mPa_s", "Fischer & Korzeniewski 2013",
                       shear / "tt_tb_critical_stress" / "Fischer2013.csv", "eta", {"tau"}));
    sets.push_back(set("critical_stress_Pa", "eta_out_mPa_s", "Abkarian et al. 2007", shear / "tt_tb_critical_stress" / "Abkarian2007.csv",
                       "eta", {"tau"}));
    sets.push_back(set("velocity_cm_per_s", "pg_mmHg_per_mm", "Tomaiuolo et al. 2009 (6.6 µm tube)", tube / "Tomaiuolo2009_pg_v_6.6um.csv",
                       "pg", {"v"}));
    sets.push_back(set("length_um", "velocity_cm_per_s", "Tomaiuolo et al. 2009 (6.6 µm tube)", tube / "Tomaiuolo2009_v_l_6.6um.csv", "v",
                       {"l", "l_high", "l_low"}));
    // A tube of 6.7 µm against the validation's 6.6 µm: drawn beside the verdicts, not judged; mm/s.
    sets.push_back(set("length_um", "velocity_cm_per_s", "Hochmuth et al. 1970 (6.7 µm tube)", tube / "Hochmut1970_v_l_6.7um.csv", "v", {"l"}));
    sets.back().xScale = 0.1, sets.back().judged = false;
    return sets;
}

}  // namespace

ExperimentalPoints readExperimentalPoints(const fs::path& file, const std::string& xColumn, const std::vector<std::string>& yColumns,
                                          bool keepBlanks) {
    std::vector<std::string> columns = {xColumn};
    columns.insert(columns.end(), yColumns.begin(), yColumns.end());
    const NumericTable t = readNumericTable(file, columns, yColumns);
    if (t.values.rows() == 0) throw InputError(fmt::format("{}: no data rows", file.string()));
    ExperimentalPoints d;
    const Eigen::VectorXd x = t.column(xColumn);
    d.x.assign(x.data(), x.data() + x.size());
    std::vector<Eigen::VectorXd> ys;
    for (const std::string& c : yColumns) ys.push_back(t.column(c));
    for (Eigen::Index r = 0; r < x.size(); ++r) {
        std::vector<double> row;
        for (const Eigen::VectorXd& y : ys) row.push_back(y[r]);
        d.y.push_back(std::move(row));
    }
    return keepBlanks ? d : withoutBlanks(d);
}

ExperimentalPoints withoutBlanks(const ExperimentalPoints& d) {
    ExperimentalPoints out{d.x, {}};
    for (const std::vector<double>& row : d.y) {
        std::vector<double> ys;
        std::copy_if(row.begin(), row.end(), std::back_inserter(ys), [](double v) { return !std::isnan(v); });
        out.y.push_back(std::move(ys));
    }
    return out;
}

std::vector<ValidationDataSet> validationDataSets(const fs::path& dataDir) {
    if (!fs::is_directory(dataDir / "shear_flow") && !fs::is_directory(dataDir / "microtube"))
        throw InputError(fmt::format("{} is not a validation data folder: it has neither shear_flow/ nor microtube/", dataDir.string()));
    std::vector<ValidationDataSet> sets;
    std::error_code ec;
    static const std::regex name(R"(Fisher2015_eta_([0-9]+(\.[0-9]+)?)_mPa_s\.csv)");
    for (const fs::directory_entry& e : fs::directory_iterator(dataDir / kAngleDir, ec)) {
        std::smatch m;
        const std::string file = e.path().filename().string();
        if (std::regex_match(file, m, name)) sets.push_back(inclinationSet(e.path(), std::stod(m[1].str())));
    }
    std::sort(sets.begin(), sets.end(), [](const auto& a, const auto& b) { return a.etaOutMPaS < b.etaOutMPaS; });
    for (ValidationDataSet& s : fixedSets(dataDir)) sets.push_back(std::move(s));
    return sets;
}

ExperimentalPoints readValidationData(const ValidationDataSet& s, bool keepBlanks) {
    ExperimentalPoints d = readExperimentalPoints(s.file, s.xColumn, s.yColumns, keepBlanks);
    for (double& x : d.x) x *= s.xScale;
    for (std::vector<double>& row : d.y)
        for (double& y : row) y *= s.yScale;
    return d;
}

std::vector<ValidationData> readValidationDataSets(const fs::path& dataDir) {
    std::vector<ValidationData> out;
    for (ValidationDataSet& s : validationDataSets(dataDir)) {
        ExperimentalPoints points = readValidationData(s, true);
        out.push_back({std::move(s), std::move(points)});
    }
    return out;
}

nlohmann::json validationDataJson(const std::vector<ValidationData>& data) {
    nlohmann::json out = nlohmann::json::array();
    const auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
    for (const auto& [s, d] : data) {
        nlohmann::json y = nlohmann::json::array();
        for (const std::vector<double>& row : d.y) {
            nlohmann::json r = nlohmann::json::array();
            for (double v : row) r.push_back(number(v));
            y.push_back(std::move(r));
        }
        out.push_back({{"observable", s.observable}, {"x_name", s.x}, {"source", s.source}, {"file", s.file.lexically_normal().string()},
                       {"eta_out_mPa_s", number(s.etaOutMPaS)}, {"judged", s.judged}, {"y_columns", s.yColumns}, {"x", d.x},
                       {"y", std::move(y)}});
    }
    return out;
}

}  // namespace trbc
