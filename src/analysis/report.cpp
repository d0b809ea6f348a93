#include "analysis/report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

#include "core/csv.hpp"
#include "core/file_io.hpp"
#include "core/error.hpp"

namespace trbc {
namespace fs = std::filesystem;

// ------------------------------------------------------------------------------------------------
// Document model

void ReportDocument::heading(int level, std::string text) { blocks_.push_back({Kind::Heading, level, std::move(text), {}, {}, {}}); }
void ReportDocument::paragraph(std::string text) { blocks_.push_back({Kind::Paragraph, 0, std::move(text), {}, {}, {}}); }
void ReportDocument::table(std::vector<std::string> header, std::vector<std::vector<std::string>> rows) {
    blocks_.push_back({Kind::Table, 0, {}, std::move(header), std::move(rows), {}});
}
void ReportDocument::image(fs::path file, std::string caption) { blocks_.push_back({Kind::Image, 0, std::move(caption), {}, {}, std::move(file)}); }
void ReportDocument::code(std::string text) { blocks_.push_back({Kind::Code, 0, std::move(text), {}, {}, {}}); }

namespace {

std::string escapeHtml(const std::string& s) {
    std::string r;
    for (char c : s) {
        switch (c) {
            case '&': r += "&amp;"; break;
            case '<': r += "&lt;"; break;
            case '>': r += "&gt;"; break;
            case '"': r += "&quot;"; break;
            default: r += c;
        }
    }
    return r;
}

/// Inline markup of paragraphs and cells: `code` and **bold**.
std::string inlineHtml(const std::string& s) {
    std::string e = escapeHtml(s);
    e = std::regex_replace(e, std::regex("`([^`]*)`"), "<code>$1</code>");
    e = std::regex_replace(e, std::regex("\\*\\*([^*]*)\\*\\*"), "<b>$1</b>");
    return e;
}

std::string mdCell(const std::string& s) { return markdownCell(s); }

}  // namespace

std::string base64Encode(const std::string& bytes) {
    static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((bytes.size() + 2) / 3 * 4);
    std::size_t i = 0;
    for (; i + 2 < bytes.size(); i += 3) {
        const unsigned n = (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8 | (unsigned char)bytes[i + 2];
        out += table[n >> 18 & 63], out += table[n >> 12 & 63], out += table[n >> 6 & 63], out += table[n & 63];
    }
    if (i + 1 == bytes.size()) {
        const unsigned n = (unsigned char)bytes[i] << 16;
        out += table[n >> 18 & 63], out += table[n >> 12 & 63], out += "==";
    } else if (i + 2 == bytes.size()) {
        const unsigned n = (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8;
        out += table[n >> 18 & 63], out += table[n >> 12 & 63], out += table[n >> 6 & 63], out += '=';
    }
    return out;
}

std::vector<MeshConvergenceRecord> meshConvergenceRecords(const fs::path& directory) {
    std::vector<MeshConvergenceRecord> records;
    if (!fs::is_directory(directory)) return records;
    const std::regex name("(.+)_L([0-9])\\.json");
    for (const auto& e : fs::directory_iterator(directory)) {
        std::smatch m;
        const std::string file = e.path().filename().string();
        if (e.is_regular_file() && std::regex_match(file, m, name)) records.push_back({e.path(), m[1], std::stoi(m[2])});
    }
    std::sort(records.begin(), records.end(), [](const auto& a, const auto& b) { return a.file < b.file; });
    return records;
}

std::string ReportDocument::markdown(const fs::path& directory) const {
    std::string s;
    for (const Block& b : blocks_) {
        switch (b.kind) {
            case Kind::Heading: s += std::string(static_cast<std::size_t>(b.level), '#') + " " + b.text + "\n\n"; break;
            case Kind::Paragraph: s += b.text + "\n\n"; break;
            case Kind::Code: s += "```\n" + b.text + (b.text.ends_with('\n') ? "" : "\n") + "```\n\n"; break;
            case Kind::Image:
                if (fs::exists(b.file))
                    s += fmt::format("![{}]({})\n\n*{}*\n\n", b.text, fs::relative(b.file, directory).string(), b.text);
                else
                    s += fmt::format("*(figure not available: {} — {})*\n\n", b.file.filename().string(), b.text);
                break;
            case Kind::Table: {
                s += "|";
                for (const auto& h : b.header) s.append(" ").append(mdCell(h)).append(" |");
                s += "\n|";
                for (std::size_t k = 0; k < b.header.size(); ++k) s += "---|";
                s += "\n";
                for (const auto& r : b.rows) {
                    s += "|";
                    for (const auto& c : r) s.append(" ").append(mdCell(c)).append(" |");
                    s += "\n";
                }
                s += "\n";
                break;
            }
        }
    }
    return s;
}

std::string ReportDocument::html(const std::string& title) const {
    std::string s = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + escapeHtml(title) + "</title>\n<style>\n"
                    "body{font-family:-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;max-width:1050px;margin:2em auto;padding:0 1em;"
                    "color:#222;line-height:1.45}\nh1{border-bottom:2px solid #444}h2{border-bottom:1px solid #bbb;margin-top:2em}\n"
                    "table{border-collapse:collapse;margin:0.8em 0;font-size:0.9em}th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}"
                    "th{background:#f0f0f0}td:first-child,th:first-child{text-align:left}\n"
                    "code{background:#f4f4f4;padding:0 3px}pre{background:#f6f6f6;padding:0.8em;overflow-x:auto;font-size:0.85em}\n"
                    "figure{margin:1em 0}figure img{max-width:100%;max-height:820px;border:1px solid #ddd}figcaption{font-size:0.9em;color:#555}\n"
                    ".missing{color:#a00}\n</style></head><body>\n";
    for (const Block& b : blocks_) {
        switch (b.kind) {
            case Kind::Heading: s += fmt::format("<h{0}>{1}</h{0}>\n", std::clamp(b.level, 1, 6), inlineHtml(b.text)); break;
            case Kind::Paragraph: s += "<p>" + inlineHtml(b.text) + "</p>\n"; break;
            case Kind::Code: s += "<pre>" + escapeHtml(b.text) + "</pre>\n"; break;
            case Kind::Image:
                if (fs::exists(b.file))
                    s += fmt::format("<figure><img alt=\"{0}\" src=\"data:image/png;base64,{1}\"><figcaption>{0}</figcaption></figure>\n",
                                     escapeHtml(b.text), base64Encode(readFileBytes(b.file)));
                else
                    s += fmt::format("<p class=\"missing\">(figure not available: {} — {})</p>\n", escapeHtml(b.file.filename().string()),
                                     escapeHtml(b.text));
                break;
            case Kind::Table:
                s += "<table><tr>";
                for (const auto& h : b.header) s += "<th>" + inlineHtml(h) + "</th>";
                s += "</tr>\n";
                for (const auto& r : b.rows) {
                    s += "<tr>";
                    for (const auto& c : r) s += "<td>" + inlineHtml(c) + "</td>";
                    s += "</tr>\n";
                }
                s += "</table>\n";
                break;
        }
    }
    return s + "</body></html>\n";
}

// ------------------------------------------------------------------------------------------------
// The calibration report

namespace {

/// Records of one of the pipeline's CSV tables (quoted fields, '#' lines skipped), header first; empty if missing.
std::vector<std::vector<std::string>> readCsvRows(const fs::path& p) { return readCsvRecords(p); }

/// Column c of a record; empty when the record is shorter or c is -1 (a missing column).
std::string cellOf(const std::vector<std::string>& row, int c) {
    return c >= 0 && static_cast<std::size_t>(c) < row.size() ? row[static_cast<std::size_t>(c)] : std::string();
}

nlohmann::json readJson(const fs::path& p) { return tryReadJson(p).value_or(nullptr); }

std::string num(double x, int digits = 3) {
    if (!std::isfinite(x)) return "–";
    return fmt::format("{:.{}g}", x, digits);
}

struct ParameterLayout {
    const char* parameter;
    const char* label;
    double factor;
    double paperMean, paperMedian, paperMap, paperSd;  ///< the paper's Table 1 (theta_new)
};
/// Units of the paper's Table 1; its theta_new statistics (trbc_paper.tex, table tab:stats:thetanew).
const ParameterLayout kThetaLayout[] = {
    {"v", "v", 1.0, 0.94, 0.95, 0.96, 0.04},
    {"mu_uN_per_m", "μ (µN/m)", 1.0, 4.99, 4.68, 4.60, 2.24},
    {"kb_J", "κ_b (1e-19 J)", 1e19, 2.10, 1.85, 1.46, 0.93},
    {"b2", "b2", 1.0, 1.84, 1.73, 1.69, 0.82},
    {"etam_Pa_s_um", "η_m (Pa s µm)", 1.0, 0.69, 0.62, 0.66, 0.46},
};

void parametersSection(ReportDocument& doc, const fs::path& out) {
    doc.heading(2, "Calibrated parameters (θ_new: a new cell given all data)");
    const auto rows = readCsvRows(out / "inference" / "posterior_stats.csv");
    if (rows.size() < 2) {
        doc.paragraph("The inference has not produced `inference/posterior_stats.csv`.");
        return;
    }
    const auto& h = rows[0];
    const int cPost = columnOf(h, "posterior"), cPar = columnOf(h, "parameter");
    std::vector<std::vector<std::string>> table, paper;
    for (const ParameterLayout& L : kThetaLayout)
        for (std::size_t r = 1; r < rows.size(); ++r) {
            if (cellOf(rows[r], cPost) != "theta_new" || cellOf(rows[r], cPar) != L.parameter) continue;
            std::vector<std::string> line = {L.label};
            for (const char* col : {"mean", "mcse_mean", "median", "map", "sd", "mcse_sd", "q05", "q95"}) {
                const int c = columnOf(h, col);
                // Statistics files of older versions have no MCSE columns; "nan" marks a statistic without one.
                const std::string cell = c < 0 ? std::string() : cellOf(rows[r], c);
                line.push_back(cell.empty() || cell == "nan" ? "–" : num(std::stod(cell) * L.factor));
            }
            table.push_back(line);
            paper.push_back({L.label, num(L.paperMean), num(L.paperMedian), num(L.paperMap), num(L.paperSd)});
        }
    doc.table({"parameter", "mean", "MCSE of the mean", "median", "MAP", "SD", "MCSE of the SD", "5 %", "95 %"}, table);
    doc.paragraph("MCSE: the Monte Carlo standard error of the estimate, from the chains' effective sample size "
                  "(docs/BAYESIAN_INFERENCE.md); eight seeds scatter by the same amount.");
    doc.paragraph("The paper's published values (Table 1 of the paper, θ_new) for comparison. trbc's posterior is built on its own "
                  "forward model and surrogates (not the paper's), so agreement within the posterior spread, not digit for digit, "
                  "is what to expect:");
    doc.table({"parameter", "paper mean", "paper median", "paper MAP", "paper SD"}, paper);
    doc.paragraph("All posteriors (phase 1: each data set alone; phase 3: each data set given all data) are in "
                  "`inference/posterior_stats.csv` and `inference/posterior_table.md`.");
    doc.image(out / "figures" / "corner_theta_new.png", "Posterior of θ_new: marginals and pairwise densities");
}

void predictionSection(ReportDocument& doc, const fs::path& out) {
    doc.heading(2, "Data against the posterior predictions");
    const fs::path dir = out / "predict";
    const auto rows = readCsvRows(dir / "coverage.csv");
    if (rows.size() < 2) {
        doc.paragraph("The prediction stage has not produced `predict/coverage.csv`.");
        return;
    }
    doc.paragraph("Each experiment's data against the posterior predictive median and bands (phase-3 posterior of its data set "
                  "given all data; every posterior sample with its own error model, docs/BAYESIAN_INFERENCE.md, prediction). A point counts as covered "
                  "when it lies inside the central 90 % band.");
    const auto& h = rows[0];
    const int cPost = columnOf(h, "posterior"), cExp = columnOf(h, "experiment"), cIn = columnOf(h, "inside_90");
    std::map<std::string, std::pair<int, int>> count;
    std::map<std::string, std::string> experiment;
    int inside = 0, total = 0;
    for (std::size_t r = 1; r < rows.size(); ++r) {
        const std::string p = cellOf(rows[r], cPost);
        const bool in = cellOf(rows[r], cIn) == "1";
        count[p].first += in, count[p].second += 1, inside += in, total += 1;
        experiment[p] = cellOf(rows[r], cExp);
    }
    std::vector<std::vector<std::string>> table;
    for (const auto& [p, c] : count)
        table.push_back({p, experiment[p], std::to_string(c.second), std::to_string(c.first),
                         fmt::format("{:.1f} %", 100.0 * c.first / std::max(c.second, 1))});
    doc.table({"posterior", "experiment", "data points", "inside 90 % band", "fraction"}, table);
    doc.paragraph(fmt::format("In all **{} of {}** data points ({:.1f} %) lie inside their 90 % band. Per-point detail: "
                              "`predict/coverage.md`.", inside, total, 100.0 * inside / std::max(total, 1)));
    std::vector<fs::path> figures;
    if (fs::is_directory(dir))
        for (const auto& e : fs::directory_iterator(dir))
            if (e.path().extension() == ".png") figures.push_back(e.path());
    std::sort(figures.begin(), figures.end());
    for (const fs::path& f : figures) {
        std::string stem = f.stem().string();
        if (stem.rfind("predict_", 0) == 0) stem = stem.substr(8);
        doc.image(f, "Prediction (median, 50/75/90/99 % bands) against the data: " + stem);
    }
}

void sobolSection(ReportDocument& doc, const fs::path& out) {
    doc.heading(2, "Sensitivity analysis (Sobol' indices on the surrogates)");
    const auto rows = readCsvRows(out / "sobol" / "sobol_indices.csv");
    if (rows.size() < 2) {
        doc.paragraph("The Sobol' stage did not run (disabled in the configuration) or has no output.");
        return;
    }
    const auto& h = rows[0];
    const int cOut = columnOf(h, "output"), cIn = columnOf(h, "input"), cS1 = columnOf(h, "S1"), cST = columnOf(h, "ST");
    const std::vector<std::string> inputs = {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um"};
    std::vector<std::vector<std::string>> table;
    for (const std::string o : {"D_um", "hmin_um", "hmax_um", "tc_s", "D0_um@100", "D1_um@100"}) {
        std::vector<std::string> line = {o};
        for (const std::string& in : inputs)
            for (std::size_t r = 1; r < rows.size(); ++r)
                if (cellOf(rows[r], cOut) == o && cellOf(rows[r], cIn) == in)
                    line.push_back(fmt::format("{:.2f} / {:.2f}", std::stod(cellOf(rows[r], cS1)),
                                               std::stod(cellOf(rows[r], cST))));
        if (line.size() == inputs.size() + 1) table.push_back(line);
    }
    std::vector<std::string> header = {"output (first order / total)"};
    header.insert(header.end(), inputs.begin(), inputs.end());
    doc.table(header, table);
    doc.paragraph("Inputs uniform on the prior box (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices); 95 % bootstrap intervals in `sobol/sobol_indices.csv`.");
    doc.image(out / "sobol" / "sobol_scalar.png", "Sobol' indices of the equilibrium observables and tc");
    doc.image(out / "sobol" / "sobol_force.png", "Sobol' indices of D0 and D1 against the stretching force");
}

void surrogateSection(ReportDocument& doc, const fs::path& modelDir) {
    doc.heading(2, "Surrogate accuracy");
    const nlohmann::json a = readJson(modelDir / "accuracy.json");
    if (a.is_null() || !a.contains("test")) {
        doc.paragraph(fmt::format("No accuracy record (`{}/accuracy.json`).", modelDir.string()));
        return;
    }
    const auto accuracyTable = [](const nlohmann::json& rows) {
        std::vector<std::vector<std::string>> table;
        for (const auto& r : rows)
            table.push_back({r.value("output", "?"), std::to_string(r.value("n", 0)), num(r.value("rmse", NAN)),
                             fmt::format("{:.2f} %", 100.0 * r.value("relative_rmse", NAN)), num(r.value("max_abs", NAN)),
                             fmt::format("{:.4f}", r.value("r2", NAN))});
        return table;
    };
    const std::vector<std::string> header = {"output", "n", "RMSE", "relative RMSE", "max abs error", "R²"};
    doc.paragraph(fmt::format("Networks of `{}`, trained by `{}` on {} rows in {} cells{}; held-out test set of whole cells "
                              "never used in training or early stopping:",
                              modelDir.string(), a.value("command", "?"), a.value("rows", 0), a.value("cells", 0),
                              a.value("data_complete", true) ? "" : " (finished part of a campaign)"));
    doc.table(header, accuracyTable(a["test"]));
    const nlohmann::json cv = readJson(modelDir / "cv.json");
    if (cv.is_object() && cv.contains("pooled") && cv.value("data_hash", "") == a.value("data_hash", "?")) {
        doc.paragraph(fmt::format("{}-fold cross-validation over whole cells (every cell predicted by the networks trained "
                                  "without it; the estimate to quote, a single split of few cells can be far from typical):",
                                  cv.value("folds", 0)));
        doc.table(header, accuracyTable(cv["pooled"]));
    }
}

void meshSection(ReportDocument& doc, const fs::path& dir) {
    doc.heading(2, "Mesh convergence of the forward model");
    std::map<std::string, std::map<int, nlohmann::json>> points;
    for (const MeshConvergenceRecord& r : meshConvergenceRecords(dir)) {
        const nlohmann::json j = readJson(r.file);
        if (j.contains("observables")) points[r.point][r.level] = j["observables"];
    }
    if (points.empty()) {
        doc.paragraph(fmt::format("No mesh-convergence runs in `{}` (scripts/mesh_convergence.sh makes them).", dir.string()));
        return;
    }
    const std::vector<std::string> obs = {"D_um", "hmin_um", "hmax_um", "D0_um", "D1_um", "tc_s"};
    std::vector<std::vector<std::string>> table;
    for (const auto& [point, levels] : points) {
        const auto& finest = levels.rbegin()->second;
        for (const auto& [level, o] : levels) {
            if (level == levels.rbegin()->first) continue;
            std::vector<std::string> line = {point, fmt::format("{} vs {}", level, levels.rbegin()->first)};
            for (const std::string& k : obs)
                line.push_back(o.contains(k) && finest.contains(k)
                                   ? fmt::format("{:+.2f} %", 100.0 * (o[k].get<double>() / finest[k].get<double>() - 1.0))
                                   : "–");
            table.push_back(line);
        }
    }
    std::vector<std::string> header = {"point", "level"};
    header.insert(header.end(), obs.begin(), obs.end());
    doc.paragraph("Relative difference of each observable against the finest level (`trbc simulate` at the reference point "
                  "and two corners of the prior box; docs/FORWARD_MODEL.md). The training campaign uses level 4.");
    doc.table(header, table);
}

void transferabilitySection(ReportDocument& doc, const fs::path& out) {
    doc.heading(2, "Transferability: flows the calibration never saw");
    const fs::path dir = out / "validation";
    const nlohmann::json v = readJson(dir / "validation.json");
    if (v.is_null() || !v.contains("summary")) {
        doc.paragraph("The flow validations did not run: enable `[validation]` in the configuration (hours on 2 cores; "
                      "`trbc validate` keeps finished cases across runs). Shipped results with the paper's Table 1 cell: "
                      "docs/VALIDATION_RESULTS.md.");
        return;
    }
    const nlohmann::json& s = v["summary"];
    doc.paragraph(fmt::format("`trbc validate` (docs/VALIDATE.md) with the θ_new posterior means, level {}: {} cases "
                              "({} failed); {} predictions inside the experimental scatter, {} outside, {} without data nearby, {} "
                              "neither (threshold not bracketed). Nothing was tuned to these data. Tables in `validation/`.",
                              v.value("level", 0), s.value("cases", 0), s.value("failed", 0), s.value("inside", 0),
                              s.value("outside", 0), s.value("no_data", 0), s.value("other", 0)));
    std::vector<std::vector<std::string>> table;
    const auto rows = readCsvRows(dir / "comparison.csv");
    for (std::size_t k = 1; k < rows.size(); ++k)
        if (rows[k].size() >= 7)
            table.push_back({rows[k][0], rows[k][1], rows[k][2],
                             rows[k][5] == "0" ? std::string("–") : rows[k][3] + " – " + rows[k][4], rows[k][6]});
    if (!table.empty()) doc.table({"case", "observable", "prediction", "experimental scatter", "verdict"}, table);
    for (const auto& [file, caption] : std::vector<std::pair<const char*, const char*>>{
             {"angle_vs_shear_rate.png", "Inclination angle against shear rate (Fischer 2015 donors)"},
             {"ttf_vs_shear_rate.png", "Tank-treading frequency at 28.9 mPa s"},
             {"critical_stress_vs_eta.png", "Tumbling / tank-treading critical stress against outer viscosity"},
             {"tube_velocity_vs_pg.png", "Cell velocity against pressure gradient, 6.6 um tube (Tomaiuolo 2009)"},
             {"tube_length_vs_velocity.png", "Cell length against velocity (Tomaiuolo 2009, Hochmuth 1970)"}})
        if (fs::exists(dir / "figures" / file)) doc.image(dir / "figures" / file, caption);
}

void cellSection(ReportDocument& doc, const fs::path& out) {
    doc.heading(2, "The calibrated cell (for flow solvers)");
    const nlohmann::json c = readJson(out / "cell" / "cell.json");
    if (c.is_null()) {
        doc.paragraph("The cell export did not run (disabled in the configuration) or has no output.");
        return;
    }
    std::vector<std::vector<std::string>> table;
    if (c.contains("physical"))
        for (const auto& [k, v] : c["physical"].items())
            if (v.is_number()) table.push_back({k, num(v.get<double>(), 5)});
    doc.paragraph(fmt::format("`trbc export` at the {} quantile of each θ_new marginal: stress-free and equilibrium meshes "
                              "(OFF and PLY) and `cell/cell.json` with the parameters in physical and dimensionless units.",
                              c.value("quantile", 0.5)));
    doc.table({"parameter", "value"}, table);
}

void provenanceSection(ReportDocument& doc, const CalibrationReportInputs& in) {
    const fs::path& out = in.outputDirectory;
    doc.heading(2, "Provenance");
    doc.paragraph(fmt::format("trbc {}; configuration `{}` (copy in `config.toml`); every stage's command line and wall time are "
                              "in `stages.json`, its log in `logs/`.",
                              in.version, in.configFile.string()));
    const nlohmann::json st = readJson(out / "stages.json");
    if (st.contains("stages")) {
        std::vector<std::string> ran, skipped;
        if (st.contains("last_run")) {
            ran = st["last_run"].value("ran", std::vector<std::string>{});
            skipped = st["last_run"].value("skipped", std::vector<std::string>{});
        }
        std::vector<std::vector<std::string>> table;
        for (const auto& [name, s] : st["stages"].items()) {
            const bool r = std::find(ran.begin(), ran.end(), name) != ran.end();
            std::string cmd;
            if (s.contains("details") && s["details"].contains("commands"))
                for (const auto& c : s["details"]["commands"]) cmd += (cmd.empty() ? "" : "; ") + c.get<std::string>();
            table.push_back({name, r ? "ran" : "cached", fmt::format("{:.1f}", s.value("wall_s", 0.0)), s.value("finished_at", ""),
                             cmd.empty() ? "" : "`" + cmd + "`"});
        }
        doc.table({"stage", "this run", "wall s", "finished (UTC)", "command"}, table);
    }
    doc.heading(3, "Data sets");
    std::vector<std::vector<std::string>> d;
    for (const std::string& s : in.dataSets) d.push_back({s});
    doc.table({"name (experiment): file"}, d);
    doc.heading(3, "Configuration");
    doc.code(readFileBytes(in.configFile));
    for (const fs::path& base : in.configBases) {
        doc.paragraph(fmt::format("Over its base `{}`:", base.string()));
        doc.code(readFileBytes(base));
    }
}

}  // namespace

ReportDocument writeCalibrationReport(const CalibrationReportInputs& in) {
    const fs::path& out = in.outputDirectory;
    ReportDocument doc;
    doc.heading(1, "trbc calibration report");
    doc.paragraph(fmt::format("A red-blood-cell model (Jülicher bending, Lim elasticity against the stress-free state, "
                              "membrane viscosity; docs/MEMBRANE_MODEL.md) calibrated by hierarchical Bayesian inference (TMCMC/BASIS on "
                              "neural-network surrogates of the three single-cell experiments; docs/BAYESIAN_INFERENCE.md) from {} data sets. "
                              "Made by trbc {} from `{}`.",
                              in.dataSets.size(), in.version, in.configFile.filename().string()));
    parametersSection(doc, out);
    predictionSection(doc, out);
    sobolSection(doc, out);
    surrogateSection(doc, in.surrogateDirectory);
    meshSection(doc, in.meshConvergenceDirectory);
    transferabilitySection(doc, out);
    cellSection(doc, out);
    provenanceSection(doc, in);
    writeFileAtomically(out / "report.md", doc.markdown(out));
    writeFileAtomically(out / "report.html", doc.html("trbc calibration report"));
    return doc;
}

}  // namespace trbc
