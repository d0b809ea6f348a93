// The stage table of trbc calibrate: every dependency is an earlier entry, the configuration gives
// the expected stages and commands, and a changed data file changes exactly the fingerprints of
// the stages downstream of it.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <set>

#include "analysis/calibrate_config.hpp"
#include "analysis/calibrate_stages.hpp"
#include "analysis/stage_ledger.hpp"
#include "core/error.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

const fs::path kSource = fs::path(TRBC_SOURCE_DIR);
const fs::path kExperiments = kSource / "data" / "experiments";

CalibrateTools tools() {
    CalibrateTools t;
    t.trbc = "/opt/trbc/bin/trbc";
    t.python = "/usr/bin/python3";
    t.scripts = "/opt/trbc/scripts";
    t.shippedSurrogates = kSource / "data" / "surrogates";
    t.validationConfig = "/opt/trbc/configs/validation.toml";
    return t;
}

CalibrateConfig config(const TempDir& dir, const std::string& toml) {
    const fs::path file = dir.path() / "c.toml";
    std::ofstream(file) << toml;
    return readCalibrateConfig(file, kExperiments);
}

const CalibrateStep& step(const std::vector<CalibrateStep>& steps, const std::string& name) {
    const auto it = std::find_if(steps.begin(), steps.end(), [&](const CalibrateStep& s) { return s.name == name; });
    if (it == steps.end()) throw std::runtime_error("no step " + name);
    return *it;
}

bool hasStep(const std::vector<CalibrateStep>& steps, const std::string& name) {
    return std::any_of(steps.begin(), steps.end(), [&](const CalibrateStep& s) { return s.name == name; });
}

const std::string kEverything =
    "[campaign]\nmode = \"run\"\nsamples = 12\nlevel = 2\n[surrogate]\nmode = \"train\"\n"
    "[validation]\nenabled = true\nonly = [\"ttf\", \"tube\"]\n[inference.prior]\nv = [0.75, 1.0]\n";

TEST(CalibrateStages, EveryDependencyIsAnEarlierEntry) {
    TempDir dir;
    for (const std::string& toml : {std::string("[run]\nseed = 1\n"), kEverything,
                                    std::string("[sobol]\nenabled = false\n[cell]\nenabled = false\n")}) {
        const std::vector<CalibrateStep> steps = calibrateSteps(config(dir, toml), "/out", 2, tools());
        std::set<std::string> seen;
        for (const CalibrateStep& s : steps) {
            for (const CalibrateStage& p : s.parts) {
                for (const std::string& d : stageDependencies(p)) EXPECT_TRUE(seen.count(d)) << p.name << " depends on " << d;
                seen.insert(p.name);
            }
            for (const std::string& d : stageDependencies(s.stage)) EXPECT_TRUE(seen.count(d)) << s.stage.name << " depends on " << d;
            EXPECT_TRUE(seen.insert(s.stage.name).second) << "entry named twice: " << s.stage.name;
        }
    }
}

TEST(CalibrateStages, TheConfigurationChoosesTheStages) {
    TempDir dir;
    std::vector<CalibrateStep> steps = calibrateSteps(config(dir, "[run]\nseed = 1\n"), "/out", 2, tools());
    std::vector<std::string> commandSteps;
    for (const CalibrateStep& s : steps)
        if (s.action != CalibrateAction::Fingerprint) commandSteps.push_back(s.name);
    EXPECT_EQ(commandSteps, (std::vector<std::string>{"data", "sobol", "inference", "predict", "cell", "report"}));
    ASSERT_EQ(step(steps, "inference").parts.size(), 7u);  // the seven data sets of the paper
    EXPECT_EQ(step(steps, "inference").parts[0].name, "inference.phase1.evans_fung_1972");
    EXPECT_EQ(step(steps, "inference").stage.name, "inference.phase23");

    steps = calibrateSteps(config(dir, kEverything), "/out", 2, tools());
    for (const char* s : {"campaign", "surrogate", "validation"}) EXPECT_TRUE(hasStep(steps, s)) << s;
    steps = calibrateSteps(config(dir, "[sobol]\nenabled = false\n[cell]\nenabled = false\n"), "/out", 2, tools());
    for (const char* s : {"campaign", "surrogate", "sobol", "cell", "validation"}) EXPECT_FALSE(hasStep(steps, s)) << s;
}

