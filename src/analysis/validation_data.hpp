#pragma once
// The experimental data sets of the flow validations: which file holds which observable, in which
// columns and units. The verdicts (ValidationEvidence, validation.hpp) and the plots (Python
// `trbc.validation_data`) read them through this one list, so that no script names a data file.
#include <cmath>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace trbc {

/// Experimental table of the validation data: rows of (x, y...) as read from a CSV.
struct ExperimentalPoints {
    std::vector<double> x;
    /// per row the y columns in their order; a blank is skipped, or NaN when read with keepBlanks
    std::vector<std::vector<double>> y;
};
/// Reads columns: x = `xColumn`, y = every other listed column (blanks allowed: skipped, or NaN
/// with `keepBlanks`). InputError naming the file, line and column for a missing column, an empty
/// x or a field that is not a number (core/csv.hpp's readNumericTable).
ExperimentalPoints readExperimentalPoints(const std::filesystem::path& file, const std::string& xColumn,
                                          const std::vector<std::string>& yColumns, bool keepBlanks = false);
/// The points with the blanks (NaN) of every row dropped.
ExperimentalPoints withoutBlanks(const ExperimentalPoints& d);

/// One experimental data set of the flow validations.
struct ValidationDataSet {
    std::string observable;  ///< inclination_deg, ttf_4pi_f_over_rate, critical_stress_Pa, velocity_cm_per_s, length_um
    std::string x;           ///< the abscissa: shear_rate_per_s, eta_out_mPa_s, pg_mmHg_per_mm or velocity_cm_per_s
    std::string source;      ///< who measured it (and where, for the tubes)
    std::filesystem::path file;
    std::string xColumn;
    std::vector<std::string> yColumns;
    double xScale = 1.0, yScale = 1.0;  ///< from the file's units to trbc's (TTF: f/rate to 4 pi f/rate; mm/s to cm/s)
    double etaOutMPaS = NAN;            ///< the outer viscosity of a set measured at one, NaN otherwise
    bool judged = true;                 ///< compared with by the verdicts; false: drawn beside them only
};

/// Every set of `dataDir` (the validation data: shear_flow/, microtube/): the inclination sets
/// found there in increasing viscosity (one file per viscosity, Fisher2015_eta_<eta>_mPa_s.csv), then
/// the TTF, the critical stresses, the tube's velocity and lengths. A listed file that is absent
/// fails when it is read; a folder with neither subfolder is an InputError naming it.
std::vector<ValidationDataSet> validationDataSets(const std::filesystem::path& dataDir);

/// The set's points in trbc's units (x times xScale, y times yScale).
ExperimentalPoints readValidationData(const ValidationDataSet& s, bool keepBlanks = false);

/// A set with its points in trbc's units, a blank read as NaN.
struct ValidationData {
    ValidationDataSet set;
    ExperimentalPoints points;
};
/// Every set of validationDataSets(dataDir) with its points, each file read once.
std::vector<ValidationData> readValidationDataSets(const std::filesystem::path& dataDir);

/// The sets with their points, as `trbc validate` records them beside its verdicts
/// (experimental_data.json) and trbc.validation_data returns them: per set observable, x_name,
/// source, file, eta_out_mPa_s (null unless measured at one), judged, y_columns, x and y (rows of
/// the y columns; a blank is null).
nlohmann::json validationDataJson(const std::vector<ValidationData>& data);

}  // namespace trbc
