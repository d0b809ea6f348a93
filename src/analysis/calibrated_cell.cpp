#include "analysis/calibrated_cell.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <fmt/format.h>

#include "analysis/validation_draws.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"

namespace trbc {

namespace fs = std::filesystem;

namespace {

CalibratedCell fromMeans(const std::array<double, 5>& m, std::string estimator, fs::path source) {
    CalibratedCell c;
    c.cell.v = m[0];
    c.cell.mu = m[1];
    c.kbJ = m[2];
    c.cell.FvK = CellParameters::fvkFromKb(m[1], m[2]);
    c.cell.b2 = m[3];
    c.cell.etam = m[4];
    c.estimator = std::move(estimator);
    c.source = std::move(source);
    return c;
}

double number(const std::string& text, const fs::path& file) {
    try {
        std::size_t used = 0;
        const double x = std::stod(text, &used);
        if (used == text.size()) return x;
    } catch (const std::exception&) {
    }
    throw InputError(fmt::format("{}: '{}' in the column 'mean' is not a number", file.string(), text));
}

}  // namespace

fs::path posteriorStatsOf(const fs::path& posterior) {
    fs::path dir = fs::absolute(posterior).lexically_normal();
    if (dir.filename().empty()) dir = dir.parent_path();  // "DIR/" normalises to a trailing separator
    if (!fs::is_directory(dir)) dir = dir.parent_path();
    if (dir.filename() != "theta_new" || dir.parent_path().filename() != "phase3") return {};
    const fs::path stats = dir.parent_path().parent_path() / "posterior_stats.csv";
    return fs::exists(stats) ? stats : fs::path{};
}

CalibratedCell calibratedCell(const fs::path& posterior, const char* option) {
    // The samples are read in every case, so that a wrong path fails the same way with and without the statistics.
    const NumericTable t = readThetaNewSamples(posterior, option);
    const fs::path stats = posteriorStatsOf(posterior);
    if (!stats.empty()) {
        const auto rows = readCsvRecords(stats);
        if (!rows.empty()) {
            const int cPost = columnOf(rows[0], "posterior"), cPar = columnOf(rows[0], "parameter"), cMean = columnOf(rows[0], "mean");
            std::array<double, 5> m;
            m.fill(std::nan(""));
            if (cPost >= 0 && cPar >= 0 && cMean >= 0)
                for (std::size_t r = 1; r < rows.size(); ++r) {
                    const auto& row = rows[r];
                    if (static_cast<int>(row.size()) <= std::max({cPost, cPar, cMean}) || row[cPost] != "theta_new") continue;
                    for (std::size_t k = 0; k < kThetaNewColumns.size(); ++k)
                        if (row[cPar] == kThetaNewColumns[k]) m[k] = number(row[cMean], stats);
                }
            if (std::all_of(m.begin(), m.end(), [](double x) { return std::isfinite(x); }))
                return fromMeans(m, "Rao-Blackwellised means (posterior_stats.csv)", stats);
        }
    }
    std::array<double, 5> m;
    for (std::size_t k = 0; k < kThetaNewColumns.size(); ++k) m[k] = t.column(kThetaNewColumns[k]).mean();
    return fromMeans(m, "sample means", t.path);
}

}  // namespace trbc
