#include "analysis/calibrate_config.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <optional>
#include <sstream>
#include <toml++/toml.h>

#include "analysis/toml_reader.hpp"

#include "core/error.hpp"
#include "core/output_dir.hpp"
#include "inference/rbc_problem.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {


/// A path value of the configuration: relative to the directory of the file that sets it.
fs::path configPath(const std::string& value, const toml::node& n, const fs::path& file, const fs::path& experiments) {
    return resolveConfigPath(value, TableReader::sourceFile(n, file).parent_path(), experiments);
}

void readData(const fs::path& file, const toml::node& node, const fs::path& experiments, CalibrateConfig& c) {
    const toml::array* arr = node.as_array();
    auto fail = [&](const toml::node& n, const std::string& what) { TableReader::failAt(n, file, what); };
    if (!arr || arr->empty())
        fail(node, "'data' must be a non-empty array of tables [[data]] with name, experiment and file");
    c.data.clear();
    for (const toml::node& e : *arr) {
        const toml::table* t = e.as_table();
        if (!t) fail(e, "every [[data]] entry must be a table with name, experiment and file");
        TableReader r(file, *t, "data");
        r.allowOnly({"name", "experiment", "file"});
        CalibrateDataSet d;
        std::string path;
        r.string("name", d.name);
        r.string("experiment", d.experiment, {"equilibrium", "stretching", "relaxation"});
        r.string("file", path);
        if (d.name.empty() || d.experiment.empty() || path.empty()) fail(e, "a [[data]] entry lacks one of name, experiment, file");
        // The name becomes a directory and a CSV/Markdown field: checked once, here.
        try {
            checkFileName(d.name, "data name");
        } catch (const InputError& bad) {
            fail(e, bad.what());
        }
        if (d.name == "theta_new" || d.name == "hyper")
            fail(e, fmt::format("data name '{}' is not allowed ('theta_new' and 'hyper' are reserved)", d.name));
        for (const CalibrateDataSet& o : c.data)
            if (o.name == d.name) fail(e, fmt::format("data name '{}' appears twice", d.name));
        d.file = configPath(path, *t->get("file"), file, experiments);
        if (!fs::is_regular_file(d.file)) fail(e, fmt::format("data '{}': file {} does not exist", d.name, d.file.string()));
        c.data.push_back(std::move(d));
    }
}

/// [inference.prior]: NAME = [lo, hi] in physical units, each inside the surrogates' training box.
void readPriorBox(const fs::path& file, const toml::table& t, CalibrateConfig& c) {
    auto fail = [&](const toml::node& n, const std::string& what) { TableReader::failAt(n, file, what); };
    RbcPriorBox box;
    for (const auto& [key, node] : t) {
        const std::string name(key.str());
        const auto& names = RbcPriorBox::parameterNames();
        if (std::find(names.begin(), names.end(), name) == names.end())
            fail(node, fmt::format("unknown key 'inference.prior.{}' (valid keys: v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um)", name));
        const auto [dlo, dhi] = RbcPriorBox{}.bounds(name);
        const toml::array* a = node.as_array();
        std::optional<double> lo, hi;
        if (a && a->size() == 2) lo = (*a)[0].value<double>(), hi = (*a)[1].value<double>();
        if (!lo || !hi) fail(node, fmt::format("'inference.prior.{}' must be an array [lo, hi] of two numbers inside [{:g}, {:g}]", name, dlo, dhi));
        try {
            box.set(name, *lo, *hi);
        } catch (const InputError& e) {
            fail(node, fmt::format("'inference.prior.{}': {}", name, e.what()));
        }
        c.inferencePrior.emplace_back(name, std::pair{*lo, *hi});
    }
}

}  // namespace

std::string mergedCalibrateConfig(const fs::path& file) {
    std::vector<fs::path> chain, bases;
    const toml::table t = parseWithBases(file, chain, bases);
    std::ostringstream s;
    s << "# The configuration " << file.string() << " with its base";
    for (const fs::path& b : bases) s << " " << b.string();
    s << " merged into it; relative paths are relative to the file that set them.\n\n" << t << "\n";
    return s.str();
}

std::vector<CalibrateDataSet> defaultCalibrateData(const fs::path& dir) {
    std::vector<CalibrateDataSet> d = {
        {"evans_fung_1972", "equilibrium", dir / "equilibrium" / "evans_fung_1972.csv"},
        {"mills_2004", "stretching", dir / "stretching" / "mills_2004" / "mills_2004.csv"},
        {"suresh_2005", "stretching", dir / "stretching" / "suresh_2005" / "suresh_2005.csv"}};
    for (int k = 1; k <= 4; ++k)
        d.push_back({fmt::format("hochmuth_1979_cell{}", k), "relaxation", dir / "relaxation" / "hochmuth_1979" / fmt::format("{}.csv", k)});
    return d;
}

