#include "flow/flow_record.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <stdexcept>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/output_dir.hpp"
#include "experiments/simulation_report.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"

namespace trbc {

nlohmann::json flowCellJson(const CellParameters& p) {
    return {{"v", p.v}, {"mu_uN_per_m", p.mu}, {"FvK", p.FvK}, {"kb_J", p.kbJoule()}, {"b2", p.b2},
            {"etam_Pa_s_um", p.etam}};
}

bool tubePlateauReached(const TubeObservables& ob) { return ob.lengthChange < 0.01 && ob.velocityChange < 0.01; }

namespace {

constexpr double kPi = std::numbers::pi;

nlohmann::json nullable(bool ok, double v) { return ok ? nlohmann::json(v) : nlohmann::json(nullptr); }

void writeText(const std::string& path, const std::string& text) { writeFileAtomically(path, text); }

nlohmann::json checkpointJson(const CellFlowResult& r, double timeUnit) {
    return {{"resumes", r.resumes}, {"resumed_at_s", r.resumes > 0 ? nlohmann::json(r.resumedAt * timeUnit) : nlohmann::json(nullptr)}};
}

/// The diagnostics of the time stepping that do not depend on the flow's time unit.
nlohmann::json stepDiagnostics(const FlowScales& scales, const CellFlowResult& r, const ShearCell& cell) {
    const long gm = r.gmresIterations;
    const double L = scales.length, T = scales.time;
    return {
        {"steps", r.steps},
        {"rejected_steps", r.rejectedSteps},
        {"failed_solves", r.failedSolves},
        {"gmres_iterations_total", gm},
        {"gmres_iterations_mean",
         r.steps > 0 ? static_cast<double>(gm) / (r.steps + r.rejectedSteps + r.failedSolves) : 0.0},
        {"gmres_iterations_max", r.maxGmresIterations},
        {"dt_min_s", r.dtSmallest * T},
        {"dt_max_s", r.dtLargest * T},
        {"area_drift_max", r.maxAreaDrift},
        {"volume_drift_max", r.maxVolumeDrift},
        {"area_projection_per_step_max", r.maxAreaCorrection},
        {"volume_projection_per_step_max", r.maxVolumeCorrection},
        {"area_projection_sum", r.sumAreaCorrection},
        {"volume_flux_correction_max_um_per_s", r.maxFluxCorrection * L / T},
        {"volume_projection_sum", r.sumVolumeCorrection},
        {"tension_final_pN_per_um", r.stepLog.empty() ? 0.0 : r.stepLog.back().tension * scales.force() / L},
        {"area_drift_final", r.areaDrift.empty() ? 0.0 : r.areaDrift.back()},
        {"volume_drift_final", r.volumeDrift.empty() ? 0.0 : r.volumeDrift.back()},
        {"frames", r.times.size()},
        {"flow_wall_s", r.wallSeconds},
        {"equilibrium", {{"converged", cell.equilibrium.converged}, {"iterations", cell.equilibrium.iterations},
                         {"wall_s", cell.equilibrium.wallSeconds}}},
        {"sfs", sfsJson(cell.sfs)}};
}

nlohmann::json stepControlJson(const CellFlowOptions& opt, double fixedDt, const char* fixedDtName) {
    return {{"scheme", "linearly implicit variable-step BDF2, error vs quadratic predictor"},
            {"local_error_tolerance_R_A", opt.adaptive ? nlohmann::json(opt.errorTolerance) : nlohmann::json(nullptr)},
            {fixedDtName, opt.adaptive ? nlohmann::json(nullptr) : nlohmann::json(fixedDt)},
            {"gmres_tolerance", effectiveGmresTolerance(opt)},
            {"far_sum", opt.quadrature.singlePrecisionFar ? "single precision" : "double precision"}};
}

/// reference_sfs.vtk, initial.vtk, shape_NNNNN.vtk (every vtkEvery-th frame) + shapes.pvd, steps.csv.
void writeShapesAndSteps(const std::string& dir, const FlowScales& scales, const ShearCell& cell, const Vertices& initial,
                         const CellFlowResult& r, int vtkEvery) {
    const double L = scales.length, T = scales.time;
    writeMesh(dir + "/reference_sfs.vtk", Mesh{cell.reference, cell.faces});
    writeMesh(dir + "/initial.vtk", Mesh{initial, cell.faces});
    // Shapes over time (legacy VTK, one file per saved frame) and a ParaView collection.
    std::string pvd = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
    for (std::size_t k = 0; k < r.frames.size(); k += static_cast<std::size_t>(vtkEvery)) {
        const std::string name = fmt::format("shape_{:05d}.vtk", k);
        writeMesh(dir + "/" + name, Mesh{r.frames[k] * L, cell.faces});
        pvd += fmt::format("<DataSet timestep=\"{:.9g}\" file=\"{}\"/>\n", r.times[k] * T, name);
    }
    pvd += "</Collection>\n</VTKFile>\n";
    writeText(dir + "/shapes.pvd", pvd);
    const double tensionUnit = scales.force() / L;
    std::string steps = csvProvenance() + "t_s,dt_s,local_error_um,gmres_iterations,tension_pN_per_um,area_drift,volume_drift,"
                        "area_projection,volume_projection\n";
    for (const auto& s : r.stepLog)
        steps += fmt::format("{:.9g},{:.6e},{:.6e},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}\n", s.t * T, s.dt * T, s.error * L,
                             s.gmresIterations, s.tension * tensionUnit, s.areaDrift, s.volumeDrift, s.areaCorrection,
                             s.volumeCorrection);
    writeText(dir + "/steps.csv", steps);
}

nlohmann::json shearParametersJson(const ShearCaseResult& res, const ShearCaseOptions& c, const std::string& cellSource) {
    const FlowConditions& fc = res.conditions;
    const FlowGroups& g = res.groups;
    return {{"eta_out_mPa_s", fc.etaOut},
            {"eta_in_mPa_s", fc.etaIn},
            {"shear_rate_per_s", fc.shearRate},
            {"shear_stress_Pa", shearStressPa(fc.etaOut, fc.shearRate)},
            {"cell", flowCellJson(res.cell)},
            {"cell_source", cellSource},
            {"area_volume", "exact constraints: area multiplier (membrane tension) in the coupled system, "
                            "projection onto A0, V0 after each step"},
            {"A0_um2", fc.A0},
            {"V0_um3", fc.V0},
            {"rotations", c.rotations},
            {"tilt_deg", c.tiltDeg},
            {"start", c.randomStart ? "random" : "in-plane"},
            {"kick_temperature_K", c.randomStart ? nlohmann::json(c.kickTemperatureK) : nlohmann::json(nullptr)},
            {"temperature_K", c.temperatureK},
            {"thermal_step_times_rate", c.temperatureK > 0.0 ? nlohmann::json(c.thermalStep) : nlohmann::json(nullptr)},
            {"seed", c.seed},
            {"stop_when_steady", c.stopWhenSteady},
            {"t_end_s", res.tEndSeconds},
            {"dimensionless", {{"capillary_number", g.capillary},
                               {"viscosity_ratio", g.viscosityRatio},
                               {"membrane_viscosity_ratio_E", g.membraneViscosity},
                               {"FvK", g.FvK}}}};
}

nlohmann::json shearDiagnosticsJson(const ShearCaseResult& res, const ShearCaseOptions& c) {
    const CellFlowResult& r = res.flow;
    nlohmann::json diag = stepDiagnostics(res.scales, r, res.prepared);
    diag["dt_min_times_rate"] = r.dtSmallest;
    diag["dt_max_times_rate"] = r.dtLargest;
    diag["stopped_when_steady"] = r.stoppedEarly;
    diag["rotations_run"] = r.tReached / (4.0 * kPi);
    if (res.integrator.thermal.kT > 0.0)
        diag["thermal"] = {{"kT_internal", res.integrator.thermal.kT},
                           {"step_times_rate", thermalStepOnFrames(res.integrator)},
                           {"lanczos_iterations_per_step", r.steps ? double(r.sqrtIterations) / r.steps : 0.0},
                           {"lanczos_iterations_max", r.maxSqrtIterations},
                           {"mobility_gmres_iterations_per_step", r.steps ? double(r.mobilityIterations) / r.steps : 0.0}};
    diag["step_control"] = stepControlJson(res.integrator, c.step.dt, "fixed_dt_times_rate");
    diag["setup_wall_s"] = res.setupWallSeconds;
    diag["wall_s_per_rotation"] = r.tReached > 0 ? r.wallSeconds / (r.tReached / (4.0 * kPi)) : 0.0;
    diag["checkpoint"] = checkpointJson(r, res.scales.time);
    diag["wall_s"] = res.wallSeconds;
    if (!res.completed) diag["t_reached_s"] = r.tReached * res.scales.time;
    return diag;
}

/// frames.csv of a tube stage (times from the start of the stage): centroid, extents, clearance, drift.
void writeTubeFrames(const std::string& dir, const TubeFrameSeries& s) {
    std::string csv = csvProvenance() + "t_s,t_R_over_V,cx_um,cy_um,cz_um,length_um,width_y_um,width_z_um,clearance_um,area_drift,"
                      "volume_drift\n";
    for (std::size_t k = 0; k < s.time.size(); ++k) {
        const Eigen::Vector3d c = s.centroidUm.col(static_cast<Eigen::Index>(k));
        csv += fmt::format("{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.6g},{:.6e},{:.6e}\n", s.time[k],
                           s.timeROverV[k], c.x(), c.y(), c.z(), s.lengthUm[k], s.widthYUm[k], s.widthZUm[k],
                           s.clearanceUm[k], s.areaDrift[k], s.volumeDrift[k]);
    }
    writeText(dir + "/frames.csv", csv);
}

/// The parameters known before the cell is fitted.
nlohmann::json tubeParametersJson(const TubeCaseResult& res, const TubeCaseOptions& c, const std::string& cellSource) {
    const TubeUnits& u = res.units;
    const double Vum = u.velocityScale, Uc = u.centreLineVelocity;
    return {{"radius_um", c.radius},
            {"pressure_gradient_mmHg_per_mm", c.pressureGradient},
            {"pressure_gradient_Pa_per_m", u.pressureGradientPaPerM},
            {"eta_out_mPa_s", res.conditions.etaOut},
            {"eta_in_mPa_s", res.conditions.etaIn},
            {"viscosity_ratio", c.viscosityRatio},
            {"velocity_scale_V_cm_per_s", Vum * 1e-4},
            {"centre_line_velocity_cm_per_s", Uc * 1e-4},
            {"mean_poiseuille_velocity_cm_per_s", 0.5 * Uc * 1e-4},
            {"time_unit_R_over_V_s", u.timeUnit},
            {"duration_R_over_V", c.duration},
            {"duration_s", c.duration * u.timeUnit},
            {"frame_interval_R_over_V", c.step.frameInterval},
            {"cell", flowCellJson(res.cell)},
            {"cell_source", cellSource},
            {"area_volume", "exact constraints: area multiplier (membrane tension) in the coupled system, "
                            "projection onto A0, V0 after each step"},
            {"A0_um2", res.conditions.A0},
            {"V0_um3", res.conditions.V0},
            {"minimum_radius_um", u.minimumRadius},
            {"domain", "infinite tube (Poiseuille flux far from the cell) instead of the reference's 50 um periodic box; "
                       "no thermal fluctuations"}};
}

nlohmann::json settlingParametersJson(const TubeCaseResult& res, const TubeCaseOptions& c) {
    if (c.settle <= 0.0) return nullptr;
    const TubeSettlingViscosity& s = res.settlingViscosity;
    return {{"max_duration_R_over_V", c.settle},
            {"criterion", fmt::format("extents along x, y and z vary by < {:g} (relative) over the last {:g} R/V",
                                      c.settleTolerance, kTubeSettleSpan)},
            {"etam_Pa_s_um", s.etam},
            {"etam_source", s.fromRelax ? "--settle-relax: eta_m = relax_requested_R_over_V x mu R / V, at most "
                                          "the cell's own eta_m"
                                        : "--settle-etam"},
            {"relax_requested_R_over_V", s.fromRelax ? nlohmann::json(c.settleRelax) : nlohmann::json(nullptr)},
            {"capped_at_cell_etam", s.fromRelax && s.etamFromRelax > res.cell.etam},
            {"relaxation_time_R_over_V", s.etam / s.etamPerTimeUnit},
            {"membrane_viscosity_ratio_E", res.groups.membraneViscosity * s.etam / res.cell.etam},
            {"note", "duration_R_over_V is the main run's, which starts from the settled shape and alone gives "
                     "the observables"}};
}

/// What the fit and the wall add to the parameters.
void addFittedParameters(nlohmann::json& params, const TubeCaseResult& res, const TubeCaseOptions& c) {
    const TubeGroups& g = res.groups;
    const double L = res.scales.length;
    params["dimensionless"] = {{"capillary_number", g.capillary}, {"viscosity_ratio", g.viscosityRatio},
                               {"membrane_viscosity_ratio_E", g.membraneViscosity}, {"FvK", g.FvK},
                               {"confinement_R_over_R_A", g.confinement}, {"centre_line_velocity_over_V", g.centreLineOverV}};
    params["settling"] = settlingParametersJson(res, c);
    params["tube"] = {{"wall_points_per_ring", res.setup.pointsPerRing},
                      {"wall_vertices", res.wallVertices},
                      {"wall_length_um", 2.0 * res.setup.halfLength * L},
                      {"wall_length_over_R", 2.0 * res.setup.halfLength / res.setup.radius},
                      {"repulsion_range_um", c.repulsionRange},
                      {"repulsion_pressure_Pa", res.repulsionPressurePa},
                      {"contact_clearance_um", res.contactClearanceUm}};
    const Eigen::Vector3d& eq = res.fit.equilibriumExtentsUm;
    const Eigen::Vector3d& fit = res.fit.fittedExtentsUm;
    params["initial_condition"] = {
        {"description", "equilibrium shape (docs/FORWARD_MODEL.md, equilibrium) on the axis, disc plane containing the axis (x-z); when "
                        "wider than the tube minus a clearance of 0.1 R, mapped by (a x, c y, b z) with b squeezing "
                        "the disc's diameter and a, c keeping area and volume exact"},
        {"equilibrium_extents_um", {eq.x(), eq.y(), eq.z()}},
        {"fitted_extents_um", {fit.x(), fit.y(), fit.z()}},
        {"clearance_um", res.fit.clearanceUm}};
}

nlohmann::json cellFrameMotionJson(const TubeObservables& ob) {
    return {{"fastest_vertex_path_um", ob.cellFrameMotion},
            {"centroid_travel_um", ob.travel},
            {"ratio", ob.cellFrameMotion / std::max(ob.travel, 1e-300)}};
}

nlohmann::json settlingDiagnosticsJson(const TubeCaseResult& res) {
    const TubeStageResult& s = res.settling;
    nlohmann::json sd = stepDiagnostics(res.scales, s.flow, res.prepared);
    sd.erase("equilibrium");
    sd.erase("sfs");
    sd["t_reached_R_over_V"] = s.flow.tReached;
    sd["settled"] = s.flow.stoppedEarly;
    sd["checkpoint"] = checkpointJson(s.flow, res.units.timeUnit);
    sd["wall_clearance_min_um"] = s.minClearanceUm;
    sd["centroid_off_axis_max_um"] = s.maxOffAxisUm;
    if (s.observables) {
        sd["cell_frame_motion"] = cellFrameMotionJson(*s.observables);
        sd["cell_frame_motion"]["window"] = fmt::format("the last {:g} R/V of the stage", kTubeSettleSpan);
    }
    if (s.flow.completed) {
        const Eigen::Vector3d e = extents(res.main.startUm);
        sd["final_length_um"] = e.x();
        sd["final_width_um"] = e.y();
    }
    return sd;
}

nlohmann::json mainDiagnosticsJson(const TubeCaseResult& res, const TubeCaseOptions& c) {
    const CellFlowResult& r = res.main.flow;
    nlohmann::json diag = stepDiagnostics(res.scales, r, res.prepared);
    diag["dt_min_R_over_V"] = r.dtSmallest;
    diag["dt_max_R_over_V"] = r.dtLargest;
    diag["step_control"] = stepControlJson(res.main.integrator, c.step.dt, "fixed_dt_R_over_V");
    diag["setup_wall_s"] = res.setupWallSeconds;
    diag["wall_operator_setup_s"] = res.wallSetupSeconds;
    diag["wall_clearance_min_um"] = res.main.minClearanceUm;
    diag["centroid_off_axis_max_um"] = res.main.maxOffAxisUm;
    diag["t_reached_R_over_V"] = r.tReached;
    diag["checkpoint"] = checkpointJson(r, res.units.timeUnit);
    return diag;
}

/// Observables, analysis and the plateau and cell-frame checks of a completed run.
void addTubeObservables(nlohmann::json& j, const TubeCaseResult& res) {
    nlohmann::json& diag = j["diagnostics"];
    if (!res.main.observables) {
        j["observables"] = {{"velocity_cm_per_s", nullptr}, {"length_um", nullptr}, {"width_um", nullptr}};
        j["analysis"] = {{"note", "fewer than 16 frames: no observables (lengthen --duration or shorten --frame-interval)"}};
        return;
    }
    const TubeObservables& ob = *res.main.observables;
    const double Uc = res.units.centreLineVelocity;
    j["observables"] = {{"velocity_cm_per_s", ob.velocity * 1e-4}, {"length_um", ob.length}, {"width_um", ob.widthY},
                        {"width_z_um", ob.widthZ}, {"velocity_over_centre_line", ob.velocity / Uc},
                        {"velocity_over_mean_poiseuille", ob.velocity / (0.5 * Uc)}};
    j["analysis"] = {{"length", "extent of the vertex x (axis), mean over the second half of the frames"},
                     {"width", "extent along y (width_um) and z (width_z_um), same window"},
                     {"velocity", "least-squares slope of the centroid x(t) over the last eighth of the frames"},
                     {"frames_used", ob.framesUsed}};
    diag["plateau"] = {{"length_change_q3_vs_q4", ob.lengthChange},
                       {"velocity_change_e7_vs_e8", ob.velocityChange},
                       {"reached", tubePlateauReached(ob)},
                       {"criterion", "both relative changes < 1 %"}};
    diag["cell_frame_motion"] = cellFrameMotionJson(ob);
    diag["cell_frame_motion"]["meaning"] =
        "path of the fastest vertex relative to the centroid over the averaging window, against the centroid's travel "
        "(bounds the membrane's speed relative to the cell): ~0 = membrane at rest in the co-moving frame (no "
        "tank-treading), a steady state independent of eta_m";
    if (diag.contains("settling")) {
        const double l0 = diag["settling"]["final_length_um"].get<double>();
        diag["settling"]["length_change_main_vs_settled"] = (ob.length - l0) / ob.length;
        if (!res.settling.flow.stoppedEarly)
            j["analysis"]["warning"] = "the settling stage reached its limit (--settle) before the shape was "
                                       "steady; the main run may not have reached the steady state";
    }
}

}  // namespace

void addShearObservables(nlohmann::json& j, const ShearObservables& obs) {
    const bool tt = obs.regime == ShearRegime::TankTreading;
    j["observables"] = {{"regime", regimeName(obs.regime)},
                        {"inclination_deg", nullable(tt, obs.inclinationDeg)},
                        {"swing_amplitude_deg", nullable(tt, obs.swingAmplitudeDeg)},
                        {"ttf_4pi_f_over_shear_rate", nullable(tt && obs.ttf.defined, obs.ttf4piFOverRate)}};
    j["analysis"] = {{"discarded_fraction", 0.25},
                     {"frames_used", obs.framesUsed},
                     {"angle_fit", {{"mean_deg", obs.angleFit.mean * 180.0 / kPi},
                                    {"amplitude_deg", obs.swingAmplitudeDeg},
                                    {"frequency_over_shear_rate", obs.swingFrequency},
                                    {"rms_deg", obs.angleFit.rms * 180.0 / kPi},
                                    {"converged", obs.angleFit.converged}}},
                     {"zero_crossing_4pi_f_over_shear_rate", nullable(obs.ttf.defined, obs.ttf4piFOverRate)},
                     {"zero_crossing_vertices", obs.ttf.vertices},
                     {"periodogram_4pi_f_over_shear_rate", obs.ttfFft4piFOverRate},
                     {"orientation_advance_deg", obs.orientationAdvance * 180.0 / kPi},
                     {"orientation_range_deg", obs.orientationRange * 180.0 / kPi},
                     {"membrane_advance_relative_to_shape_deg", obs.membraneAdvance * 180.0 / kPi},
                     {"membrane_advance_4pi_f_over_shear_rate", obs.membraneAdvance4piFOverRate}};
}

/// Shapes, steps.csv, frames.csv (per frame: time, strain, inclination, unwrapped orientation,
/// drift, centroid) and flow.json.
void writeShearOutputs(const std::string& dir, const ShearCaseResult& res, int vtkEvery, const nlohmann::json& j) {
    writeShapesAndSteps(dir, res.scales, res.prepared, res.prepared.initial, res.flow, vtkEvery);
    const ShearFrameSeries& s = res.series;
    std::string csv = csvProvenance() + "t_s,shear_strain,inclination_deg,orientation_unwrapped_deg,area_drift,volume_drift,cx_um,cy_um,cz_um\n";
    for (std::size_t k = 0; k < s.time.size(); ++k) {
        const Eigen::Vector3d c = s.centroidUm.col(static_cast<Eigen::Index>(k));
        csv += fmt::format("{:.9g},{:.9g},{:.9g},{:.9g},{:.6e},{:.6e},{:.9g},{:.9g},{:.9g}\n", s.time[k], s.shearStrain[k],
                           s.inclinationDeg[k], s.orientationDeg[k], s.areaDrift[k], s.volumeDrift[k], c.x(), c.y(), c.z());
    }
    writeText(dir + "/frames.csv", csv);
    writeText(dir + "/flow.json", j.dump(2) + "\n");
}

void writeTubeStage(const std::string& dir, const TubeCaseResult& res, const TubeStageResult& stage, int vtkEvery) {
    ensureWritableDirectory(dir);
    writeShapesAndSteps(dir, res.scales, res.prepared, stage.startUm, stage.flow, vtkEvery);
    writeTubeFrames(dir, stage.series);
}

nlohmann::json shearRecord(const ShearCaseResult& res, const ShearCaseOptions& c, const std::string& cellSource,
                           nlohmann::json provenance) {
    nlohmann::json j;
    j["parameters"] = shearParametersJson(res, c, cellSource);
    j["provenance"] = std::move(provenance);
    j["diagnostics"] = shearDiagnosticsJson(res, c);
    if (!res.completed) {
        j["status"] = "failed";
        j["reason"] = res.message;
        j["observables"] = {{"regime", nullptr}, {"inclination_deg", nullptr}, {"swing_amplitude_deg", nullptr},
                            {"ttf_4pi_f_over_shear_rate", nullptr}};
        return j;
    }
    j["status"] = "ok";
    addShearObservables(j, *res.observables);
    return j;
}

nlohmann::json rampRecord(const ShearRampResult& res, const ShearRampOptions& r, const std::string& cellSource,
                          nlohmann::json provenance) {
    const ShearCaseOptions& c = r.base;
    const bool thermal = c.temperatureK > 0.0;
    nlohmann::json stages = nlohmann::json::array();
    for (const ShearRampStage& st : res.stages) {
        nlohmann::json e{{"shear_rate_per_s", st.shearRate},
                         {"shear_stress_Pa", shearStressPa(c.etaOut, st.shearRate)},
                         {"direction", st.up ? "up" : "down"},
                         {"status", st.completed ? "ok" : "failed"},
                         {"turns", st.turns},
                         {"stopped_when_steady", st.stoppedWhenSteady},
                         {"wall_s", st.wallSeconds}};
        if (thermal) e["thermal_step_times_rate"] = st.thermalStep;
        if (!st.completed) e["reason"] = st.message;
        if (st.observables) addShearObservables(e, *st.observables);
        e.erase("analysis");
        stages.push_back(e);
    }
    const auto bracket = [](const std::optional<std::pair<double, double>>& b) {
        return b ? nlohmann::json{b->first, b->second} : nlohmann::json(nullptr);
    };
    nlohmann::json j;
    j["parameters"] = {{"eta_out_mPa_s", c.etaOut},
                       {"eta_in_mPa_s", c.etaIn},
                       {"rates_per_s", r.rates},
                       {"cell", flowCellJson(c.cell)},
                       {"cell_source", cellSource},
                       {"level", c.level},
                       {"rotations_per_stage", c.rotations},
                       {"tilt_deg", c.tiltDeg},
                       {"start", c.randomStart ? "random" : "in-plane"},
                       {"temperature_K", c.temperatureK},
                       {"seed", c.seed},
                       {"stop_when_steady", c.stopWhenSteady},
                       {"thermal_step_times_rate", thermal ? nlohmann::json(c.thermalStep) : nlohmann::json(nullptr)}};
    j["provenance"] = std::move(provenance);
    j["stages"] = std::move(stages);
    j["summary"] = {{"completed", res.completed},
                    {"up_onset_bracket_per_s", bracket(res.upBracket)},
                    {"down_end_bracket_per_s", bracket(res.downBracket)},
                    {"hysteresis", res.upBracket && res.downBracket && *res.upBracket != *res.downBracket},
                    {"wall_s", res.wallSeconds}};
    return j;
}

nlohmann::json tubeRecord(const TubeCaseResult& res, const TubeCaseOptions& c, const std::string& cellSource,
                          nlohmann::json provenance) {
    nlohmann::json j;
    j["parameters"] = tubeParametersJson(res, c, cellSource);
    j["provenance"] = std::move(provenance);
    if (res.stage == TubeCaseStage::Fit) {
        j["status"] = "failed";
        j["reason"] = res.message;
        return j;
    }
    addFittedParameters(j["parameters"], res, c);
    nlohmann::json& diag = j["diagnostics"];
    if (res.settling.ran) diag["settling"] = settlingDiagnosticsJson(res);
    if (res.main.ran) diag.update(mainDiagnosticsJson(res, c));
    diag["wall_s"] = res.wallSeconds;
    if (!res.completed) {
        j["status"] = "failed";
        j["reason"] = res.message;
        j["observables"] = {{"velocity_cm_per_s", nullptr}, {"length_um", nullptr}, {"width_um", nullptr}};
        return j;
    }
    j["status"] = "ok";
    addTubeObservables(j, res);
    return j;
}

namespace {

/// Reads the fields of one record. A field that is absent or null is missing (NaN, "", none); one of
/// another type than the schema's is a damaged record, not a missing value: InputError naming the
/// record and the field.
struct RecordFields {
    using Is = bool (nlohmann::json::*)() const noexcept;
    const std::string& source;

