// The command line under hostile numbers: every numeric option of every subcommand (found in the
// subcommand's --help, so that a new option is covered without touching this file) gets the values
// nan, inf, -inf, -1, 0, 1e300 and a non-number on top of a small valid command. Each invocation
// must, within a time bound, either exit 2 with "trbc: error:" naming the option and write nothing,
// or run: exit 0 with its output written, or a clean numerical failure (exit 3) without it. Never a
// hang, a signal, an internal error (exit 4), nor a NaN or an infinity printed as a result.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "sampling/campaign.hpp"
#include "sampling/campaign_table.hpp"
#include "sampling/design.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::CliRun;
using test::runShell;
using test::runTrbc;
using test::shellQuote;
using test::TempDir;

const std::vector<std::string> kHostileValues = {"nan", "inf", "-inf", "-1", "0", "1e300", "abc"};
// Values that no numeric option may accept.
const std::set<std::string> kNeverValid = {"nan", "inf", "-inf", "abc"};
constexpr int kTimeoutSeconds = 60;

/// The numeric options that `trbc <command> --help` lists (CLI11 prints FLOAT, INT or UINT as the
/// type of a numeric option).
std::vector<std::string> numericOptions(const std::string& command, const fs::path& scratch) {
    const CliRun r = runTrbc(command + " --help", scratch);
    EXPECT_EQ(r.status, 0) << command << " --help\n" << r.err;
    std::vector<std::string> options;
    const std::regex line(R"(^\s+(?:-\w,\s*)?(--[A-Za-z0-9][A-Za-z0-9-]*)\s+(FLOAT|INT|UINT)\b)");
    std::istringstream in(r.out);
    std::string s;
    std::smatch m;
    while (std::getline(in, s))
        if (std::regex_search(s, m, line)) options.push_back(m[1]);
    return options;
}

/// A base command as option/value pairs, so that the fuzzed option replaces its own entry.
struct Command {
    std::string name;                                        ///< e.g. "surrogate eval"
    std::vector<std::pair<std::string, std::string>> args;  ///< "{RUN}" is the invocation's own directory
    std::string output;            ///< relative to {RUN}: present after exit 0, absent otherwise ("" = none)
    std::string validFailure;      ///< with valid values the base command fails on purpose with exit 2 naming this
    std::size_t minimumOptions = 1;
};

std::string expand(std::string s, const fs::path& run) {
    for (std::size_t p; (p = s.find("{RUN}")) != std::string::npos;) s.replace(p, 5, run.string());
    return s;
}

/// The base command without `skip` (the option being fuzzed).
std::string commandArgs(const Command& c, const std::string& skip, const fs::path& run) {
    std::string args = c.name;
    for (const auto& [k, v] : c.args) {
        if (k == skip) continue;
        args += ' ';
        args += k;
        if (!v.empty()) {
            args += ' ';
            args += shellQuote(expand(v, run));
        }
    }
    return args;
}

bool printsNonFinite(const std::string& text) {
    // A JSON or CSV value that is nan or inf (a key or a word like "information" does not match).
    static const std::regex bad(R"((^|[:,\[\s])-?(nan|inf|infinity)([,\]\s}]|$))", std::regex::icase);
    return std::regex_search(text, bad);
}

/// Lines of an output file with a non-finite value, except rows marked failed (a campaign table
/// records the outputs a failed cell could not compute as nan, next to its status and reason).
bool fileHasNonFiniteResult(const fs::path& p) {
    std::istringstream in(test::slurp(p));
    for (std::string line; std::getline(in, line);)
        if (!line.starts_with('#') && printsNonFinite(line) && line.find(",failed,") == std::string::npos) return true;
    return false;
}

std::vector<fs::path> filesUnder(const fs::path& dir) {
    std::vector<fs::path> files;
    if (!fs::exists(dir)) return files;
    for (const auto& e : fs::recursive_directory_iterator(dir))
        if (e.is_regular_file()) files.push_back(e.path());
    return files;
}

