#include "analysis/validation_draws.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>

#include "analysis/prediction.hpp"
#include "core/error.hpp"
#include "inference/statistics.hpp"

namespace trbc {

std::vector<PosteriorDraw> selectPosteriorDraws(const NumericTable& samples, int n, std::uint64_t seed, const std::string& option) {
    const Eigen::Index rows = samples.values.rows();
    if (n < 1 || n > rows)
        throw InputError(fmt::format("{} {}: out of range: valid range [1, {}] (the samples of {})", option, n, rows,
                                     samples.path.string()));
    const Eigen::VectorXd v = samples.column("v"), mu = samples.column("mu_uN_per_m"), kb = samples.column("kb_J"),
                          b2 = samples.column("b2"), etam = samples.column("etam_Pa_s_um");
    std::vector<PosteriorDraw> draws;
    for (const Eigen::Index k : subsampleIndices(rows, n, seed)) draws.push_back({static_cast<long>(k), v[k], mu[k], kb[k], b2[k], etam[k]});
    return draws;
}

ValidationCase thresholdBandCase(double etaOut) { return {fmt::format("threshold_eta{:g}", etaOut), "threshold", etaOut, 0.0, 0.0}; }

std::string drawCaseId(const std::string& caseId, long sample) { return fmt::format("{}_sample{}", caseId, sample); }

std::vector<ValidationCase> casesWithDraws(const std::vector<ValidationCase>& cases, const std::vector<PosteriorDraw>& draws) {
    std::vector<ValidationCase> all;
    for (const ValidationCase& c : cases) {
        all.push_back(c);
        for (const PosteriorDraw& d : draws) {
            ValidationCase x = c;
            x.id = drawCaseId(c.id, d.sample);
            x.sample = d.sample;
            all.push_back(x);
        }
    }
    return all;
}

DrawBand drawBand(const std::vector<DrawOutcome>& outcomes) {
    DrawBand b;
    std::vector<double> values;
    for (const DrawOutcome& o : outcomes) {
        ++b.draws;
        (o.finished ? b.finished : b.failed)++;
        if (o.finished && std::isfinite(o.value))
            values.push_back(o.value);
        else
            ++b.reasons[o.reason.empty() ? std::string(o.finished ? "no value" : "failed") : o.reason];
    }
    b.withValue = static_cast<int>(values.size());
    if (values.empty()) return b;
    std::sort(values.begin(), values.end());
    b.median = quantileSorted(values, 0.5);
    b.lo = quantileSorted(values, 0.05);
    b.hi = quantileSorted(values, 0.95);
    const double ess = static_cast<double>(values.size());
    b.medianMcse = quantileMcseSorted(values, 0.5, ess);
    b.loMcse = quantileMcseSorted(values, 0.05, ess);
    b.hiMcse = quantileMcseSorted(values, 0.95, ess);
    b.endsMcseIsLowerBound = quantileMcseIsLowerBound(0.05, ess) || quantileMcseIsLowerBound(0.95, ess);
    return b;
}

std::string drawReasonsText(const DrawBand& band) {
    std::string s;
    for (const auto& [reason, count] : band.reasons) s += fmt::format("{}{} x {}", s.empty() ? "" : "; ", count, reason);
    return s;
}

std::string bandVerdict(const DrawBand& band, const ScatterComparison& scatter, bool noValueDisagrees) {
    if (scatter.points == 0) return "no data";
    if (band.finished == 0) return "no prediction";
    if (band.withValue == 0) return noValueDisagrees ? "no overlap" : "no prediction";
    return band.lo <= scatter.hi && band.hi >= scatter.lo ? "overlap" : "no overlap";
}

bool bandVerdictWithinMcse(const DrawBand& band, const ScatterComparison& scatter) {
    if (scatter.points == 0 || band.withValue == 0) return false;
    if (band.endsMcseIsLowerBound) return true;
    // Overlap: it ends when lo passes above the scatter's top or hi below its bottom; no overlap:
    // the band lies above (lo against the top) or below (hi against the bottom).
    const double upGap = band.lo - scatter.hi, downGap = scatter.lo - band.hi;
    if (upGap <= 0.0 && downGap <= 0.0) return -upGap <= band.loMcse || -downGap <= band.hiMcse;
    return upGap > 0.0 ? upGap <= band.loMcse : downGap <= band.hiMcse;
}

DrawOutcome criticalStressOutcome(const std::vector<RegimePoint>& points, double etaOut) {
    DrawOutcome o;
    o.finished = std::any_of(points.begin(), points.end(), [](const RegimePoint& p) { return !p.regime.empty(); });
    if (!o.finished) {
        o.reason = "every threshold case failed";
        return o;
    }
    const ThresholdBracket b = thresholdBracket(points);
    const auto [lo, hi] = criticalStressInterval(b, etaOut);
    if (!lo || !hi)
        o.reason = "not bracketed";
    else if (!b.monotone)
        o.reason = "not monotone";
    else
        o.value = std::sqrt(*lo * *hi);
    return o;
}

NumericTable readThetaNewSamples(const std::filesystem::path& in, const char* option) {
    const std::filesystem::path file = std::filesystem::is_directory(in) ? in / "samples.csv" : in;
    if (!std::filesystem::exists(file))
        throw InputError(fmt::format("{} {}: no samples.csv (run `trbc infer` first; e.g. DIR/phase3/theta_new)", option, in.string()));
    NumericTable t = readNumericTable(file, std::vector<std::string>(kThetaNewColumns.begin(), kThetaNewColumns.end()));
    for (const char* c : kThetaNewColumns)
        if (t.find(c) < 0)
            throw InputError(fmt::format("{}: column '{}' missing: {} must be a theta_new posterior (columns {})", file.string(), c,
                                         option, fmt::join(kThetaNewColumns, ", ")));
    if (t.values.rows() < 2) throw InputError(fmt::format("{}: fewer than two samples", file.string()));
    return t;
}

}  // namespace trbc
