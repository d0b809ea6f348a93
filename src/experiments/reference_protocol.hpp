#pragma once
// Cost of the reference implementation's protocol (docs/FORWARD_MODEL.md, reference protocol): the number of explicit
// time steps (one force evaluation each) that its damped or inertial runs take for a sample,
// computed from the explicit-step stability estimate in the unit system of each step.
#include "experiments/parameters.hpp"

namespace trbc {

struct ReferenceProtocolSteps {
    double sfs = 0.0;               ///< SFS: dt_max / 5 for 4 gamma / mu
    double equilibrium = 0.0;       ///< equilibrium: dt_max for 100 gamma / mu
    double stretchPerForce = 0.0;   ///< stretching: dt_max for 150 time units, per force level
    double preStretch = 0.0;        ///< relaxation pre-stretch: one stretching run
    double relaxation = 0.0;        ///< relaxation: dt_max / 2 for 1 s
};

ReferenceProtocolSteps referenceProtocolSteps(const CellParameters& p, int level);

}  // namespace trbc
