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

/// The in-plane elasticity law of each face against its stress-free reference (docs/MEMBRANE_MODEL.md,
/// in-plane laws): Lim (LimParameters) or one of the capsule laws (CapsuleLawParameters).
enum class InPlaneLaw { Lim, NeoHookean, Skalak };

/// The capsule laws, per face A0_t W with the strain invariants I1 = lambda1^2 + lambda2^2 - 2 and
/// I2 = lambda1^2 lambda2^2 - 1 of the face against its reference:
///   neo-Hookean (Barthes-Biesel): W = Gs/2 (I1 - 1 + 1/(I2 + 1)),  K_s = 3 Gs;
///   Skalak:                       W = Gs/4 (I1^2 + 2 I1 - 2 I2 + C I2^2),  K_s = Gs (1 + 2 C).
/// Gs is the small-strain shear modulus, K_s the small-strain area-dilation modulus.
struct CapsuleLawParameters {
    double Gs = 0.0;
    double C = 0.0;  ///< Skalak only; C > -1/2 keeps K_s > 0
};

/// "lim", "neo-hookean", "skalak" (the names of the --law option).
const char* inPlaneLawName(InPlaneLaw law);

/// Global penalties (reference form): kA/2 (A - A0)^2 / A0 and kV/2 (V - V0)^2 / V0.
struct GlobalPenaltyParameters {
    double kA = 0.0, A0 = 0.0;
    double kV = 0.0, V0 = 0.0;
};

struct MembraneParameters {
    BendingParameters bending;
    LimParameters lim;
    GlobalPenaltyParameters penalty;
    InPlaneLaw law = InPlaneLaw::Lim;
    CapsuleLawParameters capsule;  ///< used when law is NeoHookean or Skalak

    bool hasBending() const { return bending.kb != 0.0; }
    bool hasAde() const { return bending.kad != 0.0; }
    bool hasLim() const { return law == InPlaneLaw::Lim && (lim.Kalpha != 0.0 || lim.mu != 0.0); }
    bool hasCapsuleLaw() const { return law != InPlaneLaw::Lim && capsule.Gs != 0.0; }
    /// An in-plane term is on (it needs a stress-free reference).
    bool hasInPlane() const { return hasLim() || hasCapsuleLaw(); }
    bool hasArea() const { return penalty.kA != 0.0; }
    bool hasVolume() const { return penalty.kV != 0.0; }
};

/// Checks the moduli as given by a user (mesh units): kb, kad, Kalpha, mu, kA, kV finite and >= 0,
/// C0, DA0, a3, a4, b1, b2 finite; with kA > 0 (kV > 0) a target area A0 (volume V0) must be given
/// and be > 0; Gs finite and >= 0, the Skalak C finite and > -1/2. The moduli of an in-plane law are
/// set only for the chosen law: the Lim ones (ka, a3, a4, mu, b1, b2) only for Lim, Gs only for
/// neo-Hookean and Skalak, C only for Skalak. Sets p.penalty.A0 and V0. Throws InputError naming the
/// parameter as `prefix` + its name (kb, C0, kad, DA0, ka, a3, a4, mu, b1, b2, kA, A0, kV, V0, Gs,
/// skalak-c) and the law as `prefix` + law.
MembraneParameters checkedMembraneParameters(MembraneParameters p, bool haveA0, double A0, bool haveV0, double V0,
                                             const std::string& prefix = "");

}  // namespace trbc
