#include "analysis/prediction.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <random>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "experiments/experiments.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

double mixtureStdNormalCdf(double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); }

std::string fmtNum(double x) { return fmt::format("{:.8g}", x); }

/// Stretching network inputs of the posterior samples at one force: (v, mu, FvK, b2, F).
Eigen::MatrixXd stretchingInputs(const PosteriorSamples& s, double force) {
    const Eigen::Index n = s.values.cols();
    Eigen::MatrixXd x(5, n);
    for (Eigen::Index k = 0; k < n; ++k) {
        const double mu = s.values(1, k), kb = s.values(2, k) / kJoulePerKbUnit;
        x(0, k) = s.values(0, k);
        x(1, k) = mu;
        x(2, k) = fvkFromModuli(mu, kb);
        x(3, k) = s.values(3, k);
        x(4, k) = force;
    }
    return x;
}

Eigen::MatrixXd equilibriumInputs(const PosteriorSamples& s) {
    Eigen::MatrixXd x(2, s.values.cols());
    x.row(0) = s.values.row(0);
    x.row(1) = s.values.row(1);
    return x;
}

Eigen::MatrixXd relaxationInputs(const PosteriorSamples& s) {
    const Eigen::Index n = s.values.cols();
    Eigen::MatrixXd x(5, n);
    for (Eigen::Index k = 0; k < n; ++k)
        x.col(k) << kRelaxationV, kRelaxationMu, kRelaxationFvK, kRelaxationB2, kRelaxationMu * s.values(0, k);
    return x;
}

double meanOf(const Eigen::VectorXd& v) { return v.size() ? v.mean() : 0.0; }
double sdOf(const Eigen::VectorXd& v) {
    if (v.size() < 1) return 0.0;
    const double m = v.mean();
    return std::sqrt((v.array() - m).square().mean());
}

