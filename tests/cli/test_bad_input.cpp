// Bad input never gives a silent wrong answer: each case below once exited 0 with a wrong or
// partial result, or with a misleading message. Each must now exit non-zero with a message that
// names the option, file or line and the valid range, and leave no output behind.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/csv.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::CliRun;
using test::runShell;
using test::runTrbc;
using test::shellQuote;
using test::TempDir;
using test::writeText;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(BadInput, NonFiniteAndOutOfRangeNumbersNameTheOptionAndItsUnit) {
    TempDir tmp;
    const struct {
        std::string args, expect;
    } cases[] = {
        {"sfs --v 0.95 --tol nan --out x.off", "--tol: 'nan' is not a finite number (valid: (0, 1] kappa / R'_A)"},
        {"flow shear --eta-out 1 --shear-rate 1 --dt nan", "--dt: 'nan' is not a finite number (valid: (0, 100] 1/rate)"},
        {"flow shear --eta-out 1 --shear-rate 1 --rotations nan", "--rotations: 'nan' is not a finite number"},
        {"flow shear --eta-out 1 --shear-rate 1 --step-tol 1e300", "--step-tol: 1e300 is out of range (valid: (0, 1] R_A)"},
        {"flow tube --radius 1 --pressure-gradient 1", "--radius: 1 is out of range (valid: [1.4"},
        {"mesh icosphere --area nan --out m.off", "--area: 'nan' is not a finite number"},
        {"mesh icosphere --area 1e300 --out m.off", "--area: 1e300 is out of range (valid: [0, 1e100]"},
        {"minimize --mesh m.off --out r.off --kV 1 --reduced-volume nan", "--reduced-volume: 'nan' is not a finite number (valid: (0, 1])"},
        {"minimize --mesh m.off --out r.off --max-step 1e309", "--max-step: '1e309' is not a finite number"},
        {"sobol --samples 12abc --out s", "--samples: '12abc' is not a number"},
        {"sobol --samples 2.5 --out s", "--samples: '2.5' is not a whole number"},
        {"infer --samples 2 --out i", "--samples: 2 is out of range (valid: [100, 1e6])"},
        // --datasets is checked before the model or the data are read.
        {"infer --model absent --datasets paper,mills_2004 --out i", "the keyword 'paper' stands alone"},
        {"export --posterior p --quantile 1 --out x", "--quantile: 1 is out of range (valid: (0, 1))"},
        {"campaign --samples 1 --level 1 --out c", "--level: 1 is out of range (valid: [2, 6])"},
        {"flow distill --model . --samples 10 --out d", "--samples: 10 is out of range (valid: [1000, 1e7])"},
        {"flow distill --model . --hidden 8,0 --out d", "--hidden: '0' is not a layer width (integer in [1, 4096])"},
        {"flow distill --model . --hidden 8,4097 --out d", "--hidden: '4097' is not a layer width (integer in [1, 4096])"},
    };
    for (const auto& c : cases) {
        const CliRun r = runTrbc(c.args, tmp.path());
        EXPECT_EQ(r.status, 2) << c.args;
        EXPECT_TRUE(contains(r.err, "trbc: error: ")) << c.args << "\n" << r.err;
        EXPECT_TRUE(contains(r.err, c.expect)) << c.args << "\n" << r.err;
        // Unbounded ranges are written as "> 0", never as the 309 digits of the largest double.
        EXPECT_FALSE(contains(r.err, "17976931348623157")) << r.err;
        EXPECT_LT(r.err.size(), 400u) << r.err;
    }
    EXPECT_FALSE(fs::exists(tmp.path() / "m.off"));
}

TEST(BadInput, AnUnknownSimdPathInTheEnvironmentIsRefusedBeforeAnyWork) {
    // Read once at the start: a bad value fails there with exit 2, never inside a parallel region.
    const TempDir tmp;
    const CliRun r = runShell("TRBC_SIMD=avx9 " + shellQuote(TRBC_CLI) + " simulate --level 2 --no-cache", tmp.path());
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_NE(r.err.find("environment variable TRBC_SIMD: 'avx9' is not a SIMD path (valid: portable, avx2)"), std::string::npos)
        << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
    const CliRun ok = runShell("TRBC_SIMD=portable " + shellQuote(TRBC_CLI) + " simulate --level 2 --no-cache", tmp.path());
    EXPECT_EQ(ok.status, 0) << ok.err;
}