    const nlohmann::json* get(const nlohmann::json& o, const std::string& path, const char* key, Is is, const char* expected) const {
        const auto it = o.find(key);
        if (it == o.end() || it->is_null()) return nullptr;
        if (!((*it).*is)()) {
            std::string text = it->dump();
            if (text.size() > 40) text = text.substr(0, 37) + "...";
            throw InputError(fmt::format("{}: '{}{}' is {} ({}), not {} or null", source, path, key, text, it->type_name(), expected));
        }
        return &*it;
    }
    double number(const nlohmann::json& o, const std::string& path, const char* key) const {
        const nlohmann::json* v = get(o, path, key, &nlohmann::json::is_number, "a number");
        return v ? v->get<double>() : NAN;
    }
    std::string text(const nlohmann::json& o, const std::string& path, const char* key) const {
        const nlohmann::json* v = get(o, path, key, &nlohmann::json::is_string, "a string");
        return v ? v->get<std::string>() : std::string();
    }
    std::optional<bool> boolean(const nlohmann::json& o, const std::string& path, const char* key) const {
        const nlohmann::json* v = get(o, path, key, &nlohmann::json::is_boolean, "true, false");
        return v ? std::optional<bool>(v->get<bool>()) : std::nullopt;
    }
    /// The section `key` of o; an empty object when missing.
    const nlohmann::json& object(const nlohmann::json& o, const std::string& path, const char* key) const {
        static const nlohmann::json empty = nlohmann::json::object();
        const nlohmann::json* v = get(o, path, key, &nlohmann::json::is_object, "an object");
        return v ? *v : empty;
    }
};

}  // namespace

FlowRecordView readFlowRecord(const nlohmann::json& record, const std::string& source) {
    FlowRecordView v;
    if (!record.is_object()) {
        v.reason = fmt::format("{}: not a JSON object but {}", source, record.type_name());
        return v;
    }
    const RecordFields f{source};
    // Any status other than "ok" (absent, or of another type) is a failed case, not a damaged record.
    if (const auto status = record.find("status"); status != record.end() && status->is_string()) v.status = status->get<std::string>();
    v.reason = f.text(record, "", "reason");
    if (const auto o = record.find("observables"); v.ok() && (o == record.end() || !o->is_object()))
        throw InputError(fmt::format("{}: a finished case (status \"ok\") without its 'observables' object", source));
    const nlohmann::json& o = f.object(record, "", "observables");
    const nlohmann::json& d = f.object(record, "", "diagnostics");
    v.regime = f.text(o, "observables.", "regime");
    v.inclinationDeg = f.number(o, "observables.", "inclination_deg");
    v.swingDeg = f.number(o, "observables.", "swing_amplitude_deg");
    v.ttf = f.number(o, "observables.", "ttf_4pi_f_over_shear_rate");
    v.velocityCmPerS = f.number(o, "observables.", "velocity_cm_per_s");
    v.lengthUm = f.number(o, "observables.", "length_um");
    v.widthUm = f.number(o, "observables.", "width_um");
    v.plateauReached = f.boolean(f.object(d, "diagnostics.", "plateau"), "diagnostics.plateau.", "reached").value_or(false);
    const nlohmann::json& settling = f.object(d, "diagnostics.", "settling");
    if (!settling.empty()) {
        v.settled = f.boolean(settling, "diagnostics.settling.", "settled").value_or(false) ? "true" : "false";
        v.lengthChangeMainVsSettled = f.number(settling, "diagnostics.settling.", "length_change_main_vs_settled");
    }
    v.cellFrameMotionRatio = f.number(f.object(d, "diagnostics.", "cell_frame_motion"), "diagnostics.cell_frame_motion.", "ratio");
    v.areaDriftMax = f.number(d, "diagnostics.", "area_drift_max");
    v.volumeDriftMax = f.number(d, "diagnostics.", "volume_drift_max");
    return v;
}

double FlowRecordView::observable(const std::string& key) const {
    if (key == "inclination_deg") return inclinationDeg;
    if (key == "swing_amplitude_deg") return swingDeg;
    if (key == "ttf_4pi_f_over_shear_rate") return ttf;
    if (key == "velocity_cm_per_s") return velocityCmPerS;
    if (key == "length_um") return lengthUm;
    if (key == "width_um") return widthUm;
    throw std::invalid_argument("FlowRecordView: no observable '" + key + "'");
}

}  // namespace trbc
