// trbc calibrate: configuration errors name file, line and key; malformed data fails
// before any stage; an unchanged re-run skips every stage; changing one data CSV re-runs exactly
// the stages that depend on it; the report and the exported cell are written.
#include <algorithm>
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "analysis/calibrate_config.hpp"
#include "analysis/report.hpp"
#include "core/error.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::TempDir;
using test::writeText;

const fs::path kExperiments = test::experimentsDir();

/// The InputError message of reading `toml` as a configuration ("" when it is accepted).
std::string configError(const TempDir& dir, const std::string& toml) {
    const fs::path file = writeText(dir.path() / "c.toml", toml);
    try {
        readCalibrateConfig(file, kExperiments);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(CalibrateConfig, DefaultsAreThePapersSevenDataSets) {
    TempDir dir;
    const CalibrateConfig c = readCalibrateConfig(writeText(dir.path() / "c.toml", "[run]\nseed = 3\n"), kExperiments);
    ASSERT_EQ(c.data.size(), 7u);
    EXPECT_EQ(c.data[0].name, "evans_fung_1972");
    EXPECT_EQ(c.data[6].experiment, "relaxation");
    EXPECT_EQ(c.seed, 3u);
    EXPECT_EQ(c.inferenceSamples, 50000);
    EXPECT_EQ(c.surrogateMode, "shipped");
}

TEST(CalibrateConfig, ShippedPaperConfigIsValid) {
    const CalibrateConfig c = readCalibrateConfig(fs::path(TRBC_TEST_DATA) / ".." / ".." / "configs" / "paper.toml", kExperiments);
    EXPECT_EQ(c.data.size(), 7u);
    EXPECT_EQ(c.inferenceSamples, 50000);  // the paper's population per TMCMC run
    EXPECT_EQ(c.surrogateMode, "shipped");
    EXPECT_FALSE(c.validationEnabled);
    const CalibrateConfig v = readCalibrateConfig(fs::path(TRBC_TEST_DATA) / ".." / ".." / "configs" / "paper_validated.toml", kExperiments);
    EXPECT_TRUE(v.validationEnabled);
    EXPECT_EQ(v.validationConfig.filename(), "validation.toml");
    EXPECT_EQ(v.validationOnly.size(), 3u);
    EXPECT_EQ(v.inferenceSamples, c.inferenceSamples);
    ASSERT_EQ(v.bases.size(), 1u);  // an override of paper.toml
    EXPECT_EQ(v.bases[0].filename(), "paper.toml");
    EXPECT_TRUE(c.bases.empty());
}

TEST(CalibrateConfig, BaseIsOverriddenKeyByKey) {
    TempDir dir;
    writeText(dir.path() / "base" / "mine.csv", test::slurp(kExperiments / "stretching" / "mills_2004" / "mills_2004.csv"));
    writeText(dir.path() / "base" / "b.toml",
              "[run]\nseed = 3\nthreads = 4\n[[data]]\nname = \"mine\"\nexperiment = \"stretching\"\nfile = \"mine.csv\"\n"
              "[inference]\nsamples = 1000\nfvk_density = \"nodes50\"\n");
    const fs::path file = writeText(dir.path() / "o.toml", "base = \"base/b.toml\"\n[inference]\nsamples = 2000\n[cell]\nenabled = false\n");
    const CalibrateConfig c = readCalibrateConfig(file, kExperiments);
    EXPECT_EQ(c.seed, 3u);
    EXPECT_EQ(c.threads, 4);
    EXPECT_EQ(c.inferenceSamples, 2000);   // overridden
    EXPECT_EQ(c.fvkDensity, "nodes50");    // the rest of the base's section kept
    EXPECT_FALSE(c.cellEnabled);
    ASSERT_EQ(c.data.size(), 1u);
    EXPECT_EQ(c.data[0].file, (dir.path() / "base" / "mine.csv").lexically_normal());  // relative to the base
    ASSERT_EQ(c.bases.size(), 1u);
    EXPECT_EQ(c.bases[0], (dir.path() / "base" / "b.toml").lexically_normal());
    // The merged copy stands alone and reads as the same configuration.
    const fs::path merged = writeText(dir.path() / "base" / "merged.toml", mergedCalibrateConfig(file));
    const CalibrateConfig m = readCalibrateConfig(merged, kExperiments);
    EXPECT_TRUE(m.bases.empty());
    EXPECT_EQ(m.inferenceSamples, 2000);
    EXPECT_EQ(m.fvkDensity, "nodes50");
    EXPECT_FALSE(m.cellEnabled);
    EXPECT_EQ(m.data[0].file, c.data[0].file);
}

TEST(CalibrateConfig, MissingBaseCycleAndErrorsInTheBaseNameTheirFile) {
    TempDir dir;
    std::string e = configError(dir, "# an override\nbase = \"nope.toml\"\n[run]\nseed = 1\n");
    EXPECT_NE(e.find("c.toml:2: base = \"nope.toml\""), std::string::npos) << e;
    EXPECT_NE(e.find("nope.toml does not exist"), std::string::npos) << e;
    e = configError(dir, "base = 3\n");
    EXPECT_NE(e.find("c.toml:1: 'base' must be the path of the configuration"), std::string::npos) << e;
    writeText(dir.path() / "a.toml", "base = \"b.toml\"\n");
    writeText(dir.path() / "b.toml", "# b\n\nbase = \"a.toml\"\n[run]\nseed = 1\n");
    e = configError(dir, "base = \"a.toml\"\n");
    EXPECT_NE(e.find("b.toml:3: base = \"a.toml\" makes a cycle"), std::string::npos) << e;
    EXPECT_NE(e.find("a.toml -> "), std::string::npos) << e;
    e = configError(dir, "base = \"c.toml\"\n");  // itself
    EXPECT_NE(e.find("makes a cycle"), std::string::npos) << e;
    writeText(dir.path() / "bad.toml", "[run]\nseed = 1\n[inference]\nsamples = 5\n");
    e = configError(dir, "base = \"bad.toml\"\n[run]\nseed = 2\n");
    EXPECT_NE(e.find("bad.toml:4: 'inference.samples' = 5 is out of range"), std::string::npos) << e;
    e = configError(dir, "base = \"bad.toml\"\n[inference]\nsamples = 7\n");  // the override's own line
    EXPECT_NE(e.find("c.toml:3: 'inference.samples' = 7 is out of range"), std::string::npos) << e;
}

TEST(CalibrateConfig, SyntaxErrorNamesFileAndLine) {
    TempDir dir;
    const std::string e = configError(dir, "[run]\nseed = 3\nthreads = = 2\n");
    EXPECT_NE(e.find("c.toml:3"), std::string::npos) << e;
    EXPECT_NE(e.find("syntax"), std::string::npos) << e;
}

TEST(CalibrateConfig, UnknownKeysAreErrorsWithLineAndValidKeys) {
    TempDir dir;
    std::string e = configError(dir, "[run]\nseed = 3\n\n[inference]\nsamples = 1000\nsampels = 2\n");
    EXPECT_NE(e.find("c.toml:6"), std::string::npos) << e;
    EXPECT_NE(e.find("inference.sampels"), std::string::npos) << e;
    EXPECT_NE(e.find("valid keys: samples, fvk_density, prior"), std::string::npos) << e;
    e = configError(dir, "[priors]\nv = 1\n");
    EXPECT_NE(e.find("unknown key 'priors'"), std::string::npos) << e;
}

TEST(CalibrateConfig, WrongTypesAndRangesNameKeyAndRange) {
    TempDir dir;
    std::string e = configError(dir, "[inference]\nsamples = \"many\"\n");
    EXPECT_NE(e.find("c.toml:2: 'inference.samples' must be an integer in [100, 10000000]"), std::string::npos) << e;
    e = configError(dir, "[inference]\nsamples = 10\n");
    EXPECT_NE(e.find("'inference.samples' = 10 is out of range: valid range [100, 10000000]"), std::string::npos) << e;
    e = configError(dir, "[cell]\nquantile = 1.5\n");
    EXPECT_NE(e.find("'cell.quantile' = 1.5 is out of range: valid range (0, 1)"), std::string::npos) << e;
    e = configError(dir, "[surrogate]\nmode = \"magic\"\n");
    EXPECT_NE(e.find("'surrogate.mode' = \"magic\" is not one of: shipped, train, path"), std::string::npos) << e;
    e = configError(dir, "[surrogate]\nmode = \"train\"\n");
    EXPECT_NE(e.find("campaign.mode = \"run\""), std::string::npos) << e;
    e = configError(dir, "[run]\nthreads = 0\n");
    EXPECT_NE(e.find("'run.threads' = 0 is out of range"), std::string::npos) << e;
}

TEST(CalibrateConfig, OutOfRangePriorsNameFileLineKeyAndValidRange) {
    TempDir dir;
    std::string e = configError(dir, "[inference]\nsamples = 1000\n\n[inference.prior]\nv = [0.8, 1.0]\nmu_uN_per_m = [0.5, 8]\n");
    EXPECT_NE(e.find("c.toml:6: 'inference.prior.mu_uN_per_m'"), std::string::npos) << e;
    EXPECT_NE(e.find("[0.5, 8] is out of range"), std::string::npos) << e;
    EXPECT_NE(e.find("[1, 10]"), std::string::npos) << e;
    e = configError(dir, "[inference.prior]\nb2 = [3, 1]\n");
    EXPECT_NE(e.find("c.toml:2: 'inference.prior.b2'"), std::string::npos) << e;
    e = configError(dir, "[inference.prior]\netam_Pa_s_um = 0.5\n");
    EXPECT_NE(e.find("c.toml:2: 'inference.prior.etam_Pa_s_um' must be an array [lo, hi] of two numbers inside [0.1, 1]"),
              std::string::npos) << e;
    e = configError(dir, "[inference.prior]\nkappa = [1, 2]\n");
    EXPECT_NE(e.find("c.toml:2: unknown key 'inference.prior.kappa'"), std::string::npos) << e;
    const fs::path ok = writeText(dir.path() / "ok.toml", "[inference.prior]\nv = [0.8, 1.0]\nkb_J = [2e-19, 5e-19]\n");
    const CalibrateConfig c = readCalibrateConfig(ok, kExperiments);
    ASSERT_EQ(c.inferencePrior.size(), 2u);
    const auto kb = std::find_if(c.inferencePrior.begin(), c.inferencePrior.end(), [](const auto& p) { return p.first == "kb_J"; });
    ASSERT_NE(kb, c.inferencePrior.end());
    EXPECT_DOUBLE_EQ(kb->second.second, 5e-19);
}

TEST(CalibrateConfig, ValidationSectionIsChecked) {
    TempDir dir;
    std::string e = configError(dir, "[validation]\nenabled = true\nonly = [\"angle\", \"tube2\"]\n");
    EXPECT_NE(e.find("c.toml:3: 'validation.only' must be an array of"), std::string::npos) << e;
    e = configError(dir, "[validation]\nconfig = \"missing.toml\"\n");
    EXPECT_NE(e.find("c.toml:2: validation.config"), std::string::npos) << e;
    EXPECT_NE(e.find("does not exist"), std::string::npos) << e;
    const fs::path ok = writeText(dir.path() / "ok.toml", "[validation]\nenabled = true\nonly = [\"ttf\"]\n");
    const CalibrateConfig c = readCalibrateConfig(ok, kExperiments);
    EXPECT_TRUE(c.validationEnabled);
    ASSERT_EQ(c.validationOnly.size(), 1u);
    EXPECT_EQ(c.validationOnly[0], "ttf");
}

TEST(CalibrationReport, TransferabilitySectionFromValidateOutputs) {
    TempDir dir;
    CalibrationReportInputs in;
    in.outputDirectory = dir.path();
    in.configFile = writeText(dir.path() / "c.toml", "");
    in.version = "test";
    std::string md = writeCalibrationReport(in).markdown(dir.path());
    EXPECT_NE(md.find("The flow validations did not run"), std::string::npos);
    writeText(dir.path() / "validation" / "validation.json",
              R"({"summary": {"cases": 3, "failed": 0, "inside": 2, "outside": 1, "no_data": 0}, "level": 2})");
    writeText(dir.path() / "validation" / "comparison.csv",
              "case,observable,predicted,scatter_lo,scatter_hi,points,verdict,window\n"
              "ttf_eta28.9_rate65.19,4 pi f / rate,0.346,0.27,0.39,7,inside,\"w\"\n");
    md = writeCalibrationReport(in).markdown(dir.path());
    EXPECT_NE(md.find("3 cases (0 failed); 2 predictions inside the experimental scatter, 1 outside"), std::string::npos) << md;
    EXPECT_NE(md.find("| ttf_eta28.9_rate65.19 | 4 pi f / rate | 0.346 | 0.27 – 0.39 | inside |"), std::string::npos) << md;
}

TEST(CalibrationReport, SurrogateSectionShowsCrossValidationOfTheSameData) {
    TempDir dir;
    CalibrationReportInputs in;
    in.outputDirectory = dir.path();
    in.configFile = writeText(dir.path() / "c.toml", "");
    in.version = "test";
    in.surrogateDirectory = dir.path() / "model";
    const std::string acc = R"({"command": "trbc surrogate train", "rows": 20, "cells": 10, "data_hash": "fnv1a:1",
        "test": [{"output": "tc_s", "n": 1, "rmse": 0.01, "relative_rmse": 0.036, "max_abs": 0.01, "r2": 0.99}]})";
    writeText(dir.path() / "model" / "accuracy.json", acc);
    std::string md = writeCalibrationReport(in).markdown(dir.path());
    EXPECT_NE(md.find("3.60 %"), std::string::npos) << md;
    EXPECT_EQ(md.find("cross-validation"), std::string::npos) << md;
    const std::string cv = R"({"folds": 10, "data_hash": "fnv1a:1",
        "pooled": [{"output": "tc_s", "n": 10, "rmse": 0.02, "relative_rmse": 0.069, "max_abs": 0.08, "r2": 0.98}]})";
    writeText(dir.path() / "model" / "cv.json", cv);
    md = writeCalibrationReport(in).markdown(dir.path());
    EXPECT_NE(md.find("10-fold cross-validation"), std::string::npos) << md;
    EXPECT_NE(md.find("6.90 %"), std::string::npos) << md;
    // a cross-validation of other data is not shown
    writeText(dir.path() / "model" / "cv.json", R"({"folds": 10, "data_hash": "fnv1a:2", "pooled": []})");
    md = writeCalibrationReport(in).markdown(dir.path());
    EXPECT_EQ(md.find("cross-validation"), std::string::npos) << md;
}

