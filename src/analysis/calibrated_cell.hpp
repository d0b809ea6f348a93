#pragma once
// "The calibrated cell" of a theta_new posterior: one definition for every command that takes a
// cell from a posterior (flow shear/tube/ramp --posterior, validate with [cell] source = "posterior").
#include <filesystem>
#include <string>

#include "experiments/parameters.hpp"

namespace trbc {

struct CalibratedCell {
    CellParameters cell;
    double kbJ = 0.0;
    std::string estimator;         ///< "Rao-Blackwellised means (posterior_stats.csv)" or "sample means"
    std::filesystem::path source;  ///< the file the means come from
};

/// The means of (v, mu, kb, b2, etam) of a theta_new posterior given as DIR/phase3/theta_new of
/// `trbc infer` (or its samples.csv). When the inference's DIR/posterior_stats.csv holds theta_new
/// rows, its Rao-Blackwellised means are used: they are the values of the calibration's tables and
/// have the smaller Monte Carlo error. Otherwise (a samples file alone) the sample means.
/// InputError naming `option` when neither can be read.
CalibratedCell calibratedCell(const std::filesystem::path& posterior, const char* option = "--posterior");

/// The posterior_stats.csv that belongs to a theta_new posterior path, or "" when there is none.
std::filesystem::path posteriorStatsOf(const std::filesystem::path& posterior);

}  // namespace trbc