TEST(BadInput, InferListsItsDataSetsAndNamesAnUnknownOne) {
    TempDir tmp;
    const CliRun list = runTrbc("infer --datasets list", tmp.path());
    ASSERT_EQ(list.status, 0) << list.err;
    for (const char* name : {"evans_fung_1972", "hochmuth_1979_cell4", "fischer_2015_donor1", "fischer_2015_donor7",
                             "fischer_ttf_donors12", "fischer_2013_critical_stress", "abkarian_2007_critical_stress"})
        EXPECT_TRUE(contains(list.out, name)) << name << "\n" << list.out;
    EXPECT_EQ(std::count(list.out.begin(), list.out.end(), '\n'), 17);
    const std::string out = " --out " + (tmp.path() / "i").string();
    CliRun r = runTrbc("infer --datasets mills_2004,fischer_2015_donor9" + out, tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "'fischer_2015_donor9' is not a data set")) << r.err;
    EXPECT_TRUE(contains(r.err, "fischer_2015_donor7")) << r.err;
    // Refused before --out is made.
    r = runTrbc("infer --datasets mills_2004,fischer_2015_donor1 --method reweighting" + out, tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "fischer_2015_donor1 is a flow data set, which only --method joint takes")) << r.err;
    r = runTrbc("infer --datasets all", tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "--out is required")) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "i"));
}

// A flow set's phase-1 posterior belongs to the flow networks it was made with: --resume with other
// networks is refused, naming them, instead of reusing it.
TEST(BadInput, InferResumeRefusesAFlowSetsPhase1OfOtherNetworks) {
    TempDir tmp;
    const std::string run =
        "infer --datasets abkarian_2007_critical_stress --phase 1 --samples 100 --quiet --out " + (tmp.path() / "i").string();
    CliRun r = runTrbc(run, tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    r = runTrbc(run + " --resume", tmp.path());
    EXPECT_EQ(r.status, 0) << r.err;
    r = runTrbc(run + " --resume --flow-model " + (fs::path(TRBC_SOURCE_DIR) / "data/surrogates/flow").string(), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "were made with the prior box (and flow networks)")) << r.err;
    EXPECT_TRUE(contains(r.err, "--flow-model")) << r.err;
}

// flow distill refuses before training: --out over its own ensemble, a --model without the
// training.json whose accuracy the student's record carries.
TEST(BadInput, FlowDistillKeepsItsEnsembleAndNamesAMissingTrainingJson) {
    TempDir tmp;
    const fs::path model = tmp.path() / "m";
    fs::create_directories(model);
    for (const char* f : {"flow_regime.json", "flow_tank_treading.json", "flow_surrogate.json", "training.json"})
        fs::copy_file(fs::path(TRBC_SOURCE_DIR) / "data/surrogates/flow" / f, model / f);
    CliRun r = runTrbc("flow distill --model " + model.string() + " --out " + model.string(), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "is the --model directory")) << r.err;
    fs::remove(model / "training.json");
    r = runTrbc("flow distill --model " + model.string() + " --out " + (tmp.path() / "d").string(), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, (model / "training.json").string() + ": missing")) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "d"));
}

TEST(BadInput, UnknownCommandsAreNamedWithASuggestion) {
    TempDir tmp;
    CliRun r = runTrbc("simulat --level 2", tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "trbc: error: unknown command 'simulat'")) << r.err;
    EXPECT_TRUE(contains(r.err, "did you mean 'simulate'?")) << r.err;
    r = runTrbc("surrogate evl --in x", tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "did you mean 'eval'?")) << r.err;
    r = runTrbc("mesh", tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "trbc: error: 'mesh' needs a command: one of info, icosphere")) << r.err;
    EXPECT_EQ(runTrbc("mesh --help", tmp.path()).status, 0);
}

