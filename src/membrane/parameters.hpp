#pragma once
// Moduli of the membrane energy terms (docs/MEMBRANE_MODEL.md). The engine is unit-agnostic: lengths and
// moduli are in whatever consistent units the caller uses (trbc's experiments use um, pN, s).
// A term whose modulus is zero is switched off.
#include <string>

namespace trbc {

/// Juelicher bending, U_b = 2 kb sum_i A_i (H_i - C0/2)^2 (bending), and the area-difference term
/// U_AD = pi kad / (2A) (sum_e l_e theta_e - DA0)^2 with DA0 = Delta A_0 / delta.
struct BendingParameters {
    double kb = 0.0;
    double C0 = 0.0;
    double kad = 0.0;
    double DA0 = 0.0;
};

/// Lim et al. (2008) in-plane elasticity (Lim energy): per face
/// A0_t [Kalpha/2 (alpha^2 + a3 alpha^3 + a4 alpha^4) + mu (beta + b1 alpha beta + b2 beta^2)].
struct LimParameters {
    double Kalpha = 0.0, a3 = 0.0, a4 = 0.0;
    double mu = 0.0, b1 = 0.0, b2 = 0.0;
};

/// Global penalties (reference form): kA/2 (A - A0)^2 / A0 and kV/2 (V - V0)^2 / V0.
struct GlobalPenaltyParameters {
    double kA = 0.0, A0 = 0.0;
    double kV = 0.0, V0 = 0.0;
};

struct MembraneParameters {
    BendingParameters bending;
    LimParameters lim;
    GlobalPenaltyParameters penalty;

    bool hasBending() const { return bending.kb != 0.0; }
    bool hasAde() const { return bending.kad != 0.0; }
    bool hasLim() const { return lim.Kalpha != 0.0 || lim.mu != 0.0; }
    bool hasArea() const { return penalty.kA != 0.0; }
    bool hasVolume() const { return penalty.kV != 0.0; }
};

/// Checks the moduli as given by a user (mesh units): kb, kad, Kalpha, mu, kA, kV finite and >= 0,
/// C0, DA0, a3, a4, b1, b2 finite; with kA > 0 (kV > 0) a target area A0 (volume V0) must be given
/// and be > 0. Sets p.penalty.A0 and V0. Throws InputError naming the parameter as
/// `prefix` + its name (kb, C0, kad, DA0, ka, a3, a4, mu, b1, b2, kA, A0, kV, V0).
MembraneParameters checkedMembraneParameters(MembraneParameters p, bool haveA0, double A0, bool haveV0, double V0,
                                             const std::string& prefix = "");

}  // namespace trbc