TEST(CalibrateConfig, DataEntriesAreChecked) {
    TempDir dir;
    std::string e = configError(dir, "[[data]]\nname = \"x\"\nexperiment = \"stretching\"\nfile = \"missing.csv\"\n");
    EXPECT_NE(e.find("does not exist"), std::string::npos) << e;
    EXPECT_NE(e.find("missing.csv"), std::string::npos) << e;
    e = configError(dir, "[[data]]\nname = \"x\"\nexperiment = \"bending\"\nfile = \"@experiments/equilibrium/evans_fung_1972.csv\"\n");
    EXPECT_NE(e.find("'data.experiment' = \"bending\" is not one of: equilibrium, stretching, relaxation"), std::string::npos) << e;
    e = configError(dir, "[[data]]\nname = \"x\"\nexperiment = \"equilibrium\"\nfile = \"@experiments/equilibrium/evans_fung_1972.csv\"\n"
                         "[[data]]\nname = \"x\"\nexperiment = \"equilibrium\"\nfile = \"@experiments/equilibrium/evans_fung_1972.csv\"\n");
    EXPECT_NE(e.find("c.toml:5: data name 'x' appears twice"), std::string::npos) << e;
}

TEST(CalibrateConfig, MalformedDataCsvNamesFileLineAndColumn) {
    TempDir dir;
    const std::string entry = "[[data]]\nname = \"mine\"\nexperiment = \"stretching\"\nfile = \"mine.csv\"\n";
    writeText(dir.path() / "mine.csv", "Fext,D0,D1\n0,7.8,7.8\n-10,7.0,8.5\n");
    std::string e = configError(dir, entry);
    EXPECT_NE(e.find("mine.csv:3: column 'Fext' = -10 is out of range"), std::string::npos) << e;
    writeText(dir.path() / "mine.csv", "Fext,D0,D1\n0,7.8,seven\n");
    e = configError(dir, entry);
    EXPECT_NE(e.find("mine.csv:2"), std::string::npos) << e;
    EXPECT_NE(e.find("D1"), std::string::npos) << e;
    writeText(dir.path() / "mine.csv", "force,width,length\n0,7.8,7.8\n");
    e = configError(dir, entry);
    EXPECT_NE(e.find("mine.csv"), std::string::npos) << e;
    EXPECT_NE(e.find("Fext"), std::string::npos) << e;
}

