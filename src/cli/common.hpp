#pragma once
// Helpers shared by the subcommands: membrane-modulus options, validation, JSON printing.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <filesystem>
#include <string>

#include "core/csv.hpp"
#include "membrane/model.hpp"
#include "experiments/experiments.hpp"
#include "experiments/sfs.hpp"
#include "experiments/simulation_report.hpp"
#include "membrane/parameters.hpp"
#include "mesh/mesh.hpp"

namespace trbc::cli {

/// Values of the modulus options as given on the command line (mesh units, no conversion).
struct ModulusOptions {
    MembraneParameters p;
    double A0 = 0.0, V0 = 0.0;
    bool haveA0 = false, haveV0 = false;
};

/// Adds --kb --C0 --kad --DA0 --ka --a3 --a4 --mu --b1 --b2 --kA --A0 --kV --V0.
void addModulusOptions(CLI::App* app, ModulusOptions& m);

/// Checks ranges (moduli >= 0, finite; A0 and V0 positive and present when their penalty is on)
/// and returns the parameters. Throws InputError naming the option.
MembraneParameters checkedParameters(const ModulusOptions& m);

/// The command line as one string, for provenance.
std::string commandLine();
void setCommandLine(int argc, char** argv);

/// {"bending": .., "lim": ..} for the terms that are on.
nlohmann::json energyTermsJson(const MembraneParameters& p, const EnergyTerms& t);
/// Size, area, volume, reduced volume and principal extents of a mesh.
nlohmann::json meshSummary(const Mesh& m);

/// Throws InputError unless the file's directory exists and is writable (checked before a long run).
void ensureWritableFile(const std::string& path);
/// Creates the directory if needed; throws InputError unless it is writable.
void ensureWritableDirectory(const std::string& dir);

/// SFS cache options (--cache DIR, --no-cache).
struct CacheOptions {
    std::string dir;
    bool disabled = false;
};
void addCacheOptions(CLI::App* cmd, CacheOptions& c);
std::filesystem::path cacheDirectory(const CacheOptions& c);

/// Solver tolerances of the experiments: --tol --max-iter --relax-tol --relax-inner-tol --overdamped.
void addSolverOptions(CLI::App* cmd, ExperimentOptions& e);

void registerForces(CLI::App& app);
void registerCampaign(CLI::App& app);
void registerSurrogate(CLI::App& app);
void registerSobol(CLI::App& app);
void registerInfer(CLI::App& app);
void registerPredict(CLI::App& app);

/// Shipped surrogates: $TRBC_SURROGATE_DIR, else <source>/data/surrogates.
std::filesystem::path defaultSurrogateDirectory();
/// `--model DIR`, the surrogate model directory (empty: defaultSurrogateDirectory()).
void addSurrogateModelOption(CLI::App* cmd, std::string& model);
/// Experimental data: $TRBC_EXPERIMENT_DATA, else the copy shipped in <source>/data/experiments.
std::filesystem::path defaultExperimentDirectory();
/// A path quoted for /bin/sh.
std::string shellQuote(const std::filesystem::path& p);
/// The Python of the figure scripts: $TRBC_PYTHON, else Debian's /usr/bin/python3 (with
/// python3-matplotlib, scripts/bootstrap), else python3 on PATH.
std::filesystem::path pythonInterpreter();
/// Samples of a theta_new posterior (DIR/samples.csv of `trbc infer`, or the file itself), columns
/// v, mu_uN_per_m, kb_J, b2, etam_Pa_s_um; InputError naming the file and the missing column.
NumericTable readThetaNewSamples(const std::filesystem::path& posterior, const char* option = "--posterior");
void registerCalibrate(CLI::App& app);
void registerValidate(CLI::App& app);
void registerExport(CLI::App& app);
void registerSfs(CLI::App& app);
void registerSimulate(CLI::App& app);
void registerMesh(CLI::App& app);
void registerMinimize(CLI::App& app);
void registerFlow(CLI::App& app);

}  // namespace trbc::cli
