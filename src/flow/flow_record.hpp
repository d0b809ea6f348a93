#pragma once
// The records of the flow protocols (flow/shear_case.hpp, flow/tube_case.hpp), defined once for the
// CLI (`trbc flow`), the validation (which reads them back) and the Python package: flow.json's
// parameters, observables, analysis and diagnostics in physical units, a ramp's ramp.json, the
// plateau rule of the tube, and the writers of a case's files (frames.csv, steps.csv, the shapes as
// VTK).
//
// flow.json: {"status": "ok" | "failed", "reason" (when failed), "parameters", "provenance",
// "diagnostics", "observables", "analysis"}. Shear observables: regime ("tank-treading",
// "tumbling", "intermittent"), inclination_deg, swing_amplitude_deg, ttf_4pi_f_over_shear_rate
// (null unless tank-treading). Tube observables: velocity_cm_per_s, length_um, width_um,
// width_z_um, velocity_over_centre_line, velocity_over_mean_poiseuille.
#include <nlohmann/json.hpp>

#include <cmath>
#include <string>

#include "experiments/parameters.hpp"
#include "flow/shear_case.hpp"
#include "flow/tube_case.hpp"

namespace trbc {

/// The cell in physical units: v, mu_uN_per_m, FvK, kb_J, b2, etam_Pa_s_um.
nlohmann::json flowCellJson(const CellParameters& p);

/// The tube's steady state: the length (third vs fourth quarter of the frames) and the velocity
/// (seventh vs eighth eighth) each change by less than 1 %.
bool tubePlateauReached(const TubeObservables& ob);

/// The whole record of a shear case (without the time series, which frames.csv holds); `cellSource`
/// says where the cell came from, `provenance` is stored as given.
nlohmann::json shearRecord(const ShearCaseResult& res, const ShearCaseOptions& c, const std::string& cellSource,
                           nlohmann::json provenance);
/// ramp.json of a shear ramp run with options `r`: {"parameters", "provenance", "stages" (per stage:
/// rate, stress, direction, status, turns, stopped_when_steady, wall_s, the thermal step taken when
/// r.base.temperatureK > 0, the reason when failed, the observables when completed), "summary"
/// (completed, the up and down brackets or null, hysteresis when both exist and differ, wall_s)}.
nlohmann::json rampRecord(const ShearRampResult& res, const ShearRampOptions& r, const std::string& cellSource,
                          nlohmann::json provenance);
/// The same for a tube case.
nlohmann::json tubeRecord(const TubeCaseResult& res, const TubeCaseOptions& c, const std::string& cellSource,
                          nlohmann::json provenance);

/// What the validation reads back from a record of shearRecord or tubeRecord. A field the record
/// lacks (a failed case has no observables) or holds as null is NaN, "" or "none"; a status other
/// than the string "ok" is a failed case, and a record that is not a JSON object one whose reason
/// says so.
struct FlowRecordView {
    std::string status = "failed", reason;
    std::string regime;                   ///< shear: "tank-treading", "tumbling", "intermittent"
    double inclinationDeg = NAN, swingDeg = NAN, ttf = NAN;           ///< shear; ttf = 4 pi f / rate
    double velocityCmPerS = NAN, lengthUm = NAN, widthUm = NAN;       ///< tube
    bool plateauReached = false;          ///< tube: tubePlateauReached
    std::string settled = "none";         ///< tube: "true", "false", or "none" without a settling stage
    double lengthChangeMainVsSettled = NAN, cellFrameMotionRatio = NAN;  ///< tube
    double areaDriftMax = NAN, volumeDriftMax = NAN;

    bool ok() const { return status == "ok"; }
    /// The observable of the schema's key (inclination_deg, swing_amplitude_deg,
    /// ttf_4pi_f_over_shear_rate, velocity_cm_per_s, length_um, width_um); std::invalid_argument
    /// for another key.
    double observable(const std::string& key) const;
};
/// InputError naming `source` (the record's file) and the field for a damaged record: a field of
/// another type than the schema's (an observable that is not a number, a reason that is not a
/// string, a section that is not an object), or status "ok" without observables.
FlowRecordView readFlowRecord(const nlohmann::json& record, const std::string& source = "flow record");

/// j["observables"] and j["analysis"] of a finished shear run (also a ramp's stage).
void addShearObservables(nlohmann::json& j, const ShearObservables& obs);

/// Shapes (VTK, every vtkEvery-th frame, and shapes.pvd), steps.csv, frames.csv (per frame: time,
/// strain, inclination, unwrapped orientation, drift, centroid) and flow.json (`record`) in dir.
void writeShearOutputs(const std::string& dir, const ShearCaseResult& res, int vtkEvery, const nlohmann::json& record);
/// Shapes, steps.csv and frames.csv (centroid, extents, clearance, drift) of one tube stage in dir.
void writeTubeStage(const std::string& dir, const TubeCaseResult& res, const TubeStageResult& stage, int vtkEvery);

}  // namespace trbc
