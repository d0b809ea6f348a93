#pragma once
// One forward-model sample as the JSON object that `trbc simulate` prints (parameters, observables,
// diagnostics per experiment, stretching curve, relaxation fit), shared by the CLI and the Python
// module so that both report the same numbers.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "experiments/experiments.hpp"

namespace trbc {

/// Diagnostics of a stress-free state (dimensionless units of docs/FORWARD_MODEL.md, stress-free state).
nlohmann::json sfsJson(const StressFreeState& s);
/// Diagnostics of a static state (equilibrium, stretching): pN, pN/um, Pa, J, s.
nlohmann::json staticSolverJson(const SolverDiagnostics& d);
/// How the equilibrium was chosen: branch, energy_gap_J (symmetric disc minus chosen; null without
/// kicks), kick_rms_um and the candidates (start, round, kick, energy_J, hmin_um, ...).
nlohmann::json equilibriumBranchJson(const EquilibriumResult& e);

/// The experiments named in `names` (eq, stretch, relax); the equilibrium is always run because
/// stretching and relaxation start from it. InputError "<option>: unknown experiment ..." otherwise.
ExperimentSet parseExperimentSet(const std::vector<std::string>& names, const std::string& option);

/// {"v", "mu_uN_per_m", "FvK", "kb_J", "b2", "etam_Pa_s_um", "Fext_pN"}.
nlohmann::json simulationParametersJson(const CellParameters& p, double fextPn);

/// A calibrated cell for other codes (`trbc export`): v, mu_uN_per_m, kb_J (as given), FvK, b2,
/// etam_Pa_s_um, Kalpha_uN_per_m (= mu), A0_um2, V0_um3, R_A_um.
nlohmann::json cellPhysicalJson(const CellParameters& p, double kbJ);
/// The same cell in the dimensionless units of docs/MEMBRANE_MODEL.md: lengths in
/// R_A = sqrt(A0 / 4 pi), moduli in mu (kb = 1 / FvK), times in etam / mu; with those units in
/// um, J and s.
nlohmann::json cellDimensionlessJson(const CellParameters& p);

/// "parameters", "status" ("ok"), "observables" (D_um, hmin_um, hmax_um, D0_um, D1_um, tc_s; null for
/// an experiment not run), "diagnostics" (per experiment, with the steps of the reference's protocol;
/// "sample": the experiments' sum without the SFS, whatever the cache held; "total": the run's cost,
/// `wallSeconds` and the SFS when this run computed it), "stretching_curve" and "relaxation_fit" when
/// they apply.
nlohmann::json simulationJson(const CellParameters& p, double fextPn, int level, const ExperimentSet& which,
                              const SampleResult& s, double wallSeconds);

}  // namespace trbc
