#include "inference/rbc_problem.hpp"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <numbers>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/hash.hpp"
#include "core/output_dir.hpp"
#include "surrogate/surrogate.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
const double kHalfLog2Pi = 0.5 * std::log(2.0 * std::numbers::pi);

/// InputError "<file>:<line>: column '<c>' = <value> is out of range: <range>".
[[noreturn]] void outOfRange(const NumericTable& t, Eigen::Index row, const std::string& column, double value,
                             const char* range) {
    throw InputError(fmt::format("{}:{}: column '{}' = {} is out of range: {}", t.path.string(),
                                 t.lines[static_cast<std::size_t>(row)], column, value, range));
}

void requireRows(const NumericTable& t, Eigen::Index minRows, const char* what) {
    if (t.values.rows() < minRows)
        throw InputError(fmt::format("{}: {} data row(s), need at least {} ({})", t.path.string(), t.values.rows(), minRows, what));
}

}  // namespace

const char* experimentName(RbcExperiment e) {
    switch (e) {
        case RbcExperiment::Equilibrium: return "equilibrium";
        case RbcExperiment::Stretching: return "stretching";
        case RbcExperiment::Relaxation: return "relaxation";
        case RbcExperiment::Flow: return "flow";
    }
    return "?";
}

// ------------------------------------------------------------------------------------------------
// Data

RbcDataSet readEquilibriumData(const fs::path& file, std::string name) {
    const NumericTable t = readNumericTable(file, {"mean_um", "sd_um"}, {"sd_um"});
    const Eigen::VectorXd mean = t.column("mean_um", "population mean in um");
    const Eigen::VectorXd sd = t.find("sd_um") >= 0 ? t.column("sd_um") : Eigen::VectorXd::Constant(mean.size(), NAN);
    const int q = t.find("quantity");
    if (q < 0)
        throw InputError(fmt::format("{}: missing column 'quantity' (D, hmin or hmax) (columns found: {})", file.string(),
                                     fmt::join(t.columns, ", ")));
    // The text column is not kept by readNumericTable: read it from the same lines.
    std::vector<std::string> lines;
    {
        std::ifstream in(file);
        std::string line;
        while (std::getline(in, line)) lines.push_back(line);
    }
    RbcDataSet d;
    d.name = std::move(name);
    d.experiment = RbcExperiment::Equilibrium;
    d.file = file;
    d.contentHash = fileFingerprint(file);
    const char* names[3] = {"D", "hmin", "hmax"};
    bool found[3] = {false, false, false};
    for (Eigen::Index r = 0; r < mean.size(); ++r) {
        const long lineNo = t.lines[static_cast<std::size_t>(r)];
        const std::string quantity = splitList(lines.at(static_cast<std::size_t>(lineNo - 1))).at(static_cast<std::size_t>(q));
        int k = -1;
        for (int i = 0; i < 3; ++i)
            if (quantity == names[i]) k = i;
        if (k < 0)
            throw InputError(fmt::format("{}:{}: column 'quantity' = '{}' is not one of D, hmin, hmax", file.string(), lineNo, quantity));
        if (found[k]) throw InputError(fmt::format("{}:{}: quantity '{}' appears twice", file.string(), lineNo, quantity));
        if (!(mean[r] > 0.0)) outOfRange(t, r, "mean_um", mean[r], "a mean dimension must be > 0 um");
        if (!std::isnan(sd[r]) && !(sd[r] >= 0.0 && std::isfinite(sd[r])))
            outOfRange(t, r, "sd_um", sd[r], "a standard deviation must be finite and >= 0 um, or blank");
        found[k] = true;
        d.shape[k] = mean[r];
        d.shapeSd[k] = sd[r];
    }
    for (int k = 0; k < 3; ++k)
        if (!found[k]) throw InputError(fmt::format("{}: missing the row with quantity '{}'", file.string(), names[k]));
    return d;
}

