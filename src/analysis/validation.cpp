#include "analysis/validation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <toml++/toml.h>

#include "analysis/toml_reader.hpp"
#include "core/error.hpp"
#include "inference/rbc_problem.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {


/// The default shear sweeps (docs/VALIDATE.md): angles at 10.7 and 23.9 mPa s (14 rates in [1, 200]),
/// TTF at 28.9 mPa s (6 rates in [8, 264]) and the scripted threshold sweeps.
std::vector<ShearSweep> defaultSweeps() {
    std::vector<ShearSweep> s = {{"angle", 10.7, 1.0, 200.0, 14}, {"angle", 23.9, 1.0, 200.0, 14}, {"ttf", 28.9, 8.0, 264.0, 6}};
    const double t[][3] = {{10, 30, 300}, {14, 7, 70}, {20, 5, 50}, {23.9, 1, 12}, {30, 1, 4}, {50, 1, 4}, {70, 0.5, 2}, {100, 0.3, 1}};
    for (const auto& r : t) s.push_back({"threshold", r[0], r[1], r[2], 6});
    return s;
}

void readSweeps(const fs::path& file, const toml::table& shear, const char* kind, std::vector<ShearSweep>& out) {
    const toml::node* n = shear.get(kind);
    if (!n) return;
    auto fail = [&](const toml::node& at, const std::string& what) {
        throw InputError(fmt::format("{}:{}: {}", file.string(), at.source().begin.line, what));
    };
    const toml::array* arr = n->as_array();
    if (!arr || arr->empty())
        fail(*n, fmt::format("'shear.{}' must be a non-empty array of tables [[shear.{}]] with eta_out, rate_min, rate_max, count",
                             kind, kind));
    for (const toml::node& e : *arr) {
        const toml::table* t = e.as_table();
        if (!t) fail(e, fmt::format("every [[shear.{}]] entry must be a table", kind));
        TableReader r(file, *t, fmt::format("shear.{}", kind));
        r.allowOnly({"eta_out", "rate_min", "rate_max", "count"});
        ShearSweep s{kind, 0.0, 0.0, 0.0, 6};
        r.real("eta_out", s.etaOut, 0.0, 1e6, true);
        r.real("rate_min", s.rateMin, 0.0, 1e9, true);
        r.real("rate_max", s.rateMax, 0.0, 1e9, true);
        r.integer("count", s.count, 1, 1000);
        if (s.etaOut <= 0.0 || s.rateMin <= 0.0 || s.rateMax <= 0.0)
            fail(e, fmt::format("a [[shear.{}]] entry lacks one of eta_out (mPa s), rate_min, rate_max (1/s)", kind));
        if (s.rateMax < s.rateMin) fail(e, fmt::format("[[shear.{}]]: rate_max = {} < rate_min = {}", kind, s.rateMax, s.rateMin));
        out.push_back(s);
    }
}

/// A path of the file, relative to the directory of the file that sets it (this one or a base).
using PathResolver = std::function<fs::path(const toml::table&, const char*, const std::string&)>;

