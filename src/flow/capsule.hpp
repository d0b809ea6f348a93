#pragma once
// An initially spherical capsule in simple shear flow, in the dimensionless form of the capsule
// literature (Barthes-Biesel & Rallison 1981; Ramanujan & Pozrikidis 1998; Pozrikidis 2001):
// the solver's check on a deformable membrane (docs/flow_verification.md, capsules).
//
// Set-up. Sphere of radius a (the icosphere of the level, vertices on the unit sphere) as the
// stress-free state and the initial shape; outer viscosity eta, inner lambda eta; u = (rate y, 0, 0).
// Units a, 1 / rate, eta, so that the in-plane modulus is G_s' = 1 / Ca with Ca = eta rate a / G_s.
// In-plane law: neo-Hookean, Skalak or Lim (with K_alpha = mu = G_s and the red cell's a3, a4, b1,
// b2 = 0). Bending (optional) is Juelicher's discrete Helfrich energy 2 kb sum_i A_i H_i^2 without
// spontaneous curvature, kb = E_b, so that kb' = E_b / (eta rate a^3) = EB / Ca with
// EB = E_b / (a^2 G_s). Membrane viscosity (optional) through the edge friction 4 EM / sqrt 3 with
// EM = eta_m / (eta a). No global area constraint (the in-plane law alone resists area change);
// the volume is held exactly, as the flow conserves it.
//
// Observables, per frame: the ellipsoid with the capsule's volume and second moments of volume
// (a uniform ellipsoid of semi-axes a_k has int x_k^2 dV = V a_k^2 / 5), its axes L >= B in the
// shear plane (the third principal axis is the vorticity axis z by symmetry), the Taylor
// deformation D12 = (L - B) / (L + B) and the inclination of L to the flow direction x. The
// membrane's angular frequency is the mean advance of the vertices' polar angle about z in the
// frame turned with the long axis (ShearObservables::membraneAdvance), over the second half of
// the run: rate / 2 for a sphere at Ca -> 0.
#include <string>
#include <vector>

#include "flow/cell_flow.hpp"
#include "membrane/parameters.hpp"

namespace trbc {

struct CapsuleCase {
    InPlaneLaw law = InPlaneLaw::NeoHookean;
    double capillary = 0.05;          ///< Ca = eta rate a / G_s, G_s the small-strain shear modulus
    double viscosityRatio = 1.0;      ///< lambda
    double skalakC = 1.0;             ///< C of the Skalak law
    double bending = 0.0;             ///< EB = E_b / (a^2 G_s)
    double membraneViscosity = 0.0;   ///< EM = eta_m / (eta a)
    int level = 3;                    ///< icosphere level
    double strain = 12.0;             ///< duration, units of 1 / rate
    double stepTolerance = 1e-4;      ///< local error per step, largest vertex displacement / a
    double frameInterval = 0.05;      ///< units of 1 / rate
    /// Steady when D12 varies by at most this fraction of its final value over the last
    /// `steadyWindow` strain units.
    double steadyTolerance = 0.005;
    double steadyWindow = 2.0;
};

/// Throws InputError naming the option and its valid range.
void validateCapsuleCase(const CapsuleCase& c);

/// The membrane and flow of the case in internal units (header comment).
MembraneFlowSpec capsuleFlowSpec(const CapsuleCase& c);

struct EquivalentEllipsoid {
    double L = 0.0, B = 0.0, W = 0.0;  ///< semi-axes: long and short in the shear plane, along z
    double inclination = 0.0;          ///< angle of L to x, radians in (-pi/2, pi/2]
    double volume = 0.0;
};
/// The ellipsoid with the volume and second moments of volume of the closed surface (X, F).
EquivalentEllipsoid equivalentEllipsoid(const Vertices& X, const Faces& F);
/// (L - B) / (L + B).
double taylorDeformation(const EquivalentEllipsoid& e);

struct CapsuleResult {
    bool completed = false;
    std::string message;
    bool steady = false;
    double taylorD12 = 0.0;          ///< mean over the steady window
    double inclinationDeg = 0.0;     ///< mean over the steady window
    double d12Variation = 0.0;       ///< (max - min) of D12 over the window / final D12
    double membraneFrequencyOverRate = 0.0;  ///< angular frequency / rate
    double areaChange = 0.0;         ///< A / A0 - 1 at the end
    std::vector<double> times, d12, inclination;  ///< per frame (inclination in degrees)
    int steps = 0, rejectedSteps = 0;
    long gmresIterations = 0;
    double wallSeconds = 0.0;
    int vertices = 0;
};

/// Runs the case; a numerical failure gives completed = false with the reason.
CapsuleResult runCapsule(const CapsuleCase& c);

}  // namespace trbc
