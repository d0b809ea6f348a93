#include "sampling/design.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "core/error.hpp"
#include "sampling/sobol_sequence.hpp"

namespace trbc {

DesignKind parseDesignKind(const std::string& name) {
    if (name == "uniform") return DesignKind::Uniform;
    if (name == "lhs") return DesignKind::LatinHypercube;
    if (name == "sobol") return DesignKind::Sobol;
    throw InputError(fmt::format("--design: unknown design '{}' (valid: uniform, lhs, sobol)", name));
}

std::string designName(DesignKind kind) {
    switch (kind) {
        case DesignKind::Uniform: return "uniform";
        case DesignKind::LatinHypercube: return "lhs";
        default: return "sobol";
    }
}

Eigen::MatrixXd unitDesign(DesignKind kind, long n, int d, std::uint64_t seed) {
    if (n < 1) throw InputError(fmt::format("design size {} must be at least 1", n));
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    Eigen::MatrixXd u(n, d);
    if (kind == DesignKind::Uniform) {
        for (long i = 0; i < n; ++i)  // row by row: a longer design extends a shorter one
            for (int j = 0; j < d; ++j) u(i, j) = U(rng);
        return u;
    }
    if (kind == DesignKind::Sobol) {
        if (d < 1 || d > SobolSequence::kMaxDimensions)
            throw InputError(fmt::format("a Sobol' design has 1 to {} dimensions, not {}", SobolSequence::kMaxDimensions, d));
        Eigen::RowVectorXd shift(d);
        for (int j = 0; j < d; ++j) shift(j) = U(rng);
        SobolSequence seq(d);
        for (long i = 0; i < n; ++i) {
            const Eigen::VectorXd x = seq.next();
            for (int j = 0; j < d; ++j) {
                const double y = x(j) + shift(j);
                u(i, j) = y >= 1.0 ? y - 1.0 : y;
            }
        }
        return u;
    }
    std::vector<long> strata(n);
    for (int j = 0; j < d; ++j) {
        std::iota(strata.begin(), strata.end(), 0L);
        std::shuffle(strata.begin(), strata.end(), rng);
        for (long i = 0; i < n; ++i) u(i, j) = (double(strata[i]) + U(rng)) / double(n);
    }
    return u;
}

static double fromUnit(const PriorRange& r, double u) { return r.lo + u * (r.hi - r.lo); }

CellParameters cellFromUnit(const Eigen::Ref<const Eigen::RowVectorXd>& u) {
    CellParameters p;
    p.v = fromUnit(kCellBox[0], u(0));
    p.mu = fromUnit(kCellBox[1], u(1));
    p.FvK = fromUnit(kCellBox[2], u(2));
    p.b2 = fromUnit(kCellBox[3], u(3));
    p.etam = fromUnit(kCellBox[4], u(4));
    return p;
}

double forceFromUnit(double u) { return fromUnit(kPriorFext, u); }

std::vector<CampaignPoint> campaignDesign(DesignKind kind, long nSamples, int forcesPerCell, std::uint64_t seed) {
    if (nSamples < 1) throw InputError(fmt::format("--samples {} must be at least 1", nSamples));
    if (forcesPerCell < 1 || forcesPerCell > 1000)
        throw InputError(fmt::format("--forces-per-cell {} is outside [1, 1000]", forcesPerCell));
    const long nCells = (nSamples + forcesPerCell - 1) / forcesPerCell;
    // Two independent streams: cells from seed, forces from a decorrelated seed.
    const Eigen::MatrixXd cells = unitDesign(kind, nCells, 5, seed);
    const Eigen::MatrixXd forces =
        forcesPerCell == 1 && kind == DesignKind::Uniform ? Eigen::MatrixXd() : unitDesign(kind, nSamples, 1, seed ^ 0x9E3779B97F4A7C15ULL);
    // forcesPerCell = 1 with the uniform design is the reference's 6-D i.i.d. design: draw the
    // force as the sixth coordinate of the same stream.
    const Eigen::MatrixXd six = forces.size() ? Eigen::MatrixXd() : unitDesign(kind, nSamples, 6, seed);
    std::vector<CampaignPoint> pts(nSamples);
    for (long i = 0; i < nSamples; ++i) {
        CampaignPoint& q = pts[i];
        q.sampleId = i;
        q.cellId = i / forcesPerCell;
        if (six.size()) {
            q.p = cellFromUnit(six.row(i).head(5));
            q.fext = forceFromUnit(six(i, 5));
        } else {
            q.p = cellFromUnit(cells.row(q.cellId));
            q.fext = forceFromUnit(forces(i, 0));
        }
    }
    return pts;
}

}  // namespace trbc
