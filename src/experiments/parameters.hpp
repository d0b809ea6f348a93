#pragma once
// Parameters of one red-cell sample in physical units, the prior box (docs/MEMBRANE_MODEL.md, parameters) and the
// membrane model that the experiments use (the fixed constants of docs/MEMBRANE_MODEL.md).
//
// Internal units of the experiments (docs/MEMBRANE_MODEL.md, units): um, pN, s. Moduli then keep their paper
// values (uN/m = pN/um, Pa s um = pN s/um) except kb: 1 J = 1e18 pN um.
#include <cmath>
#include <string>

#include "membrane/parameters.hpp"

namespace trbc {

/// Constants of the cell and of the experiments (docs/MEMBRANE_MODEL.md, units and parameters).
namespace cell {
inline constexpr double area = 135.0;                      // A0, um^2
inline constexpr double volume = 94.0;                     // V0, um^3
inline constexpr double radiusSquared = 10.742958658;      // R_A^2 = A0 / (4 pi), um^2
inline constexpr double joule = 1e18;                      // pN um per J
inline constexpr double a3 = -2.0, a4 = 8.0, b1 = 0.7;     // Lim coefficients (reference values)
inline constexpr double beadContactDiameter = 2.0;         // um (stretching)
inline constexpr double preStretchForcePerMu = 7.5386;     // pN per (uN/m): 2.3 mu R_A (relaxation)
inline constexpr double sfsArea = 140.0;                   // um^2, area at which the SFS is generated (D)
}  // namespace cell

/// theta = (v, mu, FvK, b2, eta_m) of docs/MEMBRANE_MODEL.md, parameters, in the units of the canonical names.
struct CellParameters {
    double v = 0.95;
    double mu = 4.0;      ///< mu_uN_per_m
    double FvK = 250.0;   ///< mu R_A^2 / kb
    double b2 = 1.5;
    double etam = 0.7;    ///< etam_Pa_s_um

    double kbPnUm() const { return mu * cell::radiusSquared / FvK; }
    double kbJoule() const { return kbPnUm() / cell::joule; }
    static double fvkFromKb(double mu, double kbJoule) { return mu * cell::radiusSquared / (kbJoule * cell::joule); }
};

/// The paper's Table 1: means of the theta_new posterior, the default cell of the flow validations
/// (docs/VALIDATION_RESULTS.md) until a calibration of trbc's own is given.
namespace table1 {
inline constexpr double v = 0.94, mu = 4.99, kbJ = 2.10e-19, b2 = 1.84, etam = 0.69;
}  // namespace table1
inline CellParameters paperTable1Cell() {
    return {table1::v, table1::mu, CellParameters::fvkFromKb(table1::mu, table1::kbJ), table1::b2, table1::etam};
}

/// The shear stress eta_out rate in Pa of an outer viscosity in mPa s and a rate in 1/s, and the
/// rate of a stress.
inline double shearStressPa(double etaOutMPaS, double shearRatePerS) { return etaOutMPaS * 1e-3 * shearRatePerS; }
inline double shearRateFromStress(double etaOutMPaS, double stressPa) { return stressPa / (etaOutMPaS * 1e-3); }

/// Dimensionless groups of a cell in flow (docs/FLOW.md). Every membrane modulus is proportional to
/// mu at fixed FvK and b2, so a deterministic flow's observables depend on these and on v and b2
/// only (a thermal kick or noise adds kT / kb).
struct FlowGroups {
    double capillary = 0.0;          ///< Ca = eta_out rate R / mu
    double viscosityRatio = 0.0;     ///< lambda = eta_in / eta_out
    double membraneViscosity = 0.0;  ///< E = eta_m / (eta_out R), the Boussinesq number Bq
    double FvK = 0.0;
    double shearStressPa = 0.0;      ///< eta_out rate
};
/// The groups at radius R (um; the cell's R_A by default). mu in uN/m = pN/um and the stress in
/// Pa = pN/um^2 make Ca = stress R / mu dimensionless; eta_m in Pa s um over eta_out R in Pa s um.
inline FlowGroups flowGroups(const CellParameters& cell, double etaOutMPaS, double etaInMPaS, double shearRatePerS,
                             double radiusUm = std::sqrt(cell::radiusSquared)) {
    FlowGroups g;
    g.shearStressPa = shearStressPa(etaOutMPaS, shearRatePerS);
    g.capillary = g.shearStressPa * radiusUm / cell.mu;
    g.viscosityRatio = etaInMPaS / etaOutMPaS;
    g.membraneViscosity = cell.etam / (etaOutMPaS * 1e-3 * radiusUm);
    g.FvK = cell.FvK;
    return g;
}

/// The prior box of docs/MEMBRANE_MODEL.md, parameters (FvK support [10, 1000], Fext [0, 200] pN).
struct PriorRange {
    const char* name;
    double lo, hi;
};
inline constexpr PriorRange kPriorV{"v", 0.65, 1.0};
inline constexpr PriorRange kPriorMu{"mu_uN_per_m", 1.0, 10.0};
inline constexpr PriorRange kPriorFvK{"FvK", 10.0, 1000.0};
inline constexpr PriorRange kPriorB2{"b2", 0.0, 4.0};
inline constexpr PriorRange kPriorEtam{"etam_Pa_s_um", 0.1, 1.0};
inline constexpr PriorRange kPriorFext{"Fext_pN", 0.0, 200.0};
/// kb / R_A^2 in [0.01, 0.1] uN/m (docs/BAYESIAN_INFERENCE.md prior of kb; rbc_problem.hpp kKbLow, kKbHigh), in J.
inline constexpr PriorRange kPriorKbJ{"kb_J", 1.074295866e-19, 1.074295866e-18};

/// Throws InputError naming the parameter and its valid range when a value is not finite or
/// (unless `allowOutsidePrior`) outside the prior box; physically impossible values (v outside
/// (0, 1], non-positive moduli, negative b2 or force) are rejected in any case.
void validateCellParameters(const CellParameters& p, bool allowOutsidePrior);
void validateForce(double fextPn, bool allowOutsidePrior);
/// A bending modulus given in J (instead of FvK): > 0, and inside kPriorKbJ unless allowOutsidePrior.
void validateBendingModulus(double kbJoule, bool allowOutsidePrior);

/// Membrane moduli of the experiments (E): Kalpha = mu, kb = mu R_A^2 / FvK, Lim coefficients of
/// fixed constants, C0 = 0, no ADE. The global area and volume are imposed exactly (solvers), so the penalty
/// moduli are zero here.
MembraneParameters experimentMembrane(const CellParameters& p);

}  // namespace trbc