RbcDataSet readStretchingData(const fs::path& file, std::string name) {
    const NumericTable t = readNumericTable(file, {"Fext", "D0", "D1"});
    RbcDataSet d;
    d.name = std::move(name);
    d.experiment = RbcExperiment::Stretching;
    d.file = file;
    d.contentHash = fileFingerprint(file);
    d.force = t.column("Fext", "bead force in pN");
    d.d0 = t.column("D0", "transverse diameter in um");
    d.d1 = t.column("D1", "axial diameter in um");
    requireRows(t, 1, "one row per force");
    for (Eigen::Index r = 0; r < d.force.size(); ++r) {
        if (!(d.force[r] >= 0.0)) outOfRange(t, r, "Fext", d.force[r], "the force must be >= 0 pN");
        // The stretching surrogate is trained on Fext in the prior box only; beyond it its D0 and D1
        // are extrapolations that would enter the likelihood unnoticed.
        if (d.force[r] > kPriorFext.hi)
            outOfRange(t, r, "Fext", d.force[r],
                       fmt::format("the surrogates are trained on [{:g}, {:g}] pN only (drop the row, or train a surrogate on a "
                                   "campaign over a wider force box)",
                                   kPriorFext.lo, kPriorFext.hi)
                           .c_str());
        if (!(d.d0[r] > 0.0)) outOfRange(t, r, "D0", d.d0[r], "a diameter must be > 0 um");
        if (!(d.d1[r] > 0.0)) outOfRange(t, r, "D1", d.d1[r], "a diameter must be > 0 um");
    }
    return d;
}

RbcDataSet readRelaxationData(const fs::path& file, std::string name) {
    const NumericTable t = readNumericTable(file, {"t", "L_W"});
    RbcDataSet d;
    d.name = std::move(name);
    d.experiment = RbcExperiment::Relaxation;
    d.file = file;
    d.contentHash = fileFingerprint(file);
    d.time = t.column("t", "time since release in s");
    d.aspect = t.column("L_W", "length over width");
    requireRows(t, 2, "a relaxation curve");
    for (Eigen::Index r = 0; r < d.time.size(); ++r) {
        if (!(d.time[r] >= 0.0)) outOfRange(t, r, "t", d.time[r], "the time must be >= 0 s");
        if (!(d.aspect[r] > 0.0)) outOfRange(t, r, "L_W", d.aspect[r], "L/W must be > 0");
    }
    return d;
}

RbcDataSet flowRbcDataSet(FlowDataSet flow) {
    RbcDataSet d;
    d.name = flow.name;
    d.experiment = RbcExperiment::Flow;
    // One file: that file; several (a donor's four viscosities): their folder, and the fingerprint of all.
    if (!flow.files.empty()) {
        d.file = flow.files.size() == 1 ? flow.files.front() : flow.files.front().parent_path();
        std::vector<std::string> prints;
        for (const fs::path& f : flow.files) prints.push_back(fileFingerprint(f));
        d.contentHash = prints.size() == 1 ? prints.front() : fingerprintOf(prints);
    }
    d.flow = std::make_shared<const FlowDataSet>(std::move(flow));
    return d;
}

namespace {

/// Why P cannot be used as a data path ("does not exist", "cannot be read: ..."), or "" when it
/// exists. The error_code overloads: a path the filesystem refuses (too long, no permission) is bad
/// input like a missing one, not a std::filesystem_error.
std::string missingReason(const fs::path& p, bool directory) {
    std::error_code ec;
    const bool ok = directory ? fs::is_directory(p, ec) : fs::exists(p, ec);
    if (ok) return "";
    const bool absent = !ec || ec == std::errc::no_such_file_or_directory || ec == std::errc::not_a_directory;
    return absent ? std::string("does not exist") : "cannot be read: " + ec.message();
}

/// DIR/datasets.json: [{"name": ..., "experiment": "equilibrium|stretching|relaxation", "file": ...}, ...],
/// files relative to DIR (written by `trbc calibrate`, which copies the configured CSVs there).
std::vector<RbcDataSet> loadManifest(const fs::path& dir) {
    const fs::path manifest = dir / kRbcDataManifest;
    nlohmann::json j;
    try {
        std::ifstream f(manifest);
        j = nlohmann::json::parse(f);
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: not valid JSON: {}", manifest.string(), e.what()));
    }
    if (!j.is_array() || j.empty())
        throw InputError(fmt::format("{}: must be a non-empty array of {{name, experiment, file}}", manifest.string()));
    std::vector<RbcDataSet> sets;
    for (const nlohmann::json& e : j) {
        if (!e.is_object() || !e.contains("name") || !e.contains("experiment") || !e.contains("file") || !e["name"].is_string() ||
            !e["experiment"].is_string() || !e["file"].is_string())
            throw InputError(fmt::format("{}: every entry needs string fields name, experiment, file", manifest.string()));
        const std::string name = e["name"], exp = e["experiment"];
        // The name becomes a directory and a CSV/Markdown field: checked here, where infer reads it.
        checkFileName(name, manifest.string() + ": data set name");
        fs::path file = e["file"].get<std::string>();
        if (file.is_relative()) file = dir / file;
        if (const std::string why = missingReason(file, false); !why.empty())
            throw InputError(fmt::format("{}: data set '{}': file {} {}", manifest.string(), name, file.string(), why));
        if (exp == "equilibrium")
            sets.push_back(readEquilibriumData(file, name));
        else if (exp == "stretching")
            sets.push_back(readStretchingData(file, name));
        else if (exp == "relaxation")
            sets.push_back(readRelaxationData(file, name));
        else
            throw InputError(fmt::format("{}: data set '{}': experiment '{}' is not one of equilibrium, stretching, relaxation",
                                         manifest.string(), name, exp));
        for (std::size_t k = 0; k + 1 < sets.size(); ++k)
            if (sets[k].name == name) throw InputError(fmt::format("{}: data set name '{}' appears twice", manifest.string(), name));
    }
    return sets;
}

}  // namespace