void fuzzCommand(const Command& c, const fs::path& scratch) {
    const std::vector<std::string> options = numericOptions(c.name, scratch);
    ASSERT_GE(options.size(), c.minimumOptions) << c.name << ": numeric options not found in --help";
    {  // The base command itself runs (or fails on purpose): the hostile values are its only fault.
        const fs::path run = scratch / "base";
        fs::create_directories(run);
        const std::string args = commandArgs(c, "", run);
        const CliRun r = runShell(fmt::format("timeout -k 5 {} {} {}", kTimeoutSeconds, shellQuote(TRBC_CLI), args), run);
        if (c.validFailure.empty()) {
            ASSERT_EQ(r.status, 0) << "trbc " << args << "\n" << r.err;
            if (!c.output.empty()) {
                EXPECT_TRUE(fs::exists(run / c.output)) << "trbc " << args;
            }
        } else {
            ASSERT_EQ(r.status, 2) << "trbc " << args << "\n" << r.err;
            EXPECT_NE(r.err.find(c.validFailure), std::string::npos) << r.err;
        }
        fs::remove_all(run);
    }
    int runs = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (const std::string& option : options) {
        for (const std::string& value : kHostileValues) {
            const fs::path run = scratch / fmt::format("run{}", runs++);
            fs::create_directories(run);
            std::string args = commandArgs(c, option, run);
            args += ' ';
            args += option;
            args += ' ';
            args += value;
            std::string what = "trbc ";
            what += args;
            const CliRun r = runShell(fmt::format("timeout -k 5 {} {} {}", kTimeoutSeconds, shellQuote(TRBC_CLI), args), run);
            // stdout.txt and stderr.txt of runShell live in `run` too: not outputs.
            std::vector<fs::path> written;
            for (const fs::path& f : filesUnder(run))
                if (f.parent_path() != run || (f.filename() != "stdout.txt" && f.filename() != "stderr.txt")) written.push_back(f);
            ASSERT_NE(r.status, 124) << what << ": no result within " << kTimeoutSeconds << " s";
            ASSERT_TRUE(r.status == 0 || r.status == 2 || r.status == 3)
                << what << ": exit " << r.status << " (a crash, a signal or an internal error)\n" << r.err;
            EXPECT_FALSE(printsNonFinite(r.out)) << what << ": prints a non-finite result\n" << r.out;
            const std::string bare = option.substr(2);
            if (kNeverValid.count(value)) {
                EXPECT_EQ(r.status, 2) << what << ": accepted " << value;
            }
            if (r.status == 2) {
                EXPECT_NE(r.err.find("trbc: error:"), std::string::npos) << what << "\n" << r.err;
                const bool namesOption = r.err.find(option) != std::string::npos || r.err.find(bare) != std::string::npos;
                const bool expected = !c.validFailure.empty() && !kNeverValid.count(value) &&
                                      r.err.find(c.validFailure) != std::string::npos;
                EXPECT_TRUE(namesOption || expected) << what << ": the error does not name " << option << "\n" << r.err;
                EXPECT_TRUE(written.empty()) << what << ": bad input, yet wrote " << written.front();
            }
            if (!c.output.empty()) {
                const fs::path out = run / c.output;
                if (r.status == 0) {
                    EXPECT_TRUE(fs::exists(out)) << what << ": exit 0 without " << out;
                    if (fs::is_regular_file(out)) {
                        EXPECT_FALSE(fileHasNonFiniteResult(out)) << what << ": " << out;
                    }
                } else {
                    EXPECT_FALSE(fs::exists(out)) << what << ": failed (exit " << r.status << ") but left " << out;
                }
            }
            for (const fs::path& f : written)
                EXPECT_NE(f.extension(), ".tmp") << what << ": left the temporary " << f;
            fs::remove_all(run);
        }
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cerr << fmt::format("{}: {} options x {} values in {:.1f} s\n", c.name, options.size(), kHostileValues.size(), wall);
}

/// A level-2 icosphere scaled to a cell's area, written by the CLI itself.
fs::path icosphere(const fs::path& dir) {
    const fs::path p = dir / "ico.off";
    const CliRun r = runTrbc("mesh icosphere --level 2 --area 135 --out " + shellQuote(p.string()), dir);
    EXPECT_EQ(r.status, 0) << r.err;
    return p;
}

/// A synthetic campaign table (smooth fake outputs over the design) for the surrogate commands.
fs::path fakeCampaign(const fs::path& dir) {
    const fs::path p = dir / "campaign.csv";
    std::ofstream out(p);
    out << campaignCsvHeader() << '\n';
    for (const CampaignPoint& q : campaignDesign(DesignKind::LatinHypercube, 160, 8, 3)) {
        CampaignRow r;
        r.point = q;
        r.seed = 3;
        r.D = 7.0 + 1.5 * (q.p.v - 0.8), r.hmin = 0.8 + 0.5 * (1.0 - q.p.v), r.hmax = 2.6 - 0.3 * (1.0 - q.p.v);
        r.D0 = r.D - 0.012 * q.fext / (1.0 + 0.1 * q.p.mu), r.D1 = r.D + 0.03 * q.fext / (1.0 + 0.2 * q.p.mu);
        r.tc = q.p.etam / q.p.mu * (0.8 + 0.3 * q.p.v);
        out << formatCampaignRow(r) << '\n';
    }
    return p;
}

fs::path writeFile(const fs::path& p, const std::string& text) {
    std::ofstream(p) << text;
    return p;
}

/// theta_new-like samples around the paper's Table 1 means.
fs::path thetaSamples(const fs::path& dir) {
    return writeFile(dir / "theta.csv",
                     "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n0.93,4.8,2.0e-19,1.7,0.65\n0.94,5.0,2.1e-19,1.8,0.7\n"
                     "0.95,5.2,2.2e-19,1.9,0.72\n0.945,4.9,2.05e-19,1.85,0.68\n");
}

TEST(CliFuzz, MeshAndMembraneCommands) {
    TempDir tmp;
    const std::string ico = icosphere(tmp.path()).string();
    fuzzCommand({"mesh icosphere", {{"--level", "1"}, {"--out", "{RUN}/m.off"}}, "m.off", "", 2}, tmp.path());
    fuzzCommand({"forces", {{"--mesh", ico}, {"--reference", ico}, {"--kb", "1"}, {"--out", "{RUN}/f.csv"}}, "f.csv", "", 14},
                tmp.path());
    fuzzCommand({"minimize",
                 {{"--mesh", ico}, {"--kb", "1"}, {"--kA", "10"}, {"--A0", "135"}, {"--max-iter", "200"}, {"--out", "{RUN}/r.off"}},
                 "r.off", "", 18},
                tmp.path());
}

TEST(CliFuzz, ForwardModelCommands) {
    TempDir tmp;
    const std::string cache = (tmp.path() / "cache").string();
    const std::string theta = thetaSamples(tmp.path()).string();
    fuzzCommand({"sfs", {{"--v", "0.95"}, {"--level", "1"}, {"--cache", cache}, {"--out", "{RUN}/s.off"}}, "s.off", "", 3},
                tmp.path());
    fuzzCommand({"simulate",
                 {{"--level", "2"}, {"--experiments", "eq"}, {"--max-iter", "300"}, {"--cache", cache}, {"--save-shapes", "{RUN}/shapes"}},
                 "shapes/simulate.json", "", 14},
                tmp.path());
    fuzzCommand({"campaign",
                 {{"--samples", "1"}, {"--level", "2"}, {"--max-iter", "30"}, {"--cache", cache}, {"--out", "{RUN}/c"}},
                 "c/samples.csv", "", 10},
                tmp.path());
    fuzzCommand({"export", {{"--posterior", theta}, {"--level", "2"}, {"--max-iter", "300"}, {"--cache", cache}, {"--out", "{RUN}/x"}},
                 "x/cell.json", "", 7},
                tmp.path());
}

TEST(CliFuzz, FlowCommands) {
    TempDir tmp;
    const std::string cache = (tmp.path() / "cache").string();
    fuzzCommand({"flow shear",
                 {{"--eta-out", "1"}, {"--shear-rate", "100"}, {"--level", "1"}, {"--rotations", "0.1"}, {"--frame-interval", "0.05"},
                  {"--max-steps", "30"},
                  {"--cache", cache}},
                 "", "", 18},
                tmp.path());
    fuzzCommand({"flow tube",
                 {{"--radius", "3.3"}, {"--pressure-gradient", "1"}, {"--level", "1"}, {"--duration", "0.05"}, {"--settle", "0"},
                  {"--max-steps", "20"}, {"--cache", cache}},
                 "", "", 25},
                tmp.path());
    fuzzCommand({"validate",
                 {{"--config", std::string(TRBC_SOURCE_DIR) + "/configs/validation.toml"}, {"--out", "{RUN}/v"}, {"--dry-run", ""}},
                 "", "", 3},
                tmp.path());
}

TEST(CliFuzz, SurrogateAndInferenceCommands) {
    TempDir tmp;
    const std::string table = fakeCampaign(tmp.path()).string();
    const std::string in = writeFile(tmp.path() / "in.csv",
                                     "v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN\n0.95,4,250,1.5,0.7,100\n0.7,9,20,0.1,0.2,10\n")
                               .string();
    fuzzCommand({"surrogate train",
                 {{"--data", table}, {"--restarts", "1"}, {"--max-epochs", "2"}, {"--distill-samples", "1000"}, {"--ensemble", "none"},
                  {"--threads", "1"}, {"--out", "{RUN}/m"}},
                 "m/relaxation.json", "", 9},
                tmp.path());
    fuzzCommand({"surrogate eval", {{"--in", in}, {"--out", "{RUN}/e.csv"}}, "e.csv", "", 1}, tmp.path());
    fuzzCommand({"surrogate test", {{"--data", table}, {"--out", "{RUN}/t"}}, "t/test.json", "", 1}, tmp.path());
    fuzzCommand({"sobol", {{"--samples", "16"}, {"--forces", "2"}, {"--resamples", "2"}, {"--no-plot", ""}, {"--out", "{RUN}/s"}},
                 "s/sobol_indices.csv", "", 5},
                tmp.path());
    fuzzCommand({"infer", {{"--phase", "1"}, {"--samples", "100"}, {"--quiet", ""}, {"--out", "{RUN}/i"}}, "i/infer.json", "", 3},
                tmp.path());

    // predict needs a posterior: one phase-1 run of the smallest size.
    const fs::path inf = tmp.path() / "inference";
    const CliRun r = runTrbc("infer --phase 1 --samples 100 --quiet --out " + shellQuote(inf.string()), tmp.path());
    ASSERT_EQ(r.status, 0) << r.err;
    fuzzCommand({"predict",
                 {{"--posterior", (inf / "phase1" / "mills_2004").string()}, {"--max-samples", "20"}, {"--grid", "3"}, {"--quiet", ""},
                  {"--out", "{RUN}/p"}},
                 "p/coverage.csv", "", 6},
                tmp.path());
    // calibrate's valid --threads values reach the configuration, which is refused on purpose
    // (running the whole pipeline is the calibrate tests' job).
    const std::string bad = writeFile(tmp.path() / "bad.toml", "[inference]\nsamples = 1\n").string();
    fuzzCommand({"calibrate", {{"--config", bad}, {"--out", "{RUN}/cal"}}, "", "samples", 1}, tmp.path());
}

}  // namespace
}  // namespace trbc