TEST(CalibrationReport, MarkdownAndSelfContainedHtml) {
    TempDir dir;
    const std::string png = "\x89PNG\r\n\x1a\nabc";
    writeText(dir.path() / "f.png", png);
    ReportDocument d;
    d.heading(1, "Title <x>");
    d.paragraph("uses `code` and **bold**");
    d.table({"a", "b|c"}, {{"1", "2"}});
    d.image(dir.path() / "f.png", "a figure");
    d.image(dir.path() / "none.png", "absent");
    const std::string md = d.markdown(dir.path());
    EXPECT_NE(md.find("# Title <x>"), std::string::npos);
    EXPECT_NE(md.find("| a | b\\|c |"), std::string::npos);
    EXPECT_NE(md.find("![a figure](f.png)"), std::string::npos);
    EXPECT_NE(md.find("figure not available: none.png"), std::string::npos);
    const std::string html = d.html("t");
    EXPECT_NE(html.find("<h1>Title &lt;x&gt;</h1>"), std::string::npos);
    EXPECT_NE(html.find("<code>code</code>"), std::string::npos);
    EXPECT_NE(html.find("<b>bold</b>"), std::string::npos);
    EXPECT_NE(html.find("data:image/png;base64," + base64Encode(png)), std::string::npos);
    EXPECT_EQ(base64Encode("Man"), "TWFu");
    EXPECT_EQ(base64Encode("Ma"), "TWE=");
    EXPECT_EQ(base64Encode("M"), "TQ==");
}

