#include "experiments/parameters.hpp"

#include <fmt/format.h>

#include <cmath>

#include "core/error.hpp"

namespace trbc {
namespace {

void checkRange(const PriorRange& r, double value, bool allowOutsidePrior, double physicalLo, bool loOpen) {
    if (!std::isfinite(value))
        throw InputError(fmt::format("parameter {} = {} is not a finite number (valid range [{}, {}])", r.name,
                                     value, r.lo, r.hi));
    const bool physicalOk = loOpen ? value > physicalLo : value >= physicalLo;
    if (!physicalOk)
        throw InputError(fmt::format("parameter {} = {} is not physical (must be {} {}; prior range [{}, {}])",
                                     r.name, value, loOpen ? ">" : ">=", physicalLo, r.lo, r.hi));
    if (!allowOutsidePrior && (value < r.lo || value > r.hi))
        throw InputError(fmt::format("parameter {} = {} is outside the prior range [{}, {}] "
                                     "(--allow-outside-prior opens it)",
                                     r.name, value, r.lo, r.hi));
}

}  // namespace

void validateCellParameters(const CellParameters& p, bool allowOutsidePrior) {
    checkRange(kPriorV, p.v, allowOutsidePrior, 0.0, true);
    if (p.v > 1.0)
        throw InputError(fmt::format("parameter v = {} is not physical (a closed surface has v <= 1)", p.v));
    checkRange(kPriorMu, p.mu, allowOutsidePrior, 0.0, true);
    checkRange(kPriorFvK, p.FvK, allowOutsidePrior, 0.0, true);
    checkRange(kPriorB2, p.b2, allowOutsidePrior, 0.0, false);
    checkRange(kPriorEtam, p.etam, allowOutsidePrior, 0.0, true);
}

void validateForce(double fextPn, bool allowOutsidePrior) {
    checkRange(kPriorFext, fextPn, allowOutsidePrior, 0.0, false);
}

void validateBendingModulus(double kbJoule, bool allowOutsidePrior) {
    checkRange(kPriorKbJ, kbJoule, allowOutsidePrior, 0.0, true);
}

MembraneParameters experimentMembrane(const CellParameters& p) {
    MembraneParameters m;
    m.bending.kb = p.kbPnUm();
    m.lim = {p.mu, cell::a3, cell::a4, p.mu, cell::b1, p.b2};
    return m;
}

}  // namespace trbc