/// [cell]: the source of the cell and, for "explicit", its five parameters inside the prior box.
void readCellSection(const fs::path& file, const toml::table& tbl, const PathResolver& pathOf, ValidationConfig& c) {
    const toml::table* t = &tbl;
    TableReader r(file, *t, "cell");
    r.allowOnly({"source", "posterior", "v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"});
    r.string("source", c.cellSource, {"table1", "posterior", "explicit"});
    std::string post;
    r.string("posterior", post);
    if (!post.empty()) c.posterior = pathOf(*t, "posterior", post);
    // Prior box of docs/MEMBRANE_MODEL.md (docs/CAMPAIGN_AND_SURROGATE.md, input box); flow solvers accept no cell outside it.
    const RbcPriorBox box;
    for (const auto& [key, value] : {std::pair{"v", &c.v}, {"mu_uN_per_m", &c.mu}, {"kb_J", &c.kbJ}, {"b2", &c.b2},
                                    {"etam_Pa_s_um", &c.etam}}) {
        const auto [lo, hi] = box.bounds(key);
        r.real(key, *value, lo, hi);
    }
    // Keys the chosen source does not read are refused, not ignored: table1 and posterior take all five
    // parameters from elsewhere, explicit takes exactly the five given.
    const char* kParameters[] = {"v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"};
    if (c.cellSource != "posterior" && t->get("posterior"))
        r.fail(*t->get("posterior"), fmt::format("'cell.posterior' is not read with cell.source = \"{}\" (only with source = "
                                                 "\"posterior\"): remove it or set source = \"posterior\"",
                                                 c.cellSource));
    if (c.cellSource != "explicit")
        for (const char* key : kParameters)
            if (const toml::node* n = t->get(key))
                r.fail(*n, fmt::format("'cell.{}' is not read with cell.source = \"{}\" (the cell is {}): remove it, or set "
                                       "source = \"explicit\" and give all of v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um",
                                       key, c.cellSource,
                                       c.cellSource == "table1" ? "Table 1's means" : "the posterior's means"));
    if (c.cellSource == "explicit") {
        std::vector<std::string> missing;
        for (const char* key : kParameters)
            if (!t->get(key)) missing.push_back(key);
        if (!missing.empty())
            r.fail(*t->get("source"), fmt::format("cell.source = \"explicit\" needs all of v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um; "
                                                  "missing: {}", fmt::join(missing, ", ")));
    }
    if (c.cellSource == "posterior" && c.posterior.empty())
        r.fail(*t, "cell.source = \"posterior\" needs cell.posterior (DIR/phase3/theta_new of `trbc infer`)");
    if (c.cellSource == "posterior" && !fs::exists(c.posterior))
        r.fail(*t->get("posterior"), fmt::format("cell.posterior {} does not exist", c.posterior.string()));
}

/// [shear]: the fluid, the duration, the start and the threshold's protocol, and the sweeps.
void readShearSection(const fs::path& file, const toml::table& tbl, ValidationConfig& c) {
    const toml::table* t = &tbl;
    TableReader r(file, *t, "shear");
    r.allowOnly({"eta_in", "rotations", "tilt_deg", "threshold_refinements", "threshold_protocol", "threshold_members",
                 "temperature_K", "stop_when_steady", "angle", "ttf", "threshold"});
    r.real("eta_in", c.etaIn, 0.0, 1e6, true);
    r.real("rotations", c.rotations, 0.0, 1000.0, true);
    r.real("tilt_deg", c.tiltDeg, 0.0, 90.0);
    r.integer("threshold_refinements", c.thresholdRefinements, 0, 20);
    r.string("threshold_protocol", c.thresholdProtocol, {"in-plane", "ensemble", "fluctuating"});
    if (const toml::node* n = t->get("threshold_members"); n && n->value<std::int64_t>() == 0)
        r.fail(*n, "'shear.threshold_members' is 0: members run only with threshold_protocol = \"ensemble\" or "
                   "\"fluctuating\", in [1, 64]; one run per rate from the configured start is threshold_protocol = \"in-plane\"");
    // threshold_members without a protocol meant random starts: read as fluctuating cells, the
    // members would change their meaning silently.
    if (const toml::node* n = t->get("threshold_members"); n && !t->get("threshold_protocol"))
        r.fail(*n, "'shear.threshold_members' without 'shear.threshold_protocol': give the protocol of the members, "
                   "\"fluctuating\" (thermally fluctuating cells) or \"ensemble\" (random starts)");
    r.integer("threshold_members", c.thresholdMembers, 1, 64);
    r.real("temperature_K", c.temperatureK, 0.0, 400.0, true);  // the range of `flow shear --temperature`
    // A key the chosen protocol never reads would look like a setting that took effect. Only a key
    // of the file that chooses the protocol: a base's keys belong to the base's protocol and cannot
    // be unset, and a --threshold-protocol override is the user's choice (validation.md says what ran).
    const toml::node* protocol = t->get("threshold_protocol");
    const auto sameFile = [&](const toml::node& n) {
        return TableReader::sourceFile(n, file) == TableReader::sourceFile(*protocol, file);
    };
    const auto refuseUnread = [&](const char* key, const char* readBy) {
        if (const toml::node* n = t->get(key); n && protocol && sameFile(*n))
            r.fail(*n, fmt::format("'shear.{}' is not read with threshold_protocol = \"{}\": only {} use it; remove the key "
                                   "or choose that protocol",
                                   key, c.thresholdProtocol, readBy));
    };
    if (c.thresholdProtocol == "in-plane") refuseUnread("threshold_members", "\"ensemble\" and \"fluctuating\"");
    if (c.thresholdProtocol != "fluctuating") refuseUnread("temperature_K", "\"fluctuating\" cells");
    r.boolean("stop_when_steady", c.stopWhenSteady);
    // Sweeps given in the file replace all the default ones (the kinds not given are not run).
    if (t->get("angle") || t->get("ttf") || t->get("threshold")) c.sweeps.clear();
    for (const char* kind : {"angle", "ttf", "threshold"}) readSweeps(file, *t, kind, c.sweeps);
}

