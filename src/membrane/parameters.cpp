#include "membrane/parameters.hpp"

#include <fmt/format.h>

#include <cmath>

#include "core/error.hpp"

namespace trbc {

const char* inPlaneLawName(InPlaneLaw law) {
    switch (law) {
        case InPlaneLaw::Lim: return "lim";
        case InPlaneLaw::NeoHookean: return "neo-hookean";
        case InPlaneLaw::Skalak: return "skalak";
    }
    return "unknown";
}

MembraneParameters checkedMembraneParameters(MembraneParameters p, bool haveA0, double A0, bool haveV0, double V0,
                                             const std::string& prefix) {
    auto finite = [&](const char* name, double v) {
        if (!std::isfinite(v)) throw InputError(fmt::format("{}{} must be a finite number (got {})", prefix, name, v));
    };
    auto nonNegative = [&](const char* name, double v) {
        finite(name, v);
        if (v < 0) throw InputError(fmt::format("{}{} = {} is out of range: a modulus must be >= 0", prefix, name, v));
    };
    nonNegative("kb", p.bending.kb);
    finite("C0", p.bending.C0);
    nonNegative("kad", p.bending.kad);
    finite("DA0", p.bending.DA0);
    nonNegative("ka", p.lim.Kalpha);
    finite("a3", p.lim.a3);
    finite("a4", p.lim.a4);
    nonNegative("mu", p.lim.mu);
    finite("b1", p.lim.b1);
    finite("b2", p.lim.b2);
    nonNegative("Gs", p.capsule.Gs);
    finite("skalak-c", p.capsule.C);
    // K_s = Gs (1 + 2 C) of the Skalak law must be > 0.
    if (p.capsule.C <= -0.5)
        throw InputError(fmt::format("{}skalak-c = {} is out of range: the Skalak C must be > -1/2 (valid: (-0.5, inf))",
                                     prefix, p.capsule.C));
    const char* law = inPlaneLawName(p.law);
    const auto onlyFor = [&](const char* name, double v, bool allowed, const char* laws) {
        if (v != 0.0 && !allowed)
            throw InputError(fmt::format("{}{} = {} is a modulus of {}, but {}law is {}", prefix, name, v,
                                         laws, prefix, law));
    };
    const bool lim = p.law == InPlaneLaw::Lim, capsule = !lim, skalak = p.law == InPlaneLaw::Skalak;
    onlyFor("ka", p.lim.Kalpha, lim, "the lim law");
    onlyFor("a3", p.lim.a3, lim, "the lim law");
    onlyFor("a4", p.lim.a4, lim, "the lim law");
    onlyFor("mu", p.lim.mu, lim, "the lim law");
    onlyFor("b1", p.lim.b1, lim, "the lim law");
    onlyFor("b2", p.lim.b2, lim, "the lim law");
    onlyFor("Gs", p.capsule.Gs, capsule, "the neo-hookean and skalak laws");
    onlyFor("skalak-c", p.capsule.C, skalak, "the skalak law");
    nonNegative("kA", p.penalty.kA);
    nonNegative("kV", p.penalty.kV);
    if (p.penalty.kA > 0) {
        if (!haveA0) throw InputError(fmt::format("{}kA > 0 needs the target area {}A0", prefix, prefix));
        if (!std::isfinite(A0) || A0 <= 0)
            throw InputError(fmt::format("{}A0 = {} is out of range: the target area must be > 0", prefix, A0));
    }
    if (p.penalty.kV > 0) {
        if (!haveV0) throw InputError(fmt::format("{}kV > 0 needs the target volume {}V0", prefix, prefix));
        if (!std::isfinite(V0) || V0 <= 0)
            throw InputError(fmt::format("{}V0 = {} is out of range: the target volume must be > 0", prefix, V0));
    }
    p.penalty.A0 = A0;
    p.penalty.V0 = V0;
    return p;
}

}  // namespace trbc
