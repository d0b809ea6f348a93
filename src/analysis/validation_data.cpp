#include "analysis/validation_data.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <regex>
#include <sstream>

#include "core/error.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

std::string trim(const std::string& s) {
    const auto b = s.find_first_not_of(" \t\r"), e = s.find_last_not_of(" \t\r");
    return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

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
    std::ifstream in(file);
    if (!in) throw InputError(fmt::format("cannot read experimental data {}", file.string()));
    std::string line;
    std::vector<std::string> header;
    long lineNo = 0;
    ExperimentalPoints d;
    std::vector<int> yIdx;
    int xIdx = -1;
    while (std::getline(in, line)) {
        ++lineNo;
        if (trim(line).empty()) continue;
        std::vector<std::string> fields;
        std::stringstream ss(line);
        std::string f;
        while (std::getline(ss, f, ',')) fields.push_back(trim(f));
        if (!line.empty() && line.back() == ',') fields.push_back("");
        if (header.empty()) {
            header = fields;
            auto idx = [&](const std::string& name) {
                const auto it = std::find(header.begin(), header.end(), name);
                if (it == header.end()) throw InputError(fmt::format("{}:1: missing column '{}'", file.string(), name));
                return static_cast<int>(it - header.begin());
            };
            xIdx = idx(xColumn);
            for (const std::string& y : yColumns) yIdx.push_back(idx(y));
            continue;
        }
        auto number = [&](int i, bool required) -> std::optional<double> {
            const std::string s = i < static_cast<int>(fields.size()) ? fields[i] : "";
            if (s.empty()) {
                if (required) throw InputError(fmt::format("{}:{}: column '{}' is empty", file.string(), lineNo, header[i]));
                return std::nullopt;
            }
            try {
                std::size_t n = 0;
                const double v = std::stod(s, &n);
                if (n == s.size() && std::isfinite(v)) return v;
            } catch (const std::exception&) {
            }
            throw InputError(fmt::format("{}:{}: column '{}' = '{}' is not a number", file.string(), lineNo, header[i], s));
        };
        d.x.push_back(*number(xIdx, true));
        std::vector<double> ys;
        for (int i : yIdx) {
            const std::optional<double> v = number(i, false);
            if (v || keepBlanks) ys.push_back(v ? *v : NAN);
        }
        d.y.push_back(ys);
    }
    if (d.x.empty()) throw InputError(fmt::format("{}: no data rows", file.string()));
    return d;
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

nlohmann::json validationDataJson(const std::vector<ValidationDataSet>& sets) {
    nlohmann::json out = nlohmann::json::array();
    const auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
    for (const ValidationDataSet& s : sets) {
        const ExperimentalPoints d = readValidationData(s, true);
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