/// [tube]: the microtube, its settling stage and the pressure gradients.
void readTubeSection(const fs::path& file, const toml::table& tbl, ValidationConfig& c) {
    const toml::table* t = &tbl;
    TableReader r(file, *t, "tube");
    r.allowOnly({"enabled", "radius", "eta_out", "duration", "settle", "settle_relax", "settle_etam", "settle_tol", "step_tol", "level",
                "pressure_gradients"});
    r.boolean("enabled", c.tubeEnabled);
    r.real("radius", c.tubeRadius, 1.497, 1e4);
    r.real("eta_out", c.tubeEtaOut, 0.0, 1e6, true);
    r.real("duration", c.tubeDuration, 0.0, 1e7, true);
    r.real("settle", c.tubeSettle, 0.0, 1e7);
    r.real("settle_relax", c.tubeSettleRelax, 0.0, 1e3, true);
    r.real("settle_etam", c.tubeSettleEtam, 0.0, 1e3, true);
    if (t->get("settle_relax") && t->get("settle_etam"))
        r.fail(*t->get("settle_etam"), "'tube.settle_etam' and 'tube.settle_relax' both given: the settling stage's "
                                       "membrane viscosity is set by one of them, give one");
    r.real("settle_tol", c.tubeSettleTol, 0.0, 1.0, true);
    r.real("step_tol", c.tubeStepTol, 0.0, 1.0, true);
    if (c.tubeSettle > 0.0 && c.tubeSettle < 10.0)
        throw InputError(fmt::format("{}: [tube] settle = {}: must be 0 (no settling stage) or >= 10 R/V (the span "
                                     "of the settling criterion)",
                                     file.string(), c.tubeSettle));
    r.integer("level", c.tubeLevel, 0, 4);
    if (const toml::node* n = t->get("pressure_gradients")) {
        const toml::array* a = n->as_array();
        std::vector<double> pg;
        if (a)
            for (const toml::node& x : *a) {
                const auto v = x.value<double>();
                if (!v || !(*v > 0.0) || !std::isfinite(*v)) {
                    pg.clear();
                    break;
                }
                pg.push_back(*v);
            }
        if (pg.empty() || (a && pg.size() != a->size()))
            r.fail(*n, "'tube.pressure_gradients' must be a non-empty array of numbers > 0 (mmHg/mm)");
        c.pressureGradients = pg;
    }
}

}  // namespace