std::string outsideDescription(const CoveragePoint& c, const std::string& xName) {
    const std::string where = xName.empty() ? c.observable : fmt::format("{} at {} = {:.4g}", c.observable, xName, c.x);
    return c.y < c.q05 ? fmt::format("{}: {:.5g} < q05 {:.5g}", where, c.y, c.q05)
                       : fmt::format("{}: {:.5g} > q95 {:.5g}", where, c.y, c.q95);
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Mixtures

double normalMixtureCdf(const Eigen::VectorXd& m, const Eigen::VectorXd& s, double y) {
    if (m.size() == 0) return 0.0;
    double sum = 0.0;
    for (Eigen::Index k = 0; k < m.size(); ++k) sum += s[k] > 0 ? mixtureStdNormalCdf((y - m[k]) / s[k]) : (y >= m[k] ? 1.0 : 0.0);
    return sum / static_cast<double>(m.size());
}

double normalMixtureDensity(const Eigen::VectorXd& m, const Eigen::VectorXd& s, double y) {
    if (m.size() == 0) return 0.0;
    constexpr double c = 0.3989422804014327;  // 1 / sqrt(2 pi)
    double sum = 0.0;
    for (Eigen::Index k = 0; k < m.size(); ++k)
        if (s[k] > 0) {
            const double z = (y - m[k]) / s[k];
            sum += c * std::exp(-0.5 * z * z) / s[k];
        }
    return sum / static_cast<double>(m.size());
}

double normalMixtureQuantile(const Eigen::VectorXd& m, const Eigen::VectorXd& s, double q, double tol) {
    if (!(q > 0.0 && q < 1.0)) throw InputError(fmt::format("mixture quantile: level {} is outside (0, 1)", q));
    if (m.size() == 0 || m.size() != s.size()) throw InputError("mixture quantile: empty mixture or sizes differ");
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (Eigen::Index k = 0; k < m.size(); ++k) {
        const double w = s[k] > 0 ? 12.0 * s[k] : 0.0;
        lo = std::min(lo, m[k] - w);
        hi = std::max(hi, m[k] + w);
    }
    if (!std::isfinite(lo) || !std::isfinite(hi))
        throw InputError("mixture quantile: non-finite component (mean or standard deviation)");
    if (hi <= lo) return lo;  // all point masses at one value
    if (!(tol > 0)) tol = 1e-9 * (hi - lo);
    // Bisection on the CDF, accelerated by Newton steps where they stay inside the bracket.
    // Invariant: CDF(lo) < q <= CDF(hi) (CDF(lo) ~ 1e-33, CDF(hi) = 1 - 1e-33).
    constexpr double c = 0.3989422804014327;  // 1 / sqrt(2 pi)
    const double n = static_cast<double>(m.size());
    double x = 0.5 * (lo + hi);
    for (int it = 0; it < 400 && hi - lo > tol; ++it) {
        double cdf = 0.0, pdf = 0.0;
        for (Eigen::Index k = 0; k < m.size(); ++k) {
            if (s[k] > 0) {
                const double z = (x - m[k]) / s[k];
                cdf += mixtureStdNormalCdf(z);
                pdf += c * std::exp(-0.5 * z * z) / s[k];
            } else {
                cdf += x >= m[k] ? 1.0 : 0.0;
            }
        }
        cdf /= n;
        pdf /= n;
        if (cdf < q)
            lo = x;
        else
            hi = x;
        const double step = pdf > 0 ? (q - cdf) / pdf : 0.0;
        const double newton = x + step;
        if (pdf > 0 && newton > lo && newton < hi) {
            if (std::abs(step) <= 0.5 * tol) return newton;
            x = newton;
        } else {
            x = 0.5 * (lo + hi);
        }
    }
    return 0.5 * (lo + hi);
}

const std::vector<double>& predictiveLevels() {
    static const std::vector<double> q = {0.005, 0.05, 0.125, 0.25, 0.5, 0.75, 0.875, 0.95, 0.995};
    return q;
}

std::string levelSuffix(double q) {
    // 0.005 -> q005, 0.05 -> q05, 0.125 -> q125, 0.5 -> q50, 0.995 -> q995
    std::string digits = fmt::format("{:.3f}", q).substr(2);  // "005", "050", "125", "500", "995"
    while (digits.size() > 2 && digits.back() == '0') digits.pop_back();
    return "q" + digits;
}

double PredictiveSummary::q05() const { return quantiles[1]; }
double PredictiveSummary::q95() const { return quantiles[7]; }

PredictiveSummary summarizeMixture(const Eigen::VectorXd& m, const Eigen::VectorXd& s) {
    PredictiveSummary r;
    const auto& lv = predictiveLevels();
    r.quantiles.resize(static_cast<Eigen::Index>(lv.size()));
    for (std::size_t i = 0; i < lv.size(); ++i) r.quantiles[static_cast<Eigen::Index>(i)] = normalMixtureQuantile(m, s, lv[i]);
    r.mean = meanOf(m);
    return r;
}

// ------------------------------------------------------------------------------------------------
// Samples

namespace {

/// The header line of a samples.csv (after its # provenance lines), split at the commas.
std::vector<std::string> samplesHeader(const fs::path& file) {
    std::ifstream in(file);
    if (!in) throw InputError(fmt::format("{}: cannot open", file.string()));
    std::string header;
    while (std::getline(in, header))
        if (!header.empty() && header[0] != '#') break;
    return splitList(header);
}

/// A flow data set's samples (trbc infer --datasets all): the whole cell and its noise in degrees or
/// relative, which no single-cell layout has (kb_J and etam_over_mu_s together).
bool isFlowPosterior(const fs::path& file) {
    const std::vector<std::string> cols = samplesHeader(file);
    auto has = [&](const std::string& c) { return std::find(cols.begin(), cols.end(), c) != cols.end(); };
    const std::vector<std::string>& flow = phase1OutputNames(RbcExperiment::Flow);
    for (std::size_t k = 0; k + 1 < flow.size(); ++k)
        if (!has(flow[k])) return false;
    return has("sigma_deg") || has("sigma_rel");
}

}  // namespace

std::vector<fs::path> inferencePosteriorDirectories(const fs::path& base, bool withPhase1, const std::string& option) {
    if (!fs::is_directory(base)) throw InputError(fmt::format("{} {}: not a directory", option, base.string()));
    std::vector<std::string> phases = {"phase3"};
    if (withPhase1) phases.insert(phases.begin(), "phase1");
    std::vector<fs::path> dirs;
    for (const std::string& ph : phases) {
        const fs::path d = base / ph;
        if (!fs::is_directory(d))
            throw InputError(fmt::format("{} {}: no {} directory (run `trbc infer --phase all` first)", option, base.string(), ph));
        std::vector<fs::path> found;
        for (const auto& e : fs::directory_iterator(d))
            if (e.is_directory() && e.path().filename() != "theta_new" && fs::exists(e.path() / "samples.csv") &&
                !isFlowPosterior(e.path() / "samples.csv"))
                found.push_back(e.path());
        std::sort(found.begin(), found.end());
        if (found.empty()) throw InputError(fmt::format("{} {}: no posterior samples in {}", option, base.string(), d.string()));
        dirs.insert(dirs.end(), found.begin(), found.end());
    }
    return dirs;
}

PosteriorSamples readPosteriorSamples(const fs::path& dirOrFile) {
    PosteriorSamples p;
    const bool isDir = fs::is_directory(dirOrFile) || (!fs::exists(dirOrFile) && dirOrFile.extension() != ".csv");
    p.file = isDir ? dirOrFile / "samples.csv" : dirOrFile;
    const fs::path dir = isDir ? dirOrFile : dirOrFile.parent_path();
    if (!fs::is_regular_file(p.file))
        throw InputError(fmt::format("{}: posterior samples not found (run `trbc infer` first; --posterior takes a posterior "
                                     "directory such as DIR/phase3/mills_2004)", p.file.string()));
    const std::vector<std::string> cols = samplesHeader(p.file);
    const std::string header = fmt::format("{}", fmt::join(cols, ","));
    auto has = [&](const std::string& c) { return std::find(cols.begin(), cols.end(), c) != cols.end(); };
    int best = -1, bestCount = 0;
    for (int e = 0; e <= static_cast<int>(RbcExperiment::Flow); ++e) {
        int count = 0;
        for (const std::string& c : phase1OutputNames(static_cast<RbcExperiment>(e))) count += has(c) ? 1 : 0;
        if (count > bestCount) best = e, bestCount = count;
    }
    if (best < 0)
        throw InputError(fmt::format("{}: not posterior samples of a data set: expected the columns of an experiment, e.g. "
                                     "v,mu_uN_per_m,kb_J,b2,sigma0_um,sigma1_um (stretching); got {}",
                                     p.file.string(), header));
    p.experiment = static_cast<RbcExperiment>(best);
    if (p.experiment == RbcExperiment::Flow)
        throw InputError(fmt::format("{}: a flow data set's posterior (trbc infer --datasets); trbc predict predicts the "
                                     "single-cell experiments", p.file.string()));
    p.columns = phase1OutputNames(p.experiment);
    for (const std::string& c : p.columns)
        if (!has(c))
            throw InputError(fmt::format("{}: missing column {} ({} posterior samples need {})", p.file.string(), c,
                                         experimentName(p.experiment), fmt::join(p.columns, ",")));
    const NumericTable t = readNumericTable(p.file, p.columns);
    if (t.values.rows() < 1) throw InputError(fmt::format("{}: no samples", p.file.string()));
    p.values.resize(static_cast<Eigen::Index>(p.columns.size()), t.values.rows());
    for (std::size_t j = 0; j < p.columns.size(); ++j) p.values.row(static_cast<Eigen::Index>(j)) = t.column(p.columns[j]).transpose();
    p.name = fs::absolute(dir).lexically_normal().filename().string();
    if (p.name.empty()) p.name = fs::absolute(dir).lexically_normal().parent_path().filename().string();
    const std::string phase = fs::absolute(dir).lexically_normal().parent_path().filename().string();
    p.label = phase == "phase1" ? "single_" + p.name : phase == "phase3" ? "hierarchical_" + p.name : p.name;
    return p;
}

std::vector<Eigen::Index> subsampleIndices(Eigen::Index total, Eigen::Index n, std::uint64_t seed) {
    std::vector<Eigen::Index> idx(static_cast<std::size_t>(std::max<Eigen::Index>(total, 0)));
    std::iota(idx.begin(), idx.end(), Eigen::Index{0});
    if (n <= 0 || n >= total) return idx;
    std::mt19937_64 rng(seed);
    for (Eigen::Index i = 0; i < n; ++i) {  // partial Fisher-Yates
        std::uniform_int_distribution<Eigen::Index> pick(i, total - 1);
        std::swap(idx[static_cast<std::size_t>(i)], idx[static_cast<std::size_t>(pick(rng))]);
    }
    idx.resize(static_cast<std::size_t>(n));
    std::sort(idx.begin(), idx.end());
    return idx;
}

PosteriorSamples selectSamples(const PosteriorSamples& p, const std::vector<Eigen::Index>& indices) {
    PosteriorSamples r = p;
    r.values.resize(p.values.rows(), static_cast<Eigen::Index>(indices.size()));
    for (std::size_t i = 0; i < indices.size(); ++i) r.values.col(static_cast<Eigen::Index>(i)) = p.values.col(indices[i]);
    return r;
}

// ------------------------------------------------------------------------------------------------
// Predictions

PosteriorPrediction predictPosterior(const PosteriorSamples& s, const PredictionModel& model, const RbcDataSet* data,
                                     const PredictionOptions& o) {
    PosteriorPrediction r;
    r.label = s.label;
    r.name = s.name;
    r.experiment = s.experiment;
    r.samplesFile = s.file;
    r.samplesUsed = s.values.cols();
    if (data && data->experiment != s.experiment)
        throw InputError(fmt::format("{}: the posterior is of a {} data set but the data set {} is {}", s.file.string(),
                                     experimentName(s.experiment), data->name, experimentName(data->experiment)));
    r.haveData = data != nullptr;
    const Eigen::Index n = s.values.cols();
    if (n < 1) throw InputError(fmt::format("{}: no samples", s.file.string()));
    const int g = std::max(o.gridPoints, 2);

    switch (s.experiment) {
        case RbcExperiment::Equilibrium: {
            if (!model.equilibrium) throw InputError("predict: no equilibrium model");
            const Eigen::MatrixXd f = model.equilibrium(equilibriumInputs(s));  // 3 x n
            const Eigen::VectorXd sigma = s.values.row(2).transpose();
            static const char* obs[3] = {"D_um", "hmin_um", "hmax_um"};
            r.densityX.resize(3);
            r.density.resize(3);
            for (int j = 0; j < 3; ++j) {
                const Eigen::VectorXd m = f.row(j).transpose();
                const Eigen::VectorXd sd = (sigma.array() * m.array()).abs().matrix();
                ObservableBand b;
                b.observable = obs[j];
                b.x = {static_cast<double>(j)};
                b.summary = {summarizeMixture(m, sd)};
                r.bands.push_back(b);
                const double c = meanOf(m), w = 3.0 * (sdOf(m) + meanOf(sd));
                const int np = std::max(o.densityPoints, 2);
                for (int i = 0; i < np; ++i) {
                    const double y = c - w + 2.0 * w * i / (np - 1);
                    r.densityX[static_cast<std::size_t>(j)].push_back(y);
                    r.density[static_cast<std::size_t>(j)].push_back(normalMixtureDensity(m, sd, y));
                }
                if (data)
                    r.coverage.push_back({obs[j], 0.0, data->shape[j], b.summary[0].q05(), b.summary[0].quantiles[4], b.summary[0].q95()});
            }
            break;
        }
        case RbcExperiment::Stretching: {
            if (!model.stretching) throw InputError("predict: no stretching model");
            r.xName = "Fext_pN";
            const Eigen::VectorXd sigma0 = s.values.row(4).transpose(), sigma1 = s.values.row(5).transpose();
            std::vector<double> forces;
            for (int i = 0; i < g; ++i) forces.push_back(o.forceMax * i / (g - 1));
            const std::size_t nGrid = forces.size();
            if (data)
                for (Eigen::Index j = 0; j < data->force.size(); ++j) forces.push_back(data->force[j]);
            std::vector<Eigen::MatrixXd> out(forces.size());
            for (std::size_t i = 0; i < forces.size(); ++i) out[i] = model.stretching(stretchingInputs(s, forces[i]));  // 2 x n
            std::vector<PredictiveSummary> d0(forces.size()), d1(forces.size());
#pragma omp parallel for schedule(dynamic)
            for (long i = 0; i < static_cast<long>(forces.size()); ++i) {
                d0[static_cast<std::size_t>(i)] = summarizeMixture(out[static_cast<std::size_t>(i)].row(0).transpose(), sigma0);
                d1[static_cast<std::size_t>(i)] = summarizeMixture(out[static_cast<std::size_t>(i)].row(1).transpose(), sigma1);
            }
            ObservableBand b0{"D0_um", {}, {}}, b1{"D1_um", {}, {}};
            for (std::size_t i = 0; i < nGrid; ++i) {
                b0.x.push_back(forces[i]), b0.summary.push_back(d0[i]);
                b1.x.push_back(forces[i]), b1.summary.push_back(d1[i]);
            }
            r.bands = {b0, b1};
            if (data)
                for (Eigen::Index j = 0; j < data->force.size(); ++j) {
                    const std::size_t i = nGrid + static_cast<std::size_t>(j);
                    r.coverage.push_back({"D0_um", forces[i], data->d0[j], d0[i].q05(), d0[i].quantiles[4], d0[i].q95()});
                    r.coverage.push_back({"D1_um", forces[i], data->d1[j], d1[i].q05(), d1[i].quantiles[4], d1[i].q95()});
                }
            break;
        }
        case RbcExperiment::Flow:  // readPosteriorSamples refuses a flow posterior
            throw InputError(fmt::format("{}: trbc predict predicts the single-cell experiments, not a flow data set", s.label));
        case RbcExperiment::Relaxation: {
            r.xName = "t_s";
            const Eigen::VectorXd sigmaZ = s.values.row(5).transpose();
            std::vector<double> times;
            for (int i = 0; i < g; ++i) times.push_back(o.timeMax * i / (g - 1));
            const std::size_t nGrid = times.size();
            if (data)
                for (Eigen::Index j = 0; j < data->time.size(); ++j) times.push_back(data->time[j]);
            std::vector<PredictiveSummary> z(times.size());
#pragma omp parallel for schedule(dynamic)
            for (long i = 0; i < static_cast<long>(times.size()); ++i) {
                Eigen::VectorXd m(n);
                for (Eigen::Index k = 0; k < n; ++k)
                    m[k] = hochmuthAspect(times[static_cast<std::size_t>(i)], s.values(2, k), s.values(3, k), s.values(4, k));
                z[static_cast<std::size_t>(i)] = summarizeMixture(m, sigmaZ);
            }
            ObservableBand b{"z", {}, {}};
            for (std::size_t i = 0; i < nGrid; ++i) b.x.push_back(times[i]), b.summary.push_back(z[i]);
            r.bands = {b};
            if (data)
                for (Eigen::Index j = 0; j < data->time.size(); ++j) {
                    const std::size_t i = nGrid + static_cast<std::size_t>(j);
                    r.coverage.push_back({"z", times[i], data->aspect[j], z[i].q05(), z[i].quantiles[4], z[i].q95()});
                }
            r.tcLatent = s.values.row(2).transpose();
            if (model.relaxationTime) r.tcSim = model.relaxationTime(relaxationInputs(s));
            break;
        }
    }
    return r;
}

std::vector<fs::path> writePredictionCsv(const fs::path& dir, const PosteriorPrediction& p) {
    std::vector<fs::path> files;
    const auto& lv = predictiveLevels();
    const fs::path file = dir / fmt::format("predict_{}_{}.csv", p.label, experimentName(p.experiment));
    std::string s;
    if (p.experiment == RbcExperiment::Equilibrium) {
        // A band without a data point has "n/a" in data_um (pandas and trbc's readers take it as missing).
        s = csvProvenance() + "observable,data_um";
        for (double q : lv) s += fmt::format(",pred_{}", levelSuffix(q));
        s += ",pred_mean\n";
        for (std::size_t j = 0; j < p.bands.size(); ++j) {
            const ObservableBand& b = p.bands[j];
            s += csvField(b.observable) + "," + (j < p.coverage.size() ? fmtNum(p.coverage[j].y) : std::string("n/a"));
            for (Eigen::Index i = 0; i < b.summary[0].quantiles.size(); ++i) s += fmt::format(",{:.8g}", b.summary[0].quantiles[i]);
            s += fmt::format(",{:.8g}\n", b.summary[0].mean);
        }
        writeFileAtomically(file, s);
        files.push_back(file);
        const fs::path dfile = dir / fmt::format("predict_{}_{}_density.csv", p.label, experimentName(p.experiment));
        std::string d = csvProvenance();
        for (std::size_t j = 0; j < p.bands.size(); ++j)
            d += fmt::format("{}{},{}", j ? "," : "", csvField(p.bands[j].observable), csvField(p.bands[j].observable + "_density"));
        d += "\n";
        const std::size_t np = p.densityX.empty() ? 0 : p.densityX[0].size();
        for (std::size_t i = 0; i < np; ++i) {
            for (std::size_t j = 0; j < p.bands.size(); ++j)
                d += fmt::format("{}{},{}", j ? "," : "", fmtNum(p.densityX[j][i]), fmtNum(p.density[j][i]));
            d += "\n";
        }
        writeFileAtomically(dfile, d);
        files.push_back(dfile);
        return files;
    }
    s = csvProvenance() + csvField(p.xName);
    for (const ObservableBand& b : p.bands) {
        for (double q : lv) s += "," + csvField(fmt::format("{}_{}", b.observable, levelSuffix(q)));
        s += "," + csvField(b.observable + "_mean");
    }
    s += "\n";
    const std::size_t nx = p.bands.empty() ? 0 : p.bands[0].x.size();
    for (std::size_t i = 0; i < nx; ++i) {
        s += fmtNum(p.bands[0].x[i]);
        for (const ObservableBand& b : p.bands) {
            for (Eigen::Index k = 0; k < b.summary[i].quantiles.size(); ++k) s += fmt::format(",{:.8g}", b.summary[i].quantiles[k]);
            s += fmt::format(",{:.8g}", b.summary[i].mean);
        }
        s += "\n";
    }
    writeFileAtomically(file, s);
    files.push_back(file);
    return files;
}

void writeCoverageCsv(const fs::path& file, const std::vector<PosteriorPrediction>& predictions) {
    std::string s = csvProvenance() + "posterior,experiment,observable,x,y,q05,q50,q95,inside_90\n";
    for (const PosteriorPrediction& p : predictions)
        for (const CoveragePoint& c : p.coverage)
            s += fmt::format("{},{},{},{},{},{},{},{},{}\n", csvField(p.label), csvField(experimentName(p.experiment)), csvField(c.observable),
                             fmtNum(c.x), fmtNum(c.y),
                             fmtNum(c.q05), fmtNum(c.q50), fmtNum(c.q95), c.inside() ? 1 : 0);
    writeFileAtomically(file, s);
}

std::string coverageMarkdown(const std::vector<PosteriorPrediction>& predictions) {
    std::string s = "## Experimental data against the 90 % prediction bands\n\n"
                    "Each data point is compared with the central 90 % band [q05, q95] of the posterior predictive mixture "
                    "(every sample with its own error model, docs/BAYESIAN_INFERENCE.md, prediction) evaluated at the point's own force or time. In coverage.csv, "
                    "x is that force (pN, stretching) or time (s, relaxation; 0 for the equilibrium dimensions) and y the "
                    "measured value (um, or L/W for the relaxation).\n\n"
                    "| posterior | experiment | samples | data points | inside 90 % band | outside |\n|---|---|---|---|---|---|\n";
    int total = 0, inside = 0;
    for (const PosteriorPrediction& p : predictions) {
        if (!p.haveData) {
            s += fmt::format("| {} | {} | {} | – | – | no data set of this name |\n", markdownCell(p.label), experimentName(p.experiment),
                             p.samplesUsed);
            continue;
        }
        int in = 0;
        std::vector<std::string> out;
        for (const CoveragePoint& c : p.coverage) {
            if (c.inside())
                ++in;
            else
                out.push_back(outsideDescription(c, p.xName));
        }
        total += static_cast<int>(p.coverage.size());
        inside += in;
        s += fmt::format("| {} | {} | {} | {} | {} | {} |\n", markdownCell(p.label), experimentName(p.experiment), p.samplesUsed,
                         p.coverage.size(), in, out.empty() ? std::string("none") : markdownCell(fmt::format("{}", fmt::join(out, "; "))));
    }
    s += fmt::format("\nIn all: {} of {} data points inside their 90 % band ({:.1f} %).\n", inside, total,
                     total ? 100.0 * inside / total : 0.0);
    bool anyTc = false;
    for (const PosteriorPrediction& p : predictions) anyTc = anyTc || p.tcSim.size() > 0;
    if (anyTc) {
        s += "\n### Relaxation: latent $t_c$ against the surrogate's $t_c^{\\rm sim}(r)$\n\n"
             "| posterior | median tc_s (latent) | median tc_sim_s (surrogate at r) | median tc_sim / tc |\n|---|---|---|---|\n";
        for (const PosteriorPrediction& p : predictions) {
            if (p.tcSim.size() == 0) continue;
            auto median = [](Eigen::VectorXd v) {
                std::sort(v.data(), v.data() + v.size());
                const Eigen::Index n = v.size();
                return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
            };
            const Eigen::VectorXd ratio = (p.tcSim.array() / p.tcLatent.array()).matrix();
            s += fmt::format("| {} | {:.4g} | {:.4g} | {:.3f} |\n", markdownCell(p.label), median(p.tcLatent), median(p.tcSim), median(ratio));
        }
    }
    return s;
}

// ------------------------------------------------------------------------------------------------
// Direct model

double DirectComparison::rmse() const {
    if (surrogate.empty()) return std::numeric_limits<double>::quiet_NaN();
    double s = 0.0;
    for (std::size_t i = 0; i < surrogate.size(); ++i) s += (surrogate[i] - direct[i]) * (surrogate[i] - direct[i]);
    return std::sqrt(s / static_cast<double>(surrogate.size()));
}

double DirectComparison::maxAbs() const {
    double m = 0.0;
    for (std::size_t i = 0; i < surrogate.size(); ++i) m = std::max(m, std::abs(surrogate[i] - direct[i]));
    return surrogate.empty() ? std::numeric_limits<double>::quiet_NaN() : m;
}

std::string directComparisonMarkdown(const std::vector<DirectComparison>& rows, int level) {
    std::string s = fmt::format("## Surrogate against the direct forward model (level {})\n\n"
                                "| posterior | observable | values compared | failed direct runs | RMSE | max abs difference | "
                                "mean direct value |\n|---|---|---|---|---|---|---|\n",
                                level);
    for (const DirectComparison& r : rows) {
        double md = 0.0;
        for (double d : r.direct) md += d;
        md = r.direct.empty() ? std::numeric_limits<double>::quiet_NaN() : md / static_cast<double>(r.direct.size());
        s += fmt::format("| {} | {} | {} | {} | {:.4g} | {:.4g} | {:.4g} |\n", markdownCell(r.label), markdownCell(r.observable), r.surrogate.size(), r.failures,
                         r.rmse(), r.maxAbs(), md);
    }
    return s;
}

namespace {

/// Runs `simulate(k)` for every sample k of `s`: a sample whose direct model fails is counted as a
/// failure of every row and reported; each sample ends with a progress line.
void forEachDirectSample(const PosteriorSamples& s, const std::vector<Eigen::Index>& indices, std::vector<DirectComparison>& rows,
                         const std::function<void(const std::string&)>& progress, const std::function<void(Eigen::Index)>& simulate) {
    const Eigen::Index n = s.values.cols();
    auto say = [&](const std::string& m) {
        if (progress) progress(m);
    };
    for (Eigen::Index k = 0; k < n; ++k) {
        try {
            simulate(k);
        } catch (const NumericalError& e) {
            for (DirectComparison& r : rows) ++r.failures;
            say(fmt::format("predict --direct {}: sample {} failed: {}", s.label, indices[static_cast<std::size_t>(k)], e.what()));
        }
        say(fmt::format("predict --direct {}: {}/{}", s.label, k + 1, n));
    }
}

}  // namespace

std::vector<DirectComparison> compareWithDirectModel(const PosteriorSamples& posterior, const PredictionModel& model, const RbcDataSet* data,
                                                     const std::vector<Eigen::Index>& indices, const ExperimentOptions& opt,
                                                     const std::function<void(const std::string&)>& progress) {
    const PosteriorSamples s = selectSamples(posterior, indices);
    std::vector<DirectComparison> rows;
    switch (s.experiment) {
        case RbcExperiment::Equilibrium: {
            static const char* obs[3] = {"D_um", "hmin_um", "hmax_um"};
            for (const char* o : obs) rows.push_back({s.label, o, {}, {}, 0});
            const Eigen::MatrixXd f = model.equilibrium(equilibriumInputs(s));
            forEachDirectSample(s, indices, rows, progress, [&](Eigen::Index k) {
                CellParameters p;
                p.v = s.values(0, k), p.FvK = s.values(1, k), p.mu = 4.0, p.b2 = 2.0;
                const SampleResult r = runSample(p, 0.0, {true, false, false}, opt);
                const double d[3] = {r.equilibrium.observables.D, r.equilibrium.observables.hmin, r.equilibrium.observables.hmax};
                for (int j = 0; j < 3; ++j) rows[static_cast<std::size_t>(j)].surrogate.push_back(f(j, k)), rows[static_cast<std::size_t>(j)].direct.push_back(d[j]);
            });
            break;
        }
        case RbcExperiment::Stretching: {
            std::vector<double> forces;
            if (data && data->force.size() > 0)
                for (Eigen::Index j = 0; j < data->force.size(); ++j) forces.push_back(data->force[j]);
            else
                forces = {0.0, 50.0, 100.0, 150.0, 200.0};
            std::sort(forces.begin(), forces.end());
            forces.erase(std::unique(forces.begin(), forces.end()), forces.end());
            rows.push_back({s.label, "D0_um", {}, {}, 0});
            rows.push_back({s.label, "D1_um", {}, {}, 0});
            std::vector<Eigen::MatrixXd> f;
            for (double F : forces) f.push_back(model.stretching(stretchingInputs(s, F)));
            forEachDirectSample(s, indices, rows, progress, [&](Eigen::Index k) {
                CellParameters p;
                p.v = s.values(0, k), p.mu = s.values(1, k), p.FvK = fvkFromModuli(p.mu, s.values(2, k) / kJoulePerKbUnit), p.b2 = s.values(3, k);
                const SampleResult r = runSample(p, 0.0, {true, false, false}, opt);
                const CellMeshes meshes = cellMeshes(r.sfs, usesSymmetricReference(opt.equilibriumSymmetry));
                const std::vector<StretchPoint> pts = runStretching(p, meshes, r.equilibrium.shape, forces, opt);
                for (std::size_t i = 0; i < pts.size() && i < forces.size(); ++i) {
                    rows[0].surrogate.push_back(f[i](0, k)), rows[0].direct.push_back(pts[i].observables.D0);
                    rows[1].surrogate.push_back(f[i](1, k)), rows[1].direct.push_back(pts[i].observables.D1);
                }
            });
            break;
        }
        case RbcExperiment::Flow:  // readPosteriorSamples refuses a flow posterior
            throw InputError(fmt::format("{}: trbc predict predicts the single-cell experiments, not a flow data set", s.label));
        case RbcExperiment::Relaxation: {
            rows.push_back({s.label, "tc_s", {}, {}, 0});
            if (!model.relaxationTime) break;
            const Eigen::VectorXd f = model.relaxationTime(relaxationInputs(s));
            forEachDirectSample(s, indices, rows, progress, [&](Eigen::Index k) {
                CellParameters p;
                p.v = kRelaxationV, p.mu = kRelaxationMu, p.FvK = kRelaxationFvK, p.b2 = kRelaxationB2, p.etam = kRelaxationMu * s.values(0, k);
                const SampleResult r = runSample(p, 0.0, {true, false, true}, opt);
                rows[0].surrogate.push_back(f[k]);
                rows[0].direct.push_back(r.relaxation.fit.tc);
            });
            break;
        }
    }
    return rows;
}

}  // namespace trbc
