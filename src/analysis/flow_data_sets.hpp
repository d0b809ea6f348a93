#pragma once
// The shear-flow validation data as data sets of the red-cell model (inference/flow_likelihood.hpp),
// with the flow networks' errors from their cross-validation.
//
// Why one data set per donor of the inclination sets: Fischer & Korzeniewski measured the same
// seven donors at the four viscosities (a donor's curves lie above or below the others' at every
// viscosity: donor 4 is the highest at all four), the donors differ by 0.8-1.4 deg at a rate while a
// donor's own curve scatters by 0.1-0.5 deg about a smooth one, and the hierarchical model has a
// population for exactly this: each donor's cell is drawn from it and seen through its four
// curves. One data set per viscosity would instead fit one cell to seven donors and read their
// spread as noise.
#include <filesystem>
#include <string>
#include <vector>

#include "inference/flow_likelihood.hpp"
#include "inference/rbc_problem.hpp"

namespace trbc {

/// The networks' errors as the flow likelihood uses them.
struct FlowNetworkErrors {
    double inclinationDeg = 0.0;     ///< pooled cross-validated RMSE of the angle
    double ttfRelative = 0.0;        ///< pooled cross-validated relative RMSE of 4 pi f / rate
    double criticalStressLog = 0.0;  ///< one bracket step of the regime boundary, log(boundary factor)
    double regimeErrorRate = 0.0;    ///< share misclassified away from the boundary
};

/// From a flow-network directory's training.json (`trbc flow train --folds K`): its pooled
/// cross-validation. InputError naming the file when it has none (a training without --folds).
/// For networks distilled from an ensemble (`trbc flow distill`, a `distillation` block) the
/// student's error against the ensemble adds: in quadrature to the angle and TTF errors, and its
/// regime disagreement to the misclassified share (an upper bound: the two can cancel).
FlowNetworkErrors flowNetworkErrors(const std::filesystem::path& surrogateDir);

/// The flow data sets of the validation data directory (shear_flow/): fischer_2015_donor1..7 (each
/// donor's inclination curves, the viscosities where it has points), fischer_ttf_donors12 (4 pi f /
/// rate at 28.9 mPa s), fischer_2013_critical_stress and abkarian_2007_critical_stress (one curve
/// per viscosity), in that order; the experiments' cytosol at etaInMPaS.
std::vector<FlowDataSet> flowDataSets(const std::filesystem::path& validationDataDir, const FlowNetworkErrors& errors,
                                      double etaInMPaS = 10.0);

/// One line describing a data set for `trbc infer --datasets list`: its name, experiment and points.
std::string dataSetSummary(const RbcDataSet& d);

/// A --datasets value, parsed once: "paper" (the single-cell sets: the paper's seven, or those of the
/// data directory's datasets.json), "all" (those and the flow sets), "list" (print them all), or a
/// comma-separated list of names from both. Keywords are whole values; a name list keeps its order.
struct DataSetChoice {
    enum class Kind { Paper, All, List, Names };
    Kind kind = Kind::Paper;
    std::vector<std::string> names;  ///< Kind::Names only.

    /// InputError for an empty value, an empty item, a keyword inside a list or a name given twice.
    static DataSetChoice parse(const std::string& spec);
    /// Whether it may choose a flow set (all, list, or a name that is not a single-cell set's), so
    /// that the flow data and networks are read only then.
    bool mayChooseFlow(const std::vector<RbcDataSet>& singleCell) const;
};

/// The data sets of `choice` (List: every set), in the order of the sets or of the names given.
/// InputError naming an unknown name and the valid ones.
std::vector<RbcDataSet> selectDataSets(const DataSetChoice& choice, const std::vector<RbcDataSet>& singleCell,
                                       const std::vector<RbcDataSet>& flow);

}  // namespace trbc
