#pragma once
// A synthetic shear campaign with known answers for the flow networks' tests: tank-treading above
// a critical stress, the angle falling with log(stress / critical) and with 1 - v, a swing linear
// in v and a TTF smooth in eta_out.
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include "experiments/parameters.hpp"
#include "sampling/shear_campaign_table.hpp"

namespace trbc::test {

struct SyntheticAngle {
    double atCritical = 30.0;  ///< deg at the critical stress of a cell at v = 1
    double perLogStress = 4.0; ///< deg lost per e-fold of stress above the critical one
    double perUnitV = 5.0;     ///< deg lost per unit of 1 - v
};

/// `n` cases of the Sobol' design of `seed`, from random starts, four turns each.
inline std::vector<ShearCampaignRow> syntheticShearCampaign(long n, std::uint64_t seed,
                                                           const std::function<double(const ShearCampaignPoint&)>& criticalStressPa,
                                                           SyntheticAngle angle = {}) {
    std::vector<ShearCampaignRow> rows;
    for (const ShearCampaignPoint& q : shearCampaignDesign(DesignKind::Sobol, n, seed)) {
        ShearCampaignRow r;
        r.point = q;
        const double stress = shearStressPa(q.etaOut, q.shearRate), critical = criticalStressPa(q);
        r.regime = stress > critical ? "tank-treading" : "tumbling";
        if (r.tankTreading()) {
            r.inclinationDeg = angle.atCritical - angle.perLogStress * std::log(stress / critical) - angle.perUnitV * (1.0 - q.cell.v);
            r.swingDeg = 1.0 + 2.0 * q.cell.v;
            r.ttf = 0.3 + 0.1 * std::tanh(std::log(q.etaOut / 30.0));
        }
        r.turns = 4.0;
        r.start = "random";
        rows.push_back(r);
    }
    return rows;
}

}  // namespace trbc::test
