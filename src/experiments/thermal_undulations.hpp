#pragma once
// Thermal shape fluctuations of the resting cell, the scale of the symmetry-breaking kicks of the
// lowest-energy equilibrium (docs/EQUILIBRIUM.md "The lowest-energy equilibrium").
//
// A quasi-spherical membrane of radius R, r(Omega) = R (1 + sum_lm u_lm Y_lm(Omega)), bending
// rigidity kb and negligible tension has the mode energy (kb / 2) (l - 1)(l + 2) l (l + 1) |u_lm|^2
// (Helfrich; Milner & Safran 1987), so by equipartition <u_lm^2> = kT / (kb (l - 1)(l + 2) l (l + 1)).
// The lowest modes l = 2 (even: keeps the central symmetry x -> -x) and l = 3 (odd: breaks it)
// dominate, and their radial rms over the surface is
//   delta_r^2 = R^2 sum_{l=2,3} (2 l + 1) / (4 pi) kT / (kb (l - 1)(l + 2) l (l + 1)).
// Shear elasticity and tension only stiffen these modes, so this is an upper estimate of the
// amplitude that a resting cell explores.
#include "core/random.hpp"
#include "mesh/mesh.hpp"

namespace trbc {

inline constexpr double kBoltzmannJPerK = 1.380649e-23;
inline constexpr double kBodyTemperatureK = 310.15;  // 37 degrees C

/// kB T in pN um at the temperature T (K).
double thermalEnergy(double temperatureK = kBodyTemperatureK);

/// Variance of one real coefficient u_lm (dimensionless) of mode l >= 2: kT / (kb (l-1)(l+2) l (l+1)).
double undulationVariance(int l, double kT, double kb);

/// Radial rms (um) of the l = 2, 3 undulations of a sphere of radius R (the formula above).
double undulationRms(double radius, double kT, double kb);

/// A random radial displacement field of the l = 2, 3 real spherical harmonics about the centroid of
/// X, coefficients u_lm ~ N(0, undulationVariance) drawn from `rng`, scaled by `radius`: vertex i
/// moves by R sum_lm u_lm Y_lm(n_i) n_i, n_i the unit vector from the centroid.
Vertices thermalUndulation(const Vertices& X, double radius, double kT, double kb, Rng& rng);

}  // namespace trbc