TEST(BadInput, MeshReadersNameDirectoriesAndReadTheirOwnPlyAndVtk) {
    TempDir tmp;
    CliRun r = runTrbc("mesh info " + shellQuote(tmp.path().string()), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "is a directory, not a mesh file")) << r.err;
    for (const char* ext : {"off", "ply", "vtk"}) {
        const fs::path m = tmp.path() / fmt::format("with space/ico.{}", ext);
        fs::create_directories(m.parent_path());
        r = runTrbc("mesh icosphere --level 2 --biconcave --area 135 --out " + shellQuote(m.string()), tmp.path());
        ASSERT_EQ(r.status, 0) << r.err;
        // The provenance command can be pasted back into a shell: the path with a space is quoted.
        const auto made = nlohmann::json::parse(r.out);
        EXPECT_TRUE(contains(made["provenance"]["command"].get<std::string>(), shellQuote(m.string()))) << made.dump();
        r = runTrbc("mesh info " + shellQuote(m.string()), tmp.path());
        ASSERT_EQ(r.status, 0) << ext << ": " << r.err;
        const auto info = nlohmann::json::parse(r.out);
        EXPECT_EQ(info["vertices"], 162);
        EXPECT_NEAR(info["area"].get<double>(), 135.0, 1e-9);
        EXPECT_NEAR(info["volume"].get<double>(), made["volume"].get<double>(), 1e-9);
    }
    EXPECT_TRUE(fs::directory_iterator(tmp.path() / "with space") != fs::directory_iterator());
    for (const auto& e : fs::directory_iterator(tmp.path() / "with space")) EXPECT_NE(e.path().extension(), ".tmp");
}

TEST(BadInput, SurrogateEvalRefusesImpossibleRowsAndFlagsExtrapolation) {
    TempDir tmp;
    const std::string header = "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN\n", good = "0.95,4,250,1.5,0.7,100\n";
    const struct {
        std::string row, expect;
    } impossible[] = {
        {"0.95,4,250,-1,0.7,100\n", "b2 = -1 is not physical"},
        {"1.5,4,250,1.5,0.7,100\n", "v = 1.5 is not physical"},
        {"-3,4,250,1.5,0.7,100\n", "v = -3 is not physical"},
        {"0.95,4,250,1.5,0.7,-100\n", "Fext_pN = -100 is not physical"},
    };
    const fs::path out = tmp.path() / "e.csv";
    for (const auto& c : impossible) {
        const fs::path in = writeText(tmp.path() / "in.csv", header + good + c.row);
        const CliRun r = runTrbc("surrogate eval --in " + in.string() + " --out " + out.string(), tmp.path());
        EXPECT_EQ(r.status, 2) << c.row;
        EXPECT_TRUE(contains(r.err, in.string() + ":3: parameter " + c.expect)) << r.err;
        EXPECT_FALSE(fs::exists(out));
    }
    // Physical but outside the training box (v = 0.5, Fext = 300 pN): evaluated and flagged.
    const fs::path in = writeText(tmp.path() / "in.csv", header + good + "0.5,4,250,1.5,0.7,300\n");
    CliRun r = runTrbc("surrogate eval --in " + in.string() + " --out " + out.string(), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string csv = test::slurp(out);
    EXPECT_FALSE(contains(csv, "nan"));
    EXPECT_TRUE(contains(csv, ",0\n0.5,")) << csv;  // first row inside the box, second flagged
    EXPECT_EQ(csv.back(), '\n');
    EXPECT_EQ(csv.substr(csv.size() - 3), ",1\n") << csv;
    EXPECT_TRUE(contains(r.err, "1 outside the training box")) << r.err;

    // A full device is an error, not "2 rows written".
    if (fs::exists("/dev/full")) {
        r = runTrbc("surrogate eval --in " + in.string() + " --out /dev/full", tmp.path());
        EXPECT_NE(r.status, 0);
        EXPECT_TRUE(contains(r.err, "cannot write /dev/full")) << r.err;
    }
}

/// A copy of the shipped experimental data with one stretching force set to `force`.
fs::path dataWithForce(const fs::path& dir, const std::string& force) {
    const fs::path src = fs::path(TRBC_SOURCE_DIR) / "data" / "experiments";
    const fs::path dst = dir / "experiments";
    fs::create_directories(dir);
    fs::copy(src, dst, fs::copy_options::recursive);
    const fs::path mills = dst / "stretching" / "mills_2004" / "mills_2004.csv";
    std::string text = test::slurp(mills);
    text += force + ",4.2,15.5\n";
    writeText(mills, text);
    return dst;
}

TEST(BadInput, DataBeyondTheSurrogatesForceRangeIsRefused) {
    TempDir tmp;
    for (const std::string force : {"900", "1e9"}) {
        const fs::path data = dataWithForce(tmp.path() / force, force);
        const fs::path out = tmp.path() / force / "inference";
        const CliRun r =
            runTrbc("infer --samples 100 --quiet --data-dir " + data.string() + " --out " + out.string(), tmp.path());
        EXPECT_EQ(r.status, 2) << r.err;
        EXPECT_TRUE(contains(r.err, "mills_2004.csv:")) << r.err;
        EXPECT_TRUE(contains(r.err, "column 'Fext' = " + std::string(force == "900" ? "900" : "1000000000"))) << r.err;
        EXPECT_TRUE(contains(r.err, "trained on [0, 200] pN only")) << r.err;
        // Nothing written: not even the prior box of phase 1.
        EXPECT_FALSE(fs::exists(out / "phase1_prior_box.json"));
    }
    // calibrate reads the configured data sets before any stage, with the same check.
    const fs::path data = dataWithForce(tmp.path() / "cal", "900");
    const fs::path cfg = writeText(tmp.path() / "cal" / "c.toml", "[[data]]\nname = \"m\"\nexperiment = \"stretching\"\nfile = \"" +
                                                                       (data / "stretching" / "mills_2004" / "mills_2004.csv").string() +
                                                                       "\"\n");
    const CliRun r = runTrbc("calibrate --config " + cfg.string() + " --out " + (tmp.path() / "cal" / "o").string(), tmp.path());
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_TRUE(contains(r.err, "trained on [0, 200] pN only")) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "cal" / "o" / "stages.json"));
}