TEST(CalibrateStages, CommandsOfAConfiguration) {
    TempDir dir;
    const std::vector<CalibrateStep> steps = calibrateSteps(config(dir, kEverything + "[run]\nseed = 9\n"), "/out", 3, tools());
    const std::string trbc = "'/opt/trbc/bin/trbc' ";
    EXPECT_EQ(step(steps, "campaign").commands,
              std::vector<std::string>{trbc + "campaign --samples 12 --forces-per-cell 20 --design uniform --seed 9 --level 2 --threads 3 "
                                              "--out '/out/campaign' --resume"});
    EXPECT_EQ(step(steps, "surrogate").commands,
              std::vector<std::string>{trbc + "surrogate train --data '/out/campaign' --out '/out/surrogate' --seed 9 --threads 3"});
    EXPECT_EQ(step(steps, "sobol").commands,
              std::vector<std::string>{trbc + "sobol --model '/out/surrogate' --samples 1024 --forces 100 --resamples 100 --seed 9 "
                                              "--threads 3 --no-plot --out '/out/sobol'"});
    EXPECT_EQ(step(steps, "sobol").optionalCommands,
              std::vector<std::string>{"'/usr/bin/python3' '/opt/trbc/scripts/plot_sobol.py' '/out/sobol'"});
    const CalibrateStep& inference = step(steps, "inference");
    EXPECT_EQ(inference.commands,
              std::vector<std::string>{trbc + "infer --out '/out/inference' --data-dir '/out/data' --model '/out/surrogate' --samples 50000 "
                                              "--seed 9 --fvk-density closed --threads 3 --resume --prior v=0.75:1"});
    EXPECT_EQ(inference.recorded, inference.commands);  // the figures are not part of the posteriors' record
    EXPECT_EQ(step(steps, "predict").commands,
              std::vector<std::string>{trbc + "predict --inference '/out/inference' --out '/out/predict' --data-dir '/out/data' --model "
                                              "'/out/surrogate' --max-samples 5000 --grid 100 --seed 9 --threads 3 --quiet"});
    EXPECT_EQ(step(steps, "cell").commands,
              std::vector<std::string>{trbc + "export --posterior '/out/inference/phase3/theta_new' --quantile 0.5 --level 4 --threads 3 "
                                              "--out '/out/cell' > /dev/null"});
    const CalibrateStep& validation = step(steps, "validation");
    EXPECT_TRUE(validation.commands.empty());  // hours, and optional: a failure only warns
    EXPECT_EQ(validation.optionalCommands,
              std::vector<std::string>{trbc + "validate --config '/opt/trbc/configs/validation.toml' --posterior "
                                              "'/out/inference/phase3/theta_new' --out '/out/validation' --threads 1 --only ttf,tube --quiet"});
    EXPECT_TRUE(validation.stage.clean.empty());  // finished cases are kept
}

/// The fingerprint of every entry of the table, with the ledger of an empty OUT.
std::map<std::string, std::string> fingerprints(const std::vector<CalibrateStep>& steps, const fs::path& out) {
    const StageLedger ledger(out);
    std::map<std::string, std::string> known;
    for (const CalibrateStep& s : steps) {
        for (const CalibrateStage& p : s.parts) known[p.name] = stageFingerprint(p, known, ledger);
        known[s.stage.name] = stageFingerprint(s.stage, known, ledger);
    }
    return known;
}

TEST(CalibrateStages, AChangedDataFileChangesExactlyTheStagesDownstream) {
    TempDir dir;
    fs::copy_file(kExperiments / "relaxation" / "hochmuth_1979" / "3.csv", dir.path() / "cell3.csv");
    const std::string toml =
        "[[data]]\nname = \"mills_2004\"\nexperiment = \"stretching\"\nfile = \"@experiments/stretching/mills_2004/mills_2004.csv\"\n"
        "[[data]]\nname = \"cell3\"\nexperiment = \"relaxation\"\nfile = \"cell3.csv\"\n";
    const CalibrateConfig cfg = config(dir, toml);
    const std::vector<CalibrateStep> steps = calibrateSteps(cfg, dir.path() / "out", 2, tools());
    const std::map<std::string, std::string> before = fingerprints(steps, dir.path() / "out");
    std::ofstream(dir.path() / "cell3.csv", std::ios::app) << "0.5,1.05\n";
    const std::map<std::string, std::string> after = fingerprints(steps, dir.path() / "out");
    ASSERT_EQ(before.size(), after.size());
    std::set<std::string> changed;
    for (const auto& [name, fp] : before)
        if (after.at(name) != fp) changed.insert(name);
    const std::set<std::string> expected = {"dataset.cell3", "data", "datasets", "inference.phase1.cell3", "inference.phase23",
                                            "predict", "cell", "report"};
    EXPECT_EQ(changed, expected);
}