ValidationConfig readValidationConfig(const fs::path& file, const fs::path& experiments) {
    ValidationConfig c;
    std::vector<fs::path> chain;
    const toml::table root = parseWithBases(file, chain, c.bases);
    c.file = fs::absolute(file).lexically_normal();
    c.dataDir = experiments / "validation";
    c.sweeps = defaultSweeps();
    for (int k = 1; k <= 15; ++k) c.pressureGradients.push_back(5.0 * k);
    TableReader top(file, root, "");
    top.allowOnly({"base", "run", "data", "cell", "shear", "tube"});
    auto section = [&](const char* name) -> const toml::table* {
        const toml::node* n = root.get(name);
        if (!n) return nullptr;
        if (!n->is_table()) top.fail(*n, fmt::format("'{}' must be a table [{}]", name, name));
        return n->as_table();
    };
    const PathResolver pathOf = [&](const toml::table& t, const char* key, const std::string& value) {
        return resolveConfigPath(value, TableReader::sourceFile(*t.get(key), file).parent_path(), experiments);
    };
    if (const toml::table* t = section("run")) {
        TableReader r(file, *t, "run");
        r.allowOnly({"level", "jobs", "threads", "step_tol", "checkpoint_interval"});
        r.integer("level", c.level, 1, 4);
        r.integer("jobs", c.jobs, 1, 256);
        r.integer("threads", c.threads, 1, 1024);
        r.real("step_tol", c.stepTol, 0.0, 1.0, true);
        r.real("checkpoint_interval", c.checkpointInterval, 0.0, 1e9);
    }
    if (const toml::table* t = section("data")) {
        TableReader r(file, *t, "data");
        r.allowOnly({"dir"});
        std::string d;
        r.string("dir", d);
        if (!d.empty()) c.dataDir = pathOf(*t, "dir", d);
    }
    if (!fs::is_directory(c.dataDir / "shear_flow") || !fs::is_directory(c.dataDir / "microtube"))
        throw InputError(fmt::format("{}: validation data directory {} lacks shear_flow/ or microtube/ (data.dir)", file.string(),
                                     c.dataDir.string()));
    if (const toml::table* t = section("cell")) readCellSection(file, *t, pathOf, c);
    if (const toml::table* t = section("shear")) readShearSection(file, *t, c);
    if (const toml::table* t = section("tube")) readTubeSection(file, *t, c);
    return c;
}

std::vector<double> logSpaced(double lo, double hi, int count) {
    std::vector<double> r;
    if (count <= 1) return {lo};
    for (int k = 0; k < count; ++k) r.push_back(lo * std::pow(hi / lo, static_cast<double>(k) / (count - 1)));
    return r;
}

std::string shearCaseId(const std::string& kind, double etaOut, double rate, int digits) {
    if (digits >= 17) return fmt::format("{}_eta{}_rate{}", kind, etaOut, rate);  // shortest round trip: one id per double
    return fmt::format("{}_eta{:g}_rate{:.{}g}", kind, etaOut, rate, digits);
}

std::string uniqueShearCaseId(const std::string& kind, double etaOut, double rate, const std::vector<ValidationCase>& cases) {
    for (int digits : {4, 6, 9, 12, 17}) {
        const std::string id = shearCaseId(kind, etaOut, rate, digits);
        const bool taken = std::any_of(cases.begin(), cases.end(), [&](const ValidationCase& x) {
            return baseCaseId(x) == id && !(x.kind == kind && x.etaOut == etaOut && x.rate == rate);
        });
        if (!taken) return id;
    }
    return shearCaseId(kind, etaOut, rate, 17);
}

std::string tubeCaseId(double pg) { return fmt::format("tube_pg{:g}", pg); }

std::vector<double> thresholdViscosities(const ValidationConfig& c) {
    std::vector<double> etas;
    for (const ShearSweep& s : c.sweeps)
        if (s.kind == "threshold" && std::find(etas.begin(), etas.end(), s.etaOut) == etas.end()) etas.push_back(s.etaOut);
    return etas;
}

std::vector<ValidationCase> initialValidationCases(const ValidationConfig& c) {
    std::vector<ValidationCase> cases;
    for (const ShearSweep& s : c.sweeps)
        for (double rate : logSpaced(s.rateMin, s.rateMax, s.count)) {
            const std::string id = uniqueShearCaseId(s.kind, s.etaOut, rate, cases);
            if (std::none_of(cases.begin(), cases.end(), [&](const ValidationCase& x) { return baseCaseId(x) == id; })) {
                if (s.kind != "threshold" || thresholdMemberCount(c) == 0) {
                    cases.push_back({id, s.kind, s.etaOut, rate, 0.0});
                    continue;
                }
                for (int k = 1; k <= c.thresholdMembers; ++k)
                    cases.push_back({memberCaseId(id, k), s.kind, s.etaOut, rate, 0.0, -1, k});
            }
        }
    if (c.tubeEnabled)
        for (double pg : c.pressureGradients)
            if (std::none_of(cases.begin(), cases.end(), [&](const ValidationCase& x) { return x.id == tubeCaseId(pg); }))
                cases.push_back({tubeCaseId(pg), "tube", c.tubeEtaOut, 0.0, pg});
    return cases;
}