std::vector<RbcDataSet> loadRbcDataSets(const fs::path& dir) {
    if (const std::string why = missingReason(dir, true); !why.empty())
        throw InputError(fmt::format("experimental data directory '{}' {} (it must contain equilibrium/, stretching/ and "
                                     "relaxation/, or a {}; see data/README.md)",
                                     dir.string(), why, kRbcDataManifest));
    if (missingReason(dir / kRbcDataManifest, false).empty()) return loadManifest(dir);
    for (const fs::path& rel : {fs::path("equilibrium/evans_fung_1972.csv"), fs::path("stretching/mills_2004/mills_2004.csv"),
                               fs::path("stretching/suresh_2005/suresh_2005.csv"), fs::path("relaxation/hochmuth_1979/1.csv")})
        if (const std::string why = missingReason(dir / rel, false); !why.empty())
            throw InputError(fmt::format("experimental data directory '{}': {} {} (docs/BAYESIAN_INFERENCE.md, data/README.md)", dir.string(),
                                         rel.string(), why));
    std::vector<RbcDataSet> sets;
    sets.push_back(readEquilibriumData(dir / "equilibrium" / "evans_fung_1972.csv", "evans_fung_1972"));
    sets.push_back(readStretchingData(dir / "stretching" / "mills_2004" / "mills_2004.csv", "mills_2004"));
    sets.push_back(readStretchingData(dir / "stretching" / "suresh_2005" / "suresh_2005.csv", "suresh_2005"));
    for (int c = 1; c <= 4; ++c)
        sets.push_back(readRelaxationData(dir / "relaxation" / "hochmuth_1979" / fmt::format("{}.csv", c),
                                          fmt::format("hochmuth_1979_cell{}", c)));
    return sets;
}

// ------------------------------------------------------------------------------------------------
// Forward models

RbcModel surrogateRbcModel(std::shared_ptr<const Surrogate> s) {
    RbcModel m;
    m.equilibrium = [s](const Eigen::MatrixXd& x) { return s->equilibriumOutputs(x); };
    m.stretching = [s](const Eigen::MatrixXd& x) { return s->stretchingOutputs(x); };
    m.relaxationTime = [s](const Eigen::MatrixXd& x) { return s->relaxationTime(x); };
    return m;
}

RbcModel timedModel(RbcModel model, std::shared_ptr<ModelTimer> timer) {
    using Clock = std::chrono::steady_clock;
    // One wrapper for every callback (the flow ones take the cytosol too); an empty one stays empty,
    // so that a model without flow networks is still seen to lack them.
    auto timed = [timer](auto f) -> decltype(f) {
        if (!f) return f;
        return [timer, f](const Eigen::MatrixXd& x, const auto&... rest) {
            const auto t0 = Clock::now();
            auto y = f(x, rest...);
            timer->seconds += std::chrono::duration<double>(Clock::now() - t0).count();
            timer->evaluations += x.cols();
            return y;
        };
    };
    RbcModel m;
    m.equilibrium = timed(model.equilibrium);
    m.stretching = timed(model.stretching);
    m.relaxationTime = timed(model.relaxationTime);
    m.flow.tankTreading = timed(model.flow.tankTreading);
    m.flow.criticalStressPa = timed(model.flow.criticalStressPa);
    return m;
}

// ------------------------------------------------------------------------------------------------
// Parameters and priors