TEST(CalibrationReport, MeshConvergenceRecordsArePointAndLevelFilesOnly) {
    TempDir dir;
    EXPECT_TRUE(meshConvergenceRecords(dir.path() / "absent").empty());
    for (const char* f : {"reference_L4.json", "corner_soft_L3.json", "reference_L3.json", "table.md", "notes.json", "reference_L10.json"})
        writeText(dir.path() / f, "{}");
    fs::create_directories(dir.path() / "folder_L3.json");
    const std::vector<MeshConvergenceRecord> r = meshConvergenceRecords(dir.path());
    ASSERT_EQ(r.size(), 3u);
    EXPECT_EQ(r[0].file, dir.path() / "corner_soft_L3.json");
    EXPECT_EQ(r[0].point, "corner_soft");
    EXPECT_EQ(r[0].level, 3);
    EXPECT_EQ(r[1].point, "reference");
    EXPECT_EQ(r[1].level, 3);
    EXPECT_EQ(r[2].level, 4);
}

/// Stage names of the last run of OUT/stages.json.
std::set<std::string> lastRun(const fs::path& out, const char* which) {
    std::ifstream f(out / "stages.json");
    const nlohmann::json j = nlohmann::json::parse(f);
    std::set<std::string> s;
    for (const auto& x : j["last_run"][which]) s.insert(x.get<std::string>());
    return s;
}