int thresholdMemberCount(const ValidationConfig& c) { return c.thresholdProtocol == "in-plane" ? 0 : c.thresholdMembers; }

std::string memberCaseId(const std::string& caseId, int member) { return fmt::format("{}_m{}", caseId, member); }

std::string baseCaseId(const ValidationCase& c) {
    return c.member > 0 ? c.id.substr(0, c.id.rfind(fmt::format("_m{}", c.member))) : c.id;
}

std::vector<RegimePoint> ensembleRegimePoints(const std::vector<RegimePoint>& members) {
    std::vector<double> rates;
    for (const RegimePoint& p : members)
        if (std::find(rates.begin(), rates.end(), p.rate) == rates.end()) rates.push_back(p.rate);
    std::sort(rates.begin(), rates.end());
    std::vector<RegimePoint> out;
    for (double rate : rates) {
        int finished = 0, treading = 0;
        for (const RegimePoint& p : members)
            if (p.rate == rate && !p.regime.empty()) ++finished, treading += p.regime == "tank-treading";
        const std::string regime = finished == 0               ? ""
                                   : 2 * treading > finished ? "tank-treading"
                                   : 2 * treading < finished ? "tumbling"
                                                             : "intermittent";
        out.push_back({rate, regime});
    }
    return out;
}

std::vector<ValidationCase> validationShard(const std::vector<ValidationCase>& cases, int part, int parts) {
    if (parts < 1 || part < 1 || part > parts)
        throw InputError(fmt::format("validation shard {}/{}: need 1 <= K <= N", part, parts));
    std::vector<ValidationCase> mine;
    std::vector<std::pair<double, int>> thresholdUnit;  // viscosity -> its unit
    int unit = 0;
    for (const ValidationCase& c : cases) {
        int u;
        if (c.kind == "threshold") {
            const auto it = std::find_if(thresholdUnit.begin(), thresholdUnit.end(), [&](const auto& p) { return p.first == c.etaOut; });
            if (it != thresholdUnit.end()) {
                u = it->second;
            } else {
                u = unit++;
                thresholdUnit.emplace_back(c.etaOut, u);
            }
        } else {
            u = unit++;
        }
        if (u % parts == part - 1) mine.push_back(c);
    }
    return mine;
}

std::pair<int, int> parseShard(const std::string& text, const std::string& option) {
    int k = 0, n = 0;
    char slash = 0, extra = 0;
    std::istringstream in(text);
    if (!(in >> k >> slash >> n) || slash != '/' || (in >> extra) || k < 1 || n < 1 || k > n)
        throw InputError(fmt::format("{} '{}': expected K/N with 1 <= K <= N (part K of N, e.g. 2/4)", option, text));
    return {k, n};
}

ThresholdBracket thresholdBracket(std::vector<RegimePoint> points) {
    std::sort(points.begin(), points.end(), [](const RegimePoint& a, const RegimePoint& b) { return a.rate < b.rate; });
    ThresholdBracket b;
    for (const RegimePoint& p : points) {
        if (p.regime == "tumbling") b.gammaLo = p.rate;  // ascending: the last one is the highest
        if (p.regime == "tank-treading" && !b.gammaHi) b.gammaHi = p.rate;
        if (p.regime == "intermittent") b.intermittentRates.push_back(p.rate);
    }
    b.monotone = !(b.gammaLo && b.gammaHi) || *b.gammaLo < *b.gammaHi;
    return b;
}