TEST(BadInput, CalibrateOutputDirectoryRules) {
    TempDir tmp;
    // --config OUT/config.toml --out OUT: the configuration is already in place (no "File exists").
    // The surrogate directory lacks its networks, so the run stops right after the data stage.
    const fs::path out = tmp.path() / "run";
    fs::create_directories(out);
    fs::create_directories(tmp.path() / "nomodel");
    const std::string toml = "[surrogate]\nmode = \"path\"\ndir = \"../nomodel\"\n";
    writeText(out / "config.toml", toml);
    CliRun r = runTrbc("calibrate --quiet --config " + (out / "config.toml").string() + " --out " + out.string(), tmp.path());
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_FALSE(contains(r.err, "internal error")) << r.err;
    EXPECT_TRUE(contains(r.err, "lacks equilibrium.json")) << r.err;
    EXPECT_EQ(test::slurp(out / "config.toml"), toml);

    // A directory that is not a calibrate output is refused, its files untouched.
    const fs::path other = tmp.path() / "other";
    fs::create_directories(other);
    writeText(other / "report.md", "mine\n");
    const fs::path cfg = writeText(tmp.path() / "c.toml", toml);
    r = runTrbc("calibrate --quiet --config " + cfg.string() + " --out " + other.string(), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "that `trbc calibrate` did not write")) << r.err;
    EXPECT_EQ(test::slurp(other / "report.md"), "mine\n");
    EXPECT_FALSE(fs::exists(other / "config.toml"));

    // An empty configuration would silently run the whole paper pipeline.
    const fs::path empty = writeText(tmp.path() / "empty.toml", "# nothing\n");
    r = runTrbc("calibrate --config " + empty.string() + " --out " + (tmp.path() / "e").string(), tmp.path());
    EXPECT_EQ(r.status, 2);
    EXPECT_TRUE(contains(r.err, "the configuration is empty")) << r.err;
}

TEST(BadInput, SimulateTimeLimitStopsWithProgressOnStderr) {
    TempDir tmp;
    const auto t0 = std::chrono::steady_clock::now();
    const CliRun r = runTrbc("simulate --level 4 --no-cache --time-limit 1", tmp.path());
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(r.status, 3) << r.err;
    EXPECT_LT(wall, 60.0);
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["status"], "failed");
    EXPECT_TRUE(contains(j["reason"].get<std::string>(), "time limit reached: --time-limit 1 s ran out during the")) << j.dump();
    EXPECT_TRUE(contains(r.err, "simulate: stress-free state (v = 0.95, level 4)")) << r.err;
}

TEST(BadInput, MinimizeWritesNoShapeWhenItDoesNotConverge) {
    TempDir tmp;
    const fs::path m = tmp.path() / "m.off", out = tmp.path() / "R.vtk";
    ASSERT_EQ(runTrbc("mesh icosphere --level 2 --out " + m.string(), tmp.path()).status, 0);
    const CliRun r = runTrbc("minimize --mesh " + m.string() + " --kb 1 --kV 1 --reduced-volume 0.6 --max-iter 3 --out " + out.string(),
                             tmp.path());
    EXPECT_EQ(r.status, 3) << r.err;
    EXPECT_FALSE(fs::exists(out));
    EXPECT_TRUE(contains(r.err, "nothing written to " + out.string())) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["status"], "failed");
    EXPECT_TRUE(j["output"].is_null());
}