const std::vector<std::string>& RbcPriorBox::parameterNames() {
    static const std::vector<std::string> names = {"v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"};
    return names;
}

namespace {
/// The bound pair of a parameter and its factor from inference to physical units.
std::pair<double*, double*> boxBounds(RbcPriorBox& b, const std::string& name, double& scale) {
    scale = 1.0;
    if (name == "v") return {&b.vLo, &b.vHi};
    if (name == "mu_uN_per_m") return {&b.muLo, &b.muHi};
    if (name == "kb_J") return scale = kJoulePerKbUnit, std::pair{&b.kbLo, &b.kbHi};
    if (name == "b2") return {&b.b2Lo, &b.b2Hi};
    if (name == "etam_Pa_s_um") return {&b.etamLo, &b.etamHi};
    throw InputError(fmt::format("unknown prior parameter '{}' (valid: v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um)", name));
}
}  // namespace

std::pair<double, double> RbcPriorBox::bounds(const std::string& name) const {
    double scale = 1.0;
    RbcPriorBox copy = *this;
    const auto [lo, hi] = boxBounds(copy, name, scale);
    return {*lo * scale, *hi * scale};
}

void RbcPriorBox::set(const std::string& name, double lo, double hi) {
    const auto [dlo, dhi] = RbcPriorBox{}.bounds(name);
    if (!(std::isfinite(lo) && std::isfinite(hi) && lo < hi && lo >= dlo * (1 - 1e-12) && hi <= dhi * (1 + 1e-12)))
        throw InputError(fmt::format("prior of {}: [{:g}, {:g}] is out of range: it must satisfy lo < hi inside the surrogates' "
                                     "training box [{:.10g}, {:.10g}] (docs/CAMPAIGN_AND_SURROGATE.md, input box; a prior may be narrowed, not widened)",
                                     name, lo, hi, dlo, dhi));
    double scale = 1.0;
    const auto [plo, phi] = boxBounds(*this, name, scale);
    *plo = std::max(lo, dlo) / scale;  // the tolerance above must not widen the box
    *phi = std::min(hi, dhi) / scale;
}

const std::vector<std::string>& phase1ParameterNames(RbcExperiment e) {
    static const std::vector<std::string> eq = {"v", "FvK", "sigma"};
    static const std::vector<std::string> st = {"v", "mu", "kb", "b2", "sigma0", "sigma1"};
    static const std::vector<std::string> re = {"r", "sigma_tc", "tc", "z0", "zinf", "sigma_z"};
    if (e == RbcExperiment::Flow) return flowParameterNames();
    return e == RbcExperiment::Equilibrium ? eq : e == RbcExperiment::Stretching ? st : re;
}

const std::vector<std::string>& phase1OutputNames(RbcExperiment e) {
    static const std::vector<std::string> eq = {"v", "FvK", "sigma_rel"};
    static const std::vector<std::string> st = {"v", "mu_uN_per_m", "kb_J", "b2", "sigma0_um", "sigma1_um"};
    static const std::vector<std::string> re = {"etam_over_mu_s", "sigma_tc_rel", "tc_s", "z0", "zinf", "sigma_z"};
    // An inclination set's; a set of a relative observable names its noise sigma_rel (below).
    static const std::vector<std::string> fl = {"v", "mu_uN_per_m", "kb_J", "b2", "etam_over_mu_s", "sigma_deg"};
    if (e == RbcExperiment::Flow) return fl;
    return e == RbcExperiment::Equilibrium ? eq : e == RbcExperiment::Stretching ? st : re;
}

std::vector<std::string> phase1OutputNames(const RbcDataSet& d) {
    std::vector<std::string> names = phase1OutputNames(d.experiment);
    if (d.experiment == RbcExperiment::Flow && d.flow && d.flow->observable != FlowObservable::Inclination) names.back() = "sigma_rel";
    return names;
}

Eigen::VectorXd phase1OutputScale(RbcExperiment e) {
    Eigen::VectorXd s = Eigen::VectorXd::Ones(static_cast<Eigen::Index>(phase1ParameterNames(e).size()));
    if (e == RbcExperiment::Stretching || e == RbcExperiment::Flow) s[2] = kJoulePerKbUnit;
    return s;
}