std::optional<double> refinementRate(const std::vector<RegimePoint>& points, double minRatio) {
    if (points.empty()) return std::nullopt;
    const ThresholdBracket b = thresholdBracket(points);
    double lo = std::numeric_limits<double>::infinity(), hi = 0.0;
    for (const RegimePoint& p : points) lo = std::min(lo, p.rate), hi = std::max(hi, p.rate);
    if (b.gammaLo && b.gammaHi) {
        if (!b.monotone) return std::nullopt;  // tumbling above tank-treading: reported, not bisected
        // The widest gap between neighbouring rates already run inside [gammaLo, gammaHi]
        // (intermittent and failed cases are gap edges, so the new rate is never one run before).
        std::vector<double> inside;
        for (const RegimePoint& p : points)
            if (p.rate >= *b.gammaLo && p.rate <= *b.gammaHi) inside.push_back(p.rate);
        std::sort(inside.begin(), inside.end());
        double bestRatio = minRatio, best = 0.0;
        for (std::size_t k = 0; k + 1 < inside.size(); ++k)
            if (inside[k + 1] / inside[k] > bestRatio) bestRatio = inside[k + 1] / inside[k], best = std::sqrt(inside[k] * inside[k + 1]);
        if (best > 0.0) return best;
        return std::nullopt;
    }
    // Not bracketed yet: search upwards for tank-treading (nothing tank-treaded), downwards for
    // tumbling (something tank-treaded, nothing tumbled).
    if (!b.gammaHi && (b.gammaLo || !b.intermittentRates.empty())) return 2.0 * hi;
    if (b.gammaHi && !b.gammaLo) return 0.5 * lo;
    return std::nullopt;
}

ScatterComparison compareWithScatter(double x, double predicted, const ExperimentalPoints& data, double factor) {
    ScatterComparison c;
    c.window = fmt::format("data at x in [{:.3g}, {:.3g}] (factor {:g})", x / factor, x * factor, factor);
    c.lo = std::numeric_limits<double>::infinity();
    c.hi = -c.lo;
    for (std::size_t k = 0; k < data.x.size(); ++k)
        if (data.x[k] >= x / factor && data.x[k] <= x * factor)
            for (double y : data.y[k]) c.lo = std::min(c.lo, y), c.hi = std::max(c.hi, y), ++c.points;
    if (c.points == 0) {
        c.verdict = "no data";
        c.lo = c.hi = 0.0;
        return c;
    }
    c.verdict = std::isfinite(predicted) && predicted >= c.lo && predicted <= c.hi ? "inside" : "outside";
    return c;
}

ScatterComparison compareInterval(double x, std::optional<double> lo, std::optional<double> hi, const ExperimentalPoints& data,
                                  double tolerance) {
    ScatterComparison c;
    c.window = fmt::format("data at x within {:g} % of {:g}", 100.0 * tolerance, x);
    c.lo = std::numeric_limits<double>::infinity();
    c.hi = -c.lo;
    for (std::size_t k = 0; k < data.x.size(); ++k)
        if (std::abs(data.x[k] - x) <= tolerance * x)
            for (double y : data.y[k]) c.lo = std::min(c.lo, y), c.hi = std::max(c.hi, y), ++c.points;
    if (c.points == 0) {
        c.verdict = "no data";
        c.lo = c.hi = 0.0;
        return c;
    }
    if (!lo || !hi) {  // a one-sided bound is no prediction of the threshold
        c.verdict = "not bracketed";
        return c;
    }
    if (*lo > *hi) {  // tumbling above tank-treading
        c.verdict = "not monotone";
        return c;
    }
    c.verdict = *lo <= c.hi && *hi >= c.lo ? "inside" : "outside";
    return c;
}

ScatterComparison compareWithBand(double x, double predicted, const ExperimentalPoints& data) {
    ScatterComparison c;
    c.window = "band [l_low, l_high] interpolated linearly in log v between the data rows";
    std::vector<std::size_t> order(data.x.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return data.x[a] < data.x[b]; });
    for (std::size_t k = 0; k + 1 < order.size(); ++k) {
        const std::size_t a = order[k], b = order[k + 1];
        if (!(x >= data.x[a] && x <= data.x[b]) || data.y[a].size() < 3 || data.y[b].size() < 3) continue;
        const double w = data.x[b] > data.x[a] ? std::log(x / data.x[a]) / std::log(data.x[b] / data.x[a]) : 0.0;
        const double high = (1 - w) * data.y[a][1] + w * data.y[b][1], low = (1 - w) * data.y[a][2] + w * data.y[b][2];
        c.lo = std::min(low, high);
        c.hi = std::max(low, high);
        c.points = 2;
        c.verdict = std::isfinite(predicted) && predicted >= c.lo && predicted <= c.hi ? "inside" : "outside";
        return c;
    }
    c.verdict = "no data";
    return c;
}

