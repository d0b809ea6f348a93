#pragma once
// Shared helpers for the test suite.
#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <random>
#include <string>

#include "membrane/model.hpp"
#include "mesh/mesh.hpp"

namespace trbc::test {

inline std::string dataPath(const std::string& rel) { return std::string(TRBC_TEST_DATA) + "/" + rel; }
inline std::string meshPath(const std::string& name) { return dataPath("meshes/" + name); }
/// The source tree and its shipped experimental data.
inline std::filesystem::path sourceRoot() { return std::filesystem::path(TRBC_TEST_DATA) / ".." / ".."; }
inline std::filesystem::path experimentsDir() { return sourceRoot() / "data" / "experiments"; }

/// Icosphere with every vertex moved by a uniform random offset of relative size `amplitude`
/// (times the mean edge length), fixed seed.
Mesh perturbedIcosphere(int level, double amplitude, unsigned seed);

/// Central finite-difference gradient of the model energy, step h per coordinate.
Vertices finiteDifferenceGradient(const MembraneModel& model, const Vertices& X, double h);

/// max |a - b| / max |b| over all components.
double relativeMaxError(const Vertices& a, const Vertices& b);

/// Mean edge length of a mesh.
double meanEdgeLength(const Mesh& m);

/// A random rotation matrix (fixed seed).
Eigen::Matrix3d randomRotation(unsigned seed);

/// A scratch directory named after the running test, removed afterwards.
class TempDir {
public:
    TempDir();
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
};

/// The message of the InputError that f() throws; "" when it throws none. Other exceptions pass.
std::string inputError(const std::function<void()>& f);

std::string slurp(const std::filesystem::path& p);
/// A table without its provenance line (a first line starting with '#', which names the command
/// that wrote it).
std::string tableBody(const std::filesystem::path& csv);
/// Writes `text` to `p` (parent folders created) and returns `p`.
std::filesystem::path writeText(const std::filesystem::path& p, const std::string& text);
std::string shellQuote(const std::string& s);

struct CliRun {
    int status;  ///< exit status, -1 if the process did not exit normally
    std::string out, err;
};
/// Runs the trbc CLI with `args` (already shell-quoted where needed), stdin from /dev/null,
/// stdout and stderr captured through files in `scratch`.
CliRun runTrbc(const std::string& args, const std::filesystem::path& scratch);
/// Runs a whole shell command line the same way (for a launcher in front of the CLI, e.g. mpiexec).
CliRun runShell(const std::string& commandLine, const std::filesystem::path& scratch);
/// Processes (other than this test) whose command line mentions `needle`.
int processesMentioning(const std::string& needle);

}  // namespace trbc::test