std::shared_ptr<const ProductPrior> phase1Prior(const RbcDataSet& d) {
    const RbcPriorBox& b = d.prior;
    switch (d.experiment) {
        case RbcExperiment::Equilibrium:  // 3.1: v, FvK ~ p_RU (mu in [1, 10] over kb/R_A^2 in [0.01, 0.1]), sigma
            return std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{
                uniformPrior(b.vLo, b.vHi), ratioUniformPrior(b.muLo, b.muHi, 0.01 * b.kbLo / kKbLow, 0.01 * b.kbHi / kKbLow),
                uniformPrior(0.0, 0.5)});
        case RbcExperiment::Stretching:  // 3.2
            return std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{
                uniformPrior(b.vLo, b.vHi), uniformPrior(b.muLo, b.muHi), uniformPrior(b.kbLo, b.kbHi), uniformPrior(b.b2Lo, b.b2Hi),
                uniformPrior(0.0, 2.0), uniformPrior(0.0, 2.0)});
        case RbcExperiment::Relaxation: {  // 3.3: r ~ p_RU (etam in [0.1, 1] over mu in [1, 10])
            if (d.aspect.size() < 1) throw InputError(fmt::format("relaxation data set {} has no rows", d.name));
            const double y1 = d.aspect[0];
            return std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{
                ratioUniformPrior(b.etamLo, b.etamHi, b.muLo, b.muHi), uniformPrior(0.0, 0.05), uniformPrior(0.05, 0.5),
                uniformPrior(y1 - 0.2, y1 + 0.2), uniformPrior(0.8, 1.5), uniformPrior(0.0, 0.5)});
        }
        case RbcExperiment::Flow: {
            if (!d.flow) throw InputError(fmt::format("flow data set {} has no observations", d.name));
            const double sigmaHi = d.flow->observable == FlowObservable::Inclination ? 5.0 : 2.0;
            return std::make_shared<ProductPrior>(std::vector<ScalarPriorPtr>{
                uniformPrior(b.vLo, b.vHi), uniformPrior(b.muLo, b.muHi), uniformPrior(b.kbLo, b.kbHi), uniformPrior(b.b2Lo, b.b2Hi),
                uniformPrior(b.etamLo / b.muHi, b.etamHi / b.muLo), uniformPrior(0.0, sigmaHi)});
        }
    }
    throw InputError("phase1Prior: unknown experiment");
}

// ------------------------------------------------------------------------------------------------
// Likelihoods

double normalLogPdf(double y, double m, double s) {
    if (!(s > 0.0)) return -kInf;
    const double z = (y - m) / s;
    return -0.5 * z * z - std::log(s) - kHalfLog2Pi;
}

namespace {

void expectRows(const Eigen::MatrixXd& theta, Eigen::Index rows, const RbcDataSet& d) {
    if (theta.rows() != rows)
        throw InputError(fmt::format("{} likelihood ({}): theta needs {} rows, got {}", experimentName(d.experiment), d.name,
                                     rows, theta.rows()));
}

void expectOutput(const Eigen::MatrixXd& y, Eigen::Index rows, Eigen::Index cols, const char* what) {
    if (y.rows() != rows || y.cols() != cols)
        throw InputError(fmt::format("{} model returned {} x {}, expected {} x {}", what, y.rows(), y.cols(), rows, cols));
}

}  // namespace

Eigen::VectorXd equilibriumLogLikelihood(const RbcModel& model, const RbcDataSet& d, const Eigen::MatrixXd& theta) {
    expectRows(theta, 3, d);
    const Eigen::Index n = theta.cols();
    const Eigen::MatrixXd f = model.equilibrium(theta.topRows(2));  // (D, hmin, hmax) at (v, FvK)
    expectOutput(f, 3, n, "equilibrium");
    Eigen::VectorXd ll(n);
    for (Eigen::Index i = 0; i < n; ++i) {
        const double sigma = theta(2, i);  // relative error, one for the three observables
        double s = 0.0;
        for (int k = 0; k < 3; ++k) s += normalLogPdf(d.shape[k], f(k, i), std::abs(sigma * f(k, i)));
        ll[i] = s;
    }
    return ll;
}