TEST(CalibrateCli, RerunsOnlyTheStagesThatDependOnAChangedDataFile) {
    TempDir dir;
    // Own copy of the relaxation data of cell 3, so that the test can change it.
    fs::copy_file(kExperiments / "relaxation" / "hochmuth_1979" / "3.csv", dir.path() / "cell3.csv");
    std::string toml = "[run]\nseed = 5\nthreads = 1\n";
    for (const char* e : {"evans_fung_1972|equilibrium|@experiments/equilibrium/evans_fung_1972.csv",
                          "mills_2004|stretching|@experiments/stretching/mills_2004/mills_2004.csv",
                          "hochmuth_1979_cell1|relaxation|@experiments/relaxation/hochmuth_1979/1.csv",
                          "hochmuth_1979_cell3|relaxation|cell3.csv"}) {
        const std::string s(e);
        const auto a = s.find('|'), b = s.rfind('|');
        toml += "[[data]]\nname = \"" + s.substr(0, a) + "\"\nexperiment = \"" + s.substr(a + 1, b - a - 1) + "\"\nfile = \"" +
                s.substr(b + 1) + "\"\n";
    }
    toml += "[sobol]\nsamples = 16\nforces = 3\nresamples = 4\n[inference]\nsamples = 300\n[prediction]\nmax_samples = 100\ngrid = 10\n"
            "[cell]\nlevel = 1\n";
    const fs::path cfg = writeText(dir.path() / "cal.toml", toml);
    const fs::path out = dir.path() / "out";
    const std::string args = "calibrate --quiet --config " + cfg.string() + " --out " + out.string();

    test::CliRun r = test::runTrbc(args, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    for (const char* f : {"report.html", "report.md", "calibrate.json", "inference/posterior_stats.csv", "predict/coverage.csv",
                          "sobol/sobol_indices.csv", "cell/cell.json", "cell/sfs.off", "cell/equilibrium.ply"})
        EXPECT_TRUE(fs::exists(out / f)) << f;
    const std::set<std::string> all = lastRun(out, "ran");
    EXPECT_EQ(all.size(), 10u);  // data, sobol, 4 x phase 1, phase23, predict, cell, report
    EXPECT_TRUE(lastRun(out, "skipped").empty());
    const std::string md = test::slurp(out / "report.md");
    EXPECT_NE(md.find("Calibrated parameters"), std::string::npos);
    EXPECT_NE(md.find("data points"), std::string::npos);

    r = test::runTrbc(args, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(lastRun(out, "ran").empty());
    EXPECT_EQ(lastRun(out, "skipped"), all);

    {  // one aspect ratio of cell 3 changes
        std::string text = test::slurp(dir.path() / "cell3.csv");
        const auto eol = text.find('\n', text.find('\n') + 1);  // end of the first data line
        text = text.substr(0, eol) + "1" + text.substr(eol);   // append a digit to its last number
        std::ofstream(dir.path() / "cell3.csv") << text;
    }
    r = test::runTrbc(args, dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const std::set<std::string> expected = {"data", "inference.phase1.hochmuth_1979_cell3", "inference.phase23", "predict", "cell", "report"};
    EXPECT_EQ(lastRun(out, "ran"), expected);
    const std::set<std::string> skipped = lastRun(out, "skipped");
    for (const char* s : {"sobol", "inference.phase1.evans_fung_1972", "inference.phase1.mills_2004", "inference.phase1.hochmuth_1979_cell1"})
        EXPECT_TRUE(skipped.count(s)) << s;
}

TEST(CalibrateCli, BadConfigExitsWithStatus2BeforeAnyStage) {
    TempDir dir;
    const fs::path cfg = writeText(dir.path() / "bad.toml", "[inference]\nsamples = 1\n");
    const test::CliRun r = test::runTrbc("calibrate --config " + cfg.string() + " --out " + (dir.path() / "o").string(), dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("bad.toml:2: 'inference.samples' = 1 is out of range"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir.path() / "o" / "stages.json"));
    const test::CliRun m = test::runTrbc("calibrate --config " + (dir.path() / "nope.toml").string() + " --out " + (dir.path() / "o").string(),
                                         dir.path());
    EXPECT_EQ(m.status, 2);
    EXPECT_NE(m.err.find("nope.toml does not exist"), std::string::npos) << m.err;
}

TEST(InferCli, PriorOutsideTheTrainingBoxExitsWithStatus2NamingTheRange) {
    TempDir dir;
    const std::string out = (dir.path() / "o").string();
    test::CliRun r = test::runTrbc("infer --samples 100 --out " + out + " --prior etam_Pa_s_um=0.05:0.5", dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("prior of etam_Pa_s_um: [0.05, 0.5] is out of range"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("[0.1, 1]"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir.path() / "o" / "phase1"));
    r = test::runTrbc("infer --samples 100 --out " + out + " --prior v=high:1", dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("expected NAME=LO:HI"), std::string::npos) << r.err;
    // Resuming or running phase 2 on phase-1 posteriors of another prior box is refused.
    r = test::runTrbc("infer --phase 1 --samples 200 --quiet --out " + out + " --prior v=0.8:1", dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    r = test::runTrbc("infer --phase 2 --samples 200 --quiet --out " + out, dir.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("were made with the prior box"), std::string::npos) << r.err;
}

TEST(ExportCli, WritesMeshesAndParametersAtAQuantile) {
    TempDir dir;
    std::string csv = "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n";
    for (int k = 0; k < 11; ++k)
        csv += std::to_string(0.85 + 0.01 * k) + "," + std::to_string(3.0 + 0.2 * k) + "," + fmt::format("{:.6e}", (1.5 + 0.1 * k) * 1e-19) + "," +
               std::to_string(1.0 + 0.1 * k) + "," + std::to_string(0.5 + 0.02 * k) + "\n";
    writeText(dir.path() / "post" / "samples.csv", csv);
    const test::CliRun r = test::runTrbc("export --posterior " + (dir.path() / "post").string() + " --quantile 0.5 --level 1 --out " +
                                             (dir.path() / "cell").string(),
                                         dir.path());
    ASSERT_EQ(r.status, 0) << r.err;
    std::ifstream f(dir.path() / "cell" / "cell.json");
    const nlohmann::json j = nlohmann::json::parse(f);
    EXPECT_NEAR(j["physical"]["v"].get<double>(), 0.90, 1e-9);
    EXPECT_NEAR(j["physical"]["mu_uN_per_m"].get<double>(), 4.0, 1e-9);
    EXPECT_NEAR(j["physical"]["FvK"].get<double>(), 4.0 * 10.742958658 / 0.2, 1e-6);
    EXPECT_NEAR(j["dimensionless"]["kb"].get<double>() * j["physical"]["FvK"].get<double>(), 1.0, 1e-12);
    EXPECT_GT(j["observables"]["D_um"].get<double>(), 6.0);
    for (const char* m : {"sfs.off", "sfs.ply", "equilibrium.off", "equilibrium.ply"}) EXPECT_TRUE(fs::exists(dir.path() / "cell" / m)) << m;
    const test::CliRun bad = test::runTrbc("export --posterior " + (dir.path() / "none").string() + " --out " + (dir.path() / "c2").string(),
                                           dir.path());
    EXPECT_EQ(bad.status, 2);
    EXPECT_NE(bad.err.find("no samples.csv"), std::string::npos) << bad.err;
}

}  // namespace
}  // namespace trbc