TEST(BadInput, UnresolvedSobolIndicesAreFlagged) {
    TempDir tmp;
    const fs::path out = tmp.path() / "s";
    const CliRun r = runTrbc("sobol --samples 2 --forces 2 --resamples 4 --no-plot --out " + out.string(), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "sobol: warning: N = 2 base rows do not resolve the indices")) << r.err;
    EXPECT_TRUE(contains(r.out, "+-")) << r.out;  // the promised CI half-widths are printed
    std::ifstream in(out / "sobol.json");
    const auto j = nlohmann::json::parse(in);
    EXPECT_FALSE(j["resolved"].get<bool>());
}

TEST(BadInput, ExportOfATailQuantileOutsideThePriorBoxWarns) {
    TempDir tmp;
    // mu spread over [0.2, 6] uN/m: its 0.001 quantile lies below the prior's 1 uN/m.
    std::string csv = "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n";
    for (int k = 0; k < 40; ++k) csv += fmt::format("0.95,{},2e-19,1.5,0.7\n", 0.2 + 0.15 * k);
    const fs::path theta = writeText(tmp.path() / "theta.csv", csv);
    const fs::path out = tmp.path() / "x";
    const CliRun r = runTrbc("export --posterior " + theta.string() + " --quantile 0.001 --level 2 --cache " +
                                 (tmp.path() / "cache").string() + " --out " + out.string(),
                             tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "export: warning: --quantile 0.001 gives a cell outside the prior box")) << r.err;
    std::ifstream in(out / "cell.json");
    const auto j = nlohmann::json::parse(in);
    EXPECT_TRUE(contains(j["warning"].get<std::string>(), "mu_uN_per_m")) << j.dump();
}

}  // namespace
}  // namespace trbc

namespace trbc {
namespace {

TEST(BadInput, MessagesAndOutputsSayWhatTheirNumbersMean) {
    TempDir tmp;
    const std::string cache = " --cache " + shellQuote((tmp.path() / "cache").string());
    // The tube fit names the user's option and its unit (um), not the internal length unit R_A.
    CliRun r = runTrbc("flow tube --level 1 --radius 1.5 --pressure-gradient 1 --duration 0.01 --settle 0" + cache, tmp.path());
    EXPECT_EQ(r.status, 3) << r.err;
    EXPECT_TRUE(contains(r.err, "a tube of --radius 1.5 um")) << r.err;
    EXPECT_FALSE(contains(r.err, "R_A")) << r.err;
    // The relaxation fit's z, z0, t0_s, zinf and rms are explained next to them.
    const fs::path shapes = tmp.path() / "shapes";
    r = runTrbc("simulate --level 2 --experiments relax --save-shapes " + shapes.string() + cache, tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    const std::string law = j["relaxation_fit"]["law"];
    for (const char* term : {"z = L/W", "z0 = z at the first sample", "t0_s its time", "zinf", "rms = root-mean-square residual"})
        EXPECT_TRUE(contains(law, term)) << term;
    // The fit starts at the first sample after release (t = 0), where z = z0: relaxation.csv's second row.
    const std::vector<std::vector<std::string>> rows = readCsvRecords(shapes / "relaxation.csv");
    ASSERT_GT(rows.size(), 3u);
    const int tCol = columnOf(rows[0], "t_s"), zCol = columnOf(rows[0], "z");
    ASSERT_TRUE(tCol >= 0 && zCol >= 0);
    EXPECT_EQ(std::stod(rows[1][static_cast<std::size_t>(tCol)]), 0.0);
    const double t0 = j["relaxation_fit"]["t0_s"], z0 = j["relaxation_fit"]["z0"];
    EXPECT_NEAR(t0, std::stod(rows[2][static_cast<std::size_t>(tCol)]), 1e-9 * t0);
    EXPECT_NEAR(z0, std::stod(rows[2][static_cast<std::size_t>(zCol)]), 1e-9 * z0);
    // coverage.csv's x and y are explained in coverage.md.
    const fs::path inf = tmp.path() / "inference", pred = tmp.path() / "predict";
    ASSERT_EQ(runTrbc("infer --phase 1 --samples 100 --quiet --out " + inf.string(), tmp.path()).status, 0);
    r = runTrbc("predict --posterior " + (inf / "phase1" / "mills_2004").string() + " --max-samples 50 --quiet --out " + pred.string(),
                tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string md = test::slurp(pred / "coverage.md");
    EXPECT_TRUE(contains(md, "x is that force (pN, stretching) or time (s, relaxation")) << md;
}

}  // namespace
}  // namespace trbc