CalibrateConfig readCalibrateConfig(const fs::path& file, const fs::path& experiments) {
    CalibrateConfig c;
    std::vector<fs::path> chain;
    const toml::table root = parseWithBases(file, chain, c.bases);
    // Every key has a default (the paper's setup), so an empty file would silently run the whole
    // pipeline at full size: more likely a wrong or truncated file than a choice.
    if (root.empty())
        throw InputError(fmt::format("{}: the configuration is empty; give at least one section (configs/paper.toml lists every "
                                     "key with the paper's values)",
                                     file.string()));
    c.file = fs::absolute(file).lexically_normal();
    TableReader top(file, root, "");
    top.allowOnly({"base", "run", "data", "campaign", "surrogate", "sobol", "inference", "prediction", "cell", "validation"});
    auto section = [&](const char* name) -> const toml::table* {
        const toml::node* n = root.get(name);
        if (!n) return nullptr;
        if (!n->is_table()) top.fail(*n, fmt::format("'{}' must be a table [{}]", name, name));
        return n->as_table();
    };
    if (const toml::table* t = section("run")) {
        TableReader r(file, *t, "run");
        r.allowOnly({"seed", "threads"});
        r.unsignedInteger("seed", c.seed);
        r.integer("threads", c.threads, 1, 1024);
    }
    if (const toml::node* n = root.get("data"))
        readData(file, *n, experiments, c);
    else
        c.data = defaultCalibrateData(experiments);
    // Every data file is read now, so that a malformed CSV fails before any stage runs (the
    // readers name the file, line and column).
    for (const CalibrateDataSet& d : c.data) {
        if (d.experiment == "equilibrium")
            readEquilibriumData(d.file, d.name);
        else if (d.experiment == "stretching")
            readStretchingData(d.file, d.name);
        else
            readRelaxationData(d.file, d.name);
    }
    if (const toml::table* t = section("campaign")) {
        TableReader r(file, *t, "campaign");
        r.allowOnly({"mode", "samples", "forces_per_cell", "design", "level"});
        r.string("mode", c.campaignMode, {"shipped", "run"});
        r.integer("samples", c.campaignSamples, 1, 100000000);
        r.integer("forces_per_cell", c.campaignForcesPerCell, 1, 1000);
        r.string("design", c.campaignDesign, {"uniform", "lhs"});
        r.integer("level", c.campaignLevel, 1, 6);
    }
    if (const toml::table* t = section("surrogate")) {
        TableReader r(file, *t, "surrogate");
        r.allowOnly({"mode", "dir"});
        r.string("mode", c.surrogateMode, {"shipped", "train", "path"});
        std::string dir;
        r.string("dir", dir);
        if (!dir.empty()) c.surrogateDir = configPath(dir, *t->get("dir"), file, experiments);
        if (c.surrogateMode == "path" && c.surrogateDir.empty())
            r.fail(*t, "surrogate.mode = \"path\" needs surrogate.dir (a directory made by `trbc surrogate train`)");
    }
    if (c.surrogateMode == "train" && c.campaignMode != "run")
        throw InputError(fmt::format("{}: surrogate.mode = \"train\" needs campaign.mode = \"run\" (the shipped training set is "
                                     "already the basis of the shipped surrogates)", file.string()));
    if (const toml::table* t = section("sobol")) {
        TableReader r(file, *t, "sobol");
        r.allowOnly({"enabled", "samples", "forces", "resamples"});
        r.boolean("enabled", c.sobolEnabled);
        r.integer("samples", c.sobolSamples, 2, 1 << 24);
        r.integer("forces", c.sobolForces, 2, 1000);
        r.integer("resamples", c.sobolResamples, 2, 100000);
    }
    if (const toml::table* t = section("inference")) {
        TableReader r(file, *t, "inference");
        r.allowOnly({"samples", "fvk_density", "prior"});
        r.integer("samples", c.inferenceSamples, 100, 10000000);
        r.string("fvk_density", c.fvkDensity, {"closed", "closed-double", "nodes50"});
        if (const toml::node* pn = t->get("prior")) {
            if (!pn->is_table()) r.fail(*pn, "'inference.prior' must be a table [inference.prior] of NAME = [lo, hi]");
            readPriorBox(file, *pn->as_table(), c);
        }
    }
    if (const toml::table* t = section("prediction")) {
        TableReader r(file, *t, "prediction");
        r.allowOnly({"max_samples", "grid"});
        r.integer("max_samples", c.predictionMaxSamples, 0, 100000000);
        r.integer("grid", c.predictionGrid, 2, 100000);
    }
    if (const toml::table* t = section("cell")) {
        TableReader r(file, *t, "cell");
        r.allowOnly({"enabled", "quantile", "level"});
        r.boolean("enabled", c.cellEnabled);
        r.real("quantile", c.cellQuantile, 0.0, 1.0, true, true);
        r.integer("level", c.cellLevel, 1, 6);
    }
    if (const toml::table* t = section("validation")) {
        TableReader r(file, *t, "validation");
        r.allowOnly({"enabled", "config", "only"});
        r.boolean("enabled", c.validationEnabled);
        std::string cfg;
        r.string("config", cfg);
        if (!cfg.empty()) c.validationConfig = configPath(cfg, *t->get("config"), file, experiments);
        if (!c.validationConfig.empty() && !fs::is_regular_file(c.validationConfig))
            r.fail(*t->get("config"), fmt::format("validation.config {} does not exist", c.validationConfig.string()));
        if (const toml::node* n = t->get("only")) {
            const toml::array* a = n->as_array();
            const auto valid = [](const std::string& k) { return k == "angle" || k == "ttf" || k == "threshold" || k == "tube"; };
            if (a)
                for (const toml::node& x : *a)
                    if (const auto v = x.value_exact<std::string>(); v && valid(*v)) c.validationOnly.push_back(*v);
            if (!a || c.validationOnly.size() != a->size())
                r.fail(*n, "'validation.only' must be an array of: \"angle\", \"ttf\", \"threshold\", \"tube\"");
        }
    }
    return c;
}

}  // namespace trbc
