#include "experiments/reference_protocol.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace trbc {
namespace {

// explicit-step stability estimate in any consistent unit system: area A, Nv vertices, Nf faces, vertex mass m, edge friction
// gamma, moduli mu, kb, kA, kV.
double stableStep(double A, double nv, double nf, double m, double gamma, double mu, double kb, double kA, double kV) {
    const double l0 = std::sqrt(4.0 * A / (std::sqrt(3.0) * nf));
    const double rho = nv * m / A;
    const double eta = gamma * std::sqrt(3.0) / 4.0;
    const double dtVisc = l0 * l0 * rho / (8.0 * eta);
    const double dtEl = std::sqrt(l0 * m / (mu * l0 + kb / l0 + kA * l0 + kV * l0 * l0));
    return std::min(dtVisc, dtEl);
}

}  // namespace

ReferenceProtocolSteps referenceProtocolSteps(const CellParameters& p, int level) {
    const double nv = 10.0 * std::pow(4.0, level) + 2.0, nf = 20.0 * std::pow(4.0, level);
    const double fourPi = 4.0 * std::numbers::pi;
    const double RA = std::sqrt(cell::radiusSquared);
    const double kA = 0.5 * 1e6;   // experiments (fixed constants): 0.5 J/m^2 in pN/um
    const double kV = 7.23e5;      // 7.23e5 J/m^3 in pN/um^2
    const double kb = p.kbPnUm();
    ReferenceProtocolSteps s;
    {   // SFS: length R'_A, energy kappa = 2e-19 J; gamma = 200, m = 1.
        const double mu = 2.228169;
        s.sfs = 4.0 * 200.0 / mu / (stableStep(fourPi, nv, nf, 1.0, 200.0, mu, 1.0, 2.556824e5, 2.558384e5) / 5.0);
    }
    {   // Equilibrium: length R_A, energy 1e-19 J = 0.1 pN um; gamma = 500, m = 1.
        const double E = 0.1;
        const double mu = p.mu * cell::radiusSquared / E;
        const double dt = stableStep(fourPi, nv, nf, 1.0, 500.0, mu, kb / E, kA * cell::radiusSquared / E,
                                     kV * cell::radiusSquared * RA / E);
        s.equilibrium = 100.0 * 500.0 / mu / dt;
    }
    {   // Stretching: length R_A, force 0.25 pN; gamma = 200, m = 1, 150 time units.
        const double E = 0.25 * RA;
        const double dt = stableStep(fourPi, nv, nf, 1.0, 200.0, p.mu * cell::radiusSquared / E, kb / E,
                                     kA * cell::radiusSquared / E, kV * cell::radiusSquared * RA / E);
        s.stretchPerForce = 150.0 / dt;
        s.preStretch = s.stretchPerForce;
    }
    {   // Relaxation: physical units um, pN, s; m = 1e-11 kg = 1e-5 pN s^2/um; dt_max / 2 for 1 s.
        const double gamma = 4.0 * p.etam / std::sqrt(3.0);
        s.relaxation = 1.0 / (stableStep(cell::area, nv, nf, 1e-5, gamma, p.mu, kb, kA, kV) / 2.0);
    }
    return s;
}

}  // namespace trbc
