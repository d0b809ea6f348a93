// `trbc forces` end to end: runs the CLI on the provided meshes and checks its JSON energies
// against docs/MEMBRANE_MODEL.md, reference values, and its CSV forces against central finite differences of the library energy.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/version.hpp"
#include "membrane/model.hpp"
#include "mesh/io.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

struct CliRun {
    int status;
    std::string out;
};

CliRun runCli(const std::string& args) {
    const std::string cmd = std::string(TRBC_CLI) + " " + args + " 2>/dev/null";
    FILE* p = popen(cmd.c_str(), "r");
    std::string out;
    char buf[4096];
    while (std::size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    const int st = pclose(p);
    return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, out};
}

Vertices readForceCsv(const std::string& path, Eigen::Index nv) {
    std::ifstream in(path);
    std::string line;
    std::getline(in, line);
    EXPECT_TRUE(line.starts_with("# trbc ")) << line;  // the provenance line
    std::getline(in, line);
    EXPECT_EQ(line, "fx,fy,fz");
    Vertices f(3, nv);
    Eigen::Index i = 0;
    while (std::getline(in, line)) {
        std::stringstream ss(line);
        std::string tok;
        for (int k = 0; k < 3 && std::getline(ss, tok, ','); ++k) f(k, i) = std::stod(tok);
        ++i;
    }
    EXPECT_EQ(i, nv) << "one row per vertex";
    return f;
}

// The CLI's CSV forces against central finite differences of the library energy.
void expectCsvForcesMatchFiniteDifferences(const std::string& csv, const Mesh& m, const MembraneModel& model) {
    const Vertices fd = test::finiteDifferenceGradient(model, m.X, 1e-5 * test::meanEdgeLength(m));
    EXPECT_LE(test::relativeMaxError(readForceCsv(csv, m.numVertices()), -fd), 1e-6);
}

std::string tmpCsv(const std::string& name) {
    return (std::filesystem::temp_directory_path() / ("trbc_cli_" + name + ".csv")).string();
}

TEST(CliForces, BendingOnRbc498MatchesReferenceEnergyAndFiniteDifferences) {
    const std::string mesh = test::meshPath("rbc_498.off"), out = tmpCsv("bending");
    const CliRun r = runCli("forces --mesh " + mesh + " --kb 1 --out " + out);
    ASSERT_EQ(r.status, 0);
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_NEAR(j["energy"].get<double>(), 48.03408146, 1e-7);
    EXPECT_NEAR(j["terms"]["bending"].get<double>(), 48.03408146, 1e-7);
    const Mesh m = readOff(mesh);
    MembraneParameters p;
    p.bending.kb = 1.0;
    expectCsvForcesMatchFiniteDifferences(out, m, MembraneModel(m.F, m.numVertices(), p));
}

TEST(CliForces, LimOnRbc642WithSphereReferenceMatchesReferenceEnergyAndFiniteDifferences) {
    const std::string mesh = test::meshPath("rbc_642.off"), ref = test::meshPath("sphere_642.off"),
                      out = tmpCsv("lim");
    const CliRun r = runCli("forces --mesh " + mesh + " --reference " + ref +
                            " --ka 1 --a3 -2 --a4 8 --mu 1 --b1 0.7 --b2 0.75 --out " + out);
    ASSERT_EQ(r.status, 0);
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_NEAR(j["terms"]["lim"].get<double>(), 5.901502527, 1e-8);
    EXPECT_FALSE(j["terms"].contains("bending")) << "terms that are off are not reported";
    const Mesh m = readOff(mesh), s = readOff(ref);
    MembraneParameters p;
    p.lim = {1, -2, 8, 1, 0.7, 0.75};
    expectCsvForcesMatchFiniteDifferences(out, m, MembraneModel(m.F, m.numVertices(), p, &s.X));
}

TEST(CliForces, FullModelReportsEveryTerm) {
    const std::string mesh = test::meshPath("rbc_642.off"), ref = test::meshPath("sphere_642.off"),
                      out = tmpCsv("full");
    const CliRun r = runCli("forces --mesh " + mesh + " --reference " + ref +
                            " --kb 1 --C0 0.5 --kad 0.3 --DA0 10 --ka 1 --a3 -2 --a4 8 --mu 1 --b1 0.7 --b2 2"
                            " --kA 100 --A0 9 --kV 100 --V0 1.5 --out " + out);
    ASSERT_EQ(r.status, 0);
    const auto j = nlohmann::json::parse(r.out);
    double sum = 0.0;
    for (const char* t : {"bending", "ade", "lim", "area", "volume"}) {
        ASSERT_TRUE(j["terms"].contains(t)) << t;
        sum += j["terms"][t].get<double>();
    }
    EXPECT_NEAR(j["energy"].get<double>(), sum, 1e-12 * sum);
}

TEST(CliForces, RejectsBadParametersWithAClearMessageAndNoOutput) {
    const std::string mesh = test::meshPath("rbc_642.off"), out = tmpCsv("bad");
    std::filesystem::remove(out);
    const std::vector<std::string> badArgs = {"--kb -1", "--kb nan", "--kA 10", "--kV 10 --V0 -2", "--mu 1",
                                              "--reference " + test::meshPath("rbc_498.off") + " --mu 1"};
    for (const std::string& args : badArgs) {
        const CliRun r = runCli("forces --mesh " + mesh + " " + args + " --out " + out);
        EXPECT_NE(r.status, 0) << args;
        EXPECT_FALSE(std::filesystem::exists(out)) << args;
    }
}

// --help and --version exit 0; a command-line error (unknown option, a value CLI11 rejects)
// exits 2 like every other bad input.
TEST(Cli, HelpAndVersionExitZeroParseErrorsExitTwo) {
    for (const char* args : {"--help", "--version", "flow tube --help", "simulate --help"})
        EXPECT_EQ(runCli(args).status, 0) << args;
    // The version names the revision, as the records do.
    EXPECT_NE(runCli("--version").out.find(fmt::format("{} ({})", kVersion, gitDescribe())), std::string::npos);
    for (const char* args : {"--no-such-option", "simulate --level 9", "flow tube --radius 3 --pressure-gradient 1 --settle-relax x"})
        EXPECT_EQ(runCli(args).status, 2) << args;
}

}  // namespace
}  // namespace trbc