TEST(CalibrateStages, AChangedBaseOfTheValidationConfigChangesTheValidationStage) {
    TempDir dir;
    std::ofstream(dir.path() / "base.toml") << "[run]\nlevel = 2\n";
    std::ofstream(dir.path() / "v.toml") << "base = \"base.toml\"\n[run]\njobs = 2\n";
    const std::vector<CalibrateStep> steps = calibrateSteps(
        config(dir, "[validation]\nenabled = true\nconfig = \"" + (dir.path() / "v.toml").string() + "\"\n"), "/out", 2, tools());
    const std::map<std::string, std::string> before = fingerprints(steps, dir.path() / "out");
    std::ofstream(dir.path() / "base.toml", std::ios::app) << "threads = 3\n";
    const std::vector<CalibrateStep> again = calibrateSteps(
        config(dir, "[validation]\nenabled = true\nconfig = \"" + (dir.path() / "v.toml").string() + "\"\n"), "/out", 2, tools());
    const std::map<std::string, std::string> after = fingerprints(again, dir.path() / "out");
    std::set<std::string> changed;
    for (const auto& [name, fp] : before)
        if (after.at(name) != fp) changed.insert(name);
    EXPECT_EQ(changed, (std::set<std::string>{"validation", "report"}));
}

TEST(CalibrateStages, ARemadeMeshConvergenceRecordChangesOnlyTheReport) {
    TempDir dir;
    CalibrateTools t = tools();
    t.meshConvergence = dir.path() / "mesh";
    fs::create_directories(t.meshConvergence);
    std::ofstream(t.meshConvergence / "reference_L3.json") << R"({"observables": {"tc_s": 0.1762}})";
    const CalibrateConfig cfg = config(dir, "[run]\nseed = 1\n");
    const std::map<std::string, std::string> before = fingerprints(calibrateSteps(cfg, dir.path() / "out", 2, t), dir.path() / "out");
    std::ofstream(t.meshConvergence / "reference_L3.json") << R"({"observables": {"tc_s": 0.1766}})";
    const std::map<std::string, std::string> remade = fingerprints(calibrateSteps(cfg, dir.path() / "out", 2, t), dir.path() / "out");
    std::ofstream(t.meshConvergence / "reference_L4.json") << R"({"observables": {"tc_s": 0.1680}})";
    const std::map<std::string, std::string> added = fingerprints(calibrateSteps(cfg, dir.path() / "out", 2, t), dir.path() / "out");
    for (const auto* after : {&remade, &added}) {
        std::set<std::string> changed;
        for (const auto& [name, fp] : before)
            if (after->at(name) != fp) changed.insert(name);
        EXPECT_EQ(changed, (std::set<std::string>{"report"}));
    }
    EXPECT_NE(remade.at("report"), added.at("report"));
    // The table's other files are not records: they leave the report's fingerprint alone.
    std::ofstream(t.meshConvergence / "table.md") << "| point |";
    std::ofstream(t.meshConvergence / "notes.json") << "{}";
    EXPECT_EQ(fingerprints(calibrateSteps(cfg, dir.path() / "out", 2, t), dir.path() / "out"), added);
}

TEST(CalibrateStages, MissingNetworksNameTheSurrogateDirectory) {
    TempDir dir;
    const std::string toml = "[surrogate]\nmode = \"path\"\ndir = \"" + dir.path().string() + "\"\n";
    const std::vector<CalibrateStep> steps = calibrateSteps(config(dir, toml), dir.path() / "out", 2, tools());
    try {
        fingerprints(steps, dir.path() / "out");
        FAIL() << "no error for a surrogate directory without networks";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("lacks equilibrium.json"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace trbc