std::pair<std::optional<double>, std::optional<double>> criticalStressInterval(const ThresholdBracket& b, double etaOut) {
    std::optional<double> lo, hi;
    if (b.gammaLo) lo = shearStressPa(etaOut, *b.gammaLo);
    if (b.gammaHi) hi = shearStressPa(etaOut, *b.gammaHi);
    return {lo, hi};
}

ValidationEvidence::ValidationEvidence(const fs::path& dataDir) : dataDir_(dataDir), data_(readValidationDataSets(dataDir)) {
    for (const auto& [s, points] : data_) {
        judged_.push_back(s.judged ? withoutBlanks(points) : ExperimentalPoints{});
        if (s.judged && s.observable == "critical_stress_Pa") {
            critical_.x.insert(critical_.x.end(), judged_.back().x.begin(), judged_.back().x.end());
            critical_.y.insert(critical_.y.end(), judged_.back().y.begin(), judged_.back().y.end());
        }
    }
    if (critical_.x.empty()) throw InputError(fmt::format("the validation data {} have no critical stresses", dataDir.string()));
}

const ExperimentalPoints* ValidationEvidence::judged(const std::string& observable, std::optional<double> etaOut) const {
    for (std::size_t i = 0; i < data_.size(); ++i) {
        const ValidationDataSet& s = data_[i].set;
        if (s.judged && s.observable == observable && (!etaOut || s.etaOutMPaS == *etaOut)) return &judged_[i];
    }
    return nullptr;
}

const ExperimentalPoints& ValidationEvidence::required(const std::string& observable) const {
    const ExperimentalPoints* d = judged(observable);
    if (!d) throw InputError(fmt::format("the validation data {} have no set of {}", dataDir_.string(), observable));
    return *d;
}

std::optional<ScatterComparison> ValidationEvidence::inclination(double etaOut, double rate, double angle, const std::string& regime) const {
    const ExperimentalPoints* d = judged("inclination_deg", etaOut);
    if (!d) return std::nullopt;
    ScatterComparison s = compareWithScatter(rate, angle, *d, 1.5);
    if (regime == "tank-treading" && !std::isfinite(angle) && s.points > 0) s.verdict = "no prediction";
    return s;
}

ScatterComparison ValidationEvidence::tankTreadingFrequency(double rate, double ttf, const std::string& regime) const {
    ScatterComparison s = compareWithScatter(rate, ttf, required("ttf_4pi_f_over_rate"), 1.25);
    if (regime == "tank-treading" && !std::isfinite(ttf) && s.points > 0) s.verdict = "no prediction";  // TTF undefined
    return s;
}

ScatterComparison ValidationEvidence::tubeVelocity(double pressureGradient, double velocity) const {
    return compareWithScatter(pressureGradient, velocity, required("velocity_cm_per_s"), 1.25);
}

ScatterComparison ValidationEvidence::tubeLength(double velocity, double length) const {
    return compareWithBand(velocity, length, required("length_um"));
}

ScatterComparison ValidationEvidence::criticalStress(double etaOut, std::optional<double> tauLo, std::optional<double> tauHi) const {
    return compareInterval(etaOut, tauLo, tauHi, critical_, 0.1);
}

std::string shortenedReason(const std::string& reason, std::size_t limit) {
    std::string line = reason.substr(0, reason.find('\n'));
    if (line.size() <= limit) return line;
    std::size_t cut = line.rfind(' ', limit);
    if (cut == std::string::npos || cut < limit / 2) cut = limit;  // one long word: cut it
    return line.substr(0, cut) + " ...";
}

}  // namespace trbc