Eigen::VectorXd stretchingLogLikelihood(const RbcModel& model, const RbcDataSet& d, const Eigen::MatrixXd& theta) {
    expectRows(theta, 6, d);
    const Eigen::Index n = theta.cols(), J = d.force.size();
    // One batch: column i J + j = candidate i at force j; FvK = mu R_A^2 / kb.
    Eigen::MatrixXd x(5, n * J);
    for (Eigen::Index i = 0; i < n; ++i) {
        const double fvk = fvkFromModuli(theta(1, i), theta(2, i));
        for (Eigen::Index j = 0; j < J; ++j) x.col(i * J + j) << theta(0, i), theta(1, i), fvk, theta(3, i), d.force[j];
    }
    const Eigen::MatrixXd D = model.stretching(x);
    expectOutput(D, 2, n * J, "stretching");
    Eigen::VectorXd ll(n);
    for (Eigen::Index i = 0; i < n; ++i) {
        const double s0 = theta(4, i), s1 = theta(5, i);  // absolute errors (um), one per diameter
        double s = 0.0;
        for (Eigen::Index j = 0; j < J; ++j)
            s += normalLogPdf(d.d0[j], D(0, i * J + j), s0) + normalLogPdf(d.d1[j], D(1, i * J + j), s1);
        ll[i] = s;
    }
    return ll;
}

double hochmuthAspect(double t, double tc, double z0, double zinf) {
    if (z0 == zinf) return zinf;
    const double lambda = (z0 + zinf) / (z0 - zinf), e = std::exp(-t / tc);
    return zinf * (lambda + e) / (lambda - e);
}

Eigen::VectorXd relaxationLogLikelihood(const RbcModel& model, const RbcDataSet& d, const Eigen::MatrixXd& theta) {
    expectRows(theta, 6, d);
    const Eigen::Index n = theta.cols();
    // tc_sim(r) = r g(v = 0.95, mu = 4, FvK = 250, b2 = 1.6, etam = 4 r): the model returns g etam / mu = g r.
    Eigen::MatrixXd x(5, n);
    for (Eigen::Index i = 0; i < n; ++i)
        x.col(i) << kRelaxationV, kRelaxationMu, kRelaxationFvK, kRelaxationB2, kRelaxationMu * theta(0, i);
    const Eigen::VectorXd tcSim = model.relaxationTime(x);
    expectOutput(tcSim, n, 1, "relaxation");
    Eigen::VectorXd ll(n);
    for (Eigen::Index i = 0; i < n; ++i) {
        const double sigmaTc = theta(1, i), tc = theta(2, i), z0 = theta(3, i), zinf = theta(4, i), sigmaZ = theta(5, i);
        double s = normalLogPdf(tc, tcSim[i], sigmaTc * tc);  // relative error on the latent tc
        for (Eigen::Index k = 0; k < d.time.size(); ++k) s += normalLogPdf(d.aspect[k], hochmuthAspect(d.time[k], tc, z0, zinf), sigmaZ);
        ll[i] = s;
    }
    return ll;
}

Eigen::VectorXd rbcLogLikelihood(const RbcModel& model, const RbcDataSet& d, const Eigen::MatrixXd& theta) {
    switch (d.experiment) {
        case RbcExperiment::Equilibrium: return equilibriumLogLikelihood(model, d, theta);
        case RbcExperiment::Stretching: return stretchingLogLikelihood(model, d, theta);
        case RbcExperiment::Relaxation: return relaxationLogLikelihood(model, d, theta);
        case RbcExperiment::Flow:
            if (!d.flow || !model.flow.tankTreading || !model.flow.criticalStressPa)
                throw InputError(fmt::format("flow data set {}: no {}", d.name, d.flow ? "flow networks in the model" : "observations"));
            return flowLogLikelihood(model.flow, *d.flow, theta);
    }
    throw InputError("rbcLogLikelihood: unknown experiment");
}

TmcmcProblem phase1Problem(const RbcModel& model, const RbcDataSet& data) {
    TmcmcProblem p;
    p.prior = phase1Prior(data);
    p.batchLogLikelihood = [model, data](const Eigen::MatrixXd& theta) { return rbcLogLikelihood(model, data, theta); };
    return p;
}

RbcSamplerSettings rbcSamplerSettings(RbcRun run, RbcExperiment e) {
    switch (run) {
        case RbcRun::Phase1:
            if (e == RbcExperiment::Flow) return RbcSamplerSettings{0.4, 0.06, 4000};
            return e == RbcExperiment::Equilibrium ? RbcSamplerSettings{0.3, 0.08} : RbcSamplerSettings{0.4, 0.06};
        case RbcRun::Phase2:
        case RbcRun::Phase3a: return {0.4, 0.06};
        case RbcRun::Phase3b:
            return e == RbcExperiment::Stretching ? RbcSamplerSettings{0.8, 0.04} : RbcSamplerSettings{0.6, 0.04};
    }
    return {};
}

}  // namespace trbc
