#pragma once
// Cost of the reference implementation's protocol (MODEL.md G.1, G.2): the number of explicit
// time steps (one force evaluation each) that its damped or inertial runs take for a sample,
// computed from the stability estimate of G.2 in the unit system of each step.
#include "experiments/parameters.hpp"

namespace trbc {

struct ReferenceProtocolSteps {
    double sfs = 0.0;               ///< D.3: dt_max / 5 for 4 gamma / mu
    double equilibrium = 0.0;       ///< E.1: dt_max for 100 gamma / mu
    double stretchPerForce = 0.0;   ///< E.2: dt_max for 150 time units, per force level
    double preStretch = 0.0;        ///< E.3 pre-stretch: one stretching run
    double relaxation = 0.0;        ///< E.3: dt_max / 2 for 1 s
};

ReferenceProtocolSteps referenceProtocolSteps(const CellParameters& p, int level);

}  // namespace trbc
