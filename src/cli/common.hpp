#pragma once
// Helpers shared by the subcommands: membrane-modulus options, validation, JSON printing.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <nlohmann/json.hpp>
#include <filesystem>
#include <limits>
#include <string>
#include <type_traits>

#include "core/csv.hpp"
#include "core/output_dir.hpp"
#include "core/shell_quote.hpp"
#include "membrane/model.hpp"
#include "experiments/experiments.hpp"
#include "experiments/sfs.hpp"
#include "experiments/simulation_report.hpp"
#include "membrane/parameters.hpp"
#include "mesh/mesh.hpp"

namespace trbc::cli {

/// The valid values of a numeric option: an interval whose ends may be open, closed or infinite,
/// and the unit that the messages and the help name.
struct NumberRange {
    double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
    bool loOpen = false, hiOpen = false;
    std::string unit;

    static NumberRange any(std::string unit = "") { return {.unit = std::move(unit)}; }
    static NumberRange positive(std::string unit = "") { return {.lo = 0.0, .loOpen = true, .unit = std::move(unit)}; }
    static NumberRange nonNegative(std::string unit = "") { return {.lo = 0.0, .unit = std::move(unit)}; }
    static NumberRange closed(double lo, double hi, std::string unit = "") { return {.lo = lo, .hi = hi, .unit = std::move(unit)}; }
    static NumberRange open(double lo, double hi, std::string unit = "") {
        return {.lo = lo, .hi = hi, .loOpen = true, .hiOpen = true, .unit = std::move(unit)};
    }
    /// (lo, hi]
    static NumberRange leftOpen(double lo, double hi, std::string unit = "") {
        return {.lo = lo, .hi = hi, .loOpen = true, .unit = std::move(unit)};
    }
    /// [lo, hi)
    static NumberRange rightOpen(double lo, double hi, std::string unit = "") {
        return {.lo = lo, .hi = hi, .hiOpen = true, .unit = std::move(unit)};
    }
    bool contains(double x) const { return (loOpen ? x > lo : x >= lo) && (hiOpen ? x < hi : x <= hi); }
    /// "> 0 um", "[0, 1]", "in [1, 1024]": short, numbers in %g (never the 309 digits of DBL_MAX).
    std::string describe() const;
};

/// The one check of every numeric option: the text must be a whole number (integer options) or
/// a finite decimal number (no nan, inf), inside `range`. A failure stops parsing with exit 2 and
/// "--name: ..." naming the option, the value as typed, the valid range and the unit.
CLI::Validator numberValidator(const NumberRange& range, bool integer);

/// Adds a numeric option checked by numberValidator (the help shows the range and unit after the type).
template <class T>
CLI::Option* addNumber(CLI::App* cmd, const std::string& name, T& value, const std::string& help, const NumberRange& range) {
    static_assert(std::is_arithmetic_v<T>, "addNumber is for numeric options");
    NumberRange r = range;
    if constexpr (std::is_integral_v<T>) {  // what the variable can hold
        r.lo = std::max(r.lo, static_cast<double>(std::numeric_limits<T>::lowest()));
        r.hi = std::min(r.hi, static_cast<double>(std::numeric_limits<T>::max()));
    }
    return cmd->add_option(name, value, help)->check(numberValidator(r, std::is_integral_v<T>));
}

/// The most threads that --threads accepts.
constexpr int kMaxThreads = 1024;

/// --threads N, N in [minThreads, maxThreads]; `help` says what runs in parallel. The default (the
/// value of `threads`) is shown in the help unless it is 0, which stands for "not given": the
/// count of the configuration file or OpenMP's own.
CLI::Option* addThreadsOption(CLI::App* cmd, int& threads, const std::string& help = "OpenMP threads", int minThreads = 1,
                              int maxThreads = kMaxThreads);

/// --out PATH, the output file or directory that `help` describes; required unless `required` is false.
CLI::Option* addOutOption(CLI::App* cmd, std::string& out, const std::string& help = "output directory", bool required = true);

/// --data-dir DIR, the experimental data directory (empty: experimentDirectory() picks the default).
CLI::Option* addDataDirOption(CLI::App* cmd, std::string& dataDir);
/// The directory of --data-dir: the one given, else defaultExperimentDirectory().
std::filesystem::path experimentDirectory(const std::string& dataDir);

/// Progress of a long command on stderr: "<command>: <stage> (<elapsed> s)" when a stage starts, and
/// the same line again every `interval` while it runs, so that a long stage is visibly alive.
class ProgressLine {
public:
    explicit ProgressLine(std::string command, std::chrono::duration<double> interval = std::chrono::seconds(15));
    ~ProgressLine();
    ProgressLine(const ProgressLine&) = delete;
    ProgressLine& operator=(const ProgressLine&) = delete;
    void stage(const std::string& what);
    /// The stage running now ("" before the first).
    std::string current() const;
    double elapsedSeconds() const;

private:
    void print(const char* suffix) const;
    std::string command_, stage_;
    std::chrono::steady_clock::time_point start_;
    mutable std::mutex mutex_;
    std::condition_variable wake_;
    bool done_ = false;
    std::thread ticker_;
};

/// Values of the modulus options as given on the command line (mesh units, no conversion).
struct ModulusOptions {
    MembraneParameters p;
    double A0 = 0.0, V0 = 0.0;
    bool haveA0 = false, haveV0 = false;
    std::string law = "lim";  ///< --law, when addInPlaneLawOptions added it
};

/// Adds --kb --C0 --kad --DA0 --ka --a3 --a4 --mu --b1 --b2 --kA --A0 --kV --V0.
void addModulusOptions(CLI::App* app, ModulusOptions& m);
/// Adds --law {lim,neo-hookean,skalak}, --Gs and --skalak-c (the in-plane law and its moduli).
void addInPlaneLawOptions(CLI::App* app, ModulusOptions& m);

/// Checks ranges (moduli >= 0, finite; A0 and V0 positive and present when their penalty is on;
/// only the moduli of the chosen --law) and returns the parameters. Throws InputError naming the option.
MembraneParameters checkedParameters(const ModulusOptions& m);

/// A comma-separated list of integers in [minValue, maxValue], in the order given; InputError naming
/// `option`, the bad item and what it should be (`what`, e.g. "a case id") with the valid range.
std::vector<long> parseIntegerList(const std::string& text, const std::string& option, const std::string& what, long minValue,
                                   long maxValue = std::numeric_limits<long>::max());
/// The numbers of a comma-separated list; InputError "OPTION: 'ITEM' is not a number (HINT)" for an
/// item that is not one whole number. Ranges are the caller's.
std::vector<double> parseNumberList(const std::string& text, const std::string& option, const std::string& hint);

/// The command line as one string, for provenance.
std::string commandLine();
void setCommandLine(int argc, char** argv);

/// {"bending": .., "lim": ..} for the terms that are on.
nlohmann::json energyTermsJson(const MembraneParameters& p, const EnergyTerms& t);
/// Size, area, volume, reduced volume and principal extents of a mesh.
nlohmann::json meshSummary(const Mesh& m);

/// SFS cache options (--cache DIR, --no-cache).
struct CacheOptions {
    std::string dir;
    bool disabled = false;
};
void addCacheOptions(CLI::App* cmd, CacheOptions& c);
std::filesystem::path cacheDirectory(const CacheOptions& c);

/// Solver tolerances of the experiments: --tol --max-iter --relax-tol --relax-inner-tol --overdamped.
void addSolverOptions(CLI::App* cmd, ExperimentOptions& e);

/// `trbc flow capsule` (cmd_flow_capsule.cpp), a subcommand of `trbc flow`.
void registerFlowCapsule(CLI::App* flow);
void registerFlowCampaign(CLI::App* flow);
void registerFlowTrain(CLI::App* flow);
void registerFlowSobol(CLI::App* flow);
void registerFlowDistill(CLI::App* flow);
void registerForces(CLI::App& app);
void registerCampaign(CLI::App& app);
void registerSurrogate(CLI::App& app);
void registerSobol(CLI::App& app);
void registerInfer(CLI::App& app);
void registerPredict(CLI::App& app);

/// The folder of data/, configs/, scripts/ and results/mesh_convergence/: <prefix>/share/trbc beside an
/// installed trbc (found from the executable's path), else the source tree it was built from.
std::filesystem::path resourceRoot();
/// The shipped data: $TRBC_DATA_DIR, else resourceRoot()/data.
std::filesystem::path dataDirectory();
/// Shipped surrogates: $TRBC_SURROGATE_DIR, else dataDirectory()/surrogates.
std::filesystem::path defaultSurrogateDirectory();
/// `--model DIR`, the surrogate model directory (empty: defaultSurrogateDirectory()).
void addSurrogateModelOption(CLI::App* cmd, std::string& model);
/// The directory of --model: the one given, else defaultSurrogateDirectory().
std::filesystem::path surrogateModelDirectory(const std::string& model);
/// Experimental data: $TRBC_EXPERIMENT_DATA, else dataDirectory()/experiments.
std::filesystem::path defaultExperimentDirectory();
/// The figure scripts run by calibrate, validate and sobol: resourceRoot()/scripts.
std::filesystem::path scriptDirectory();
/// The Python of the figure scripts: $TRBC_PYTHON, else Debian's /usr/bin/python3 (with
/// python3-matplotlib, scripts/bootstrap), else python3 on PATH.
std::filesystem::path pythonInterpreter();
void registerCalibrate(CLI::App& app);
void registerValidate(CLI::App& app);
void registerExport(CLI::App& app);
void registerSfs(CLI::App& app);
void registerSimulate(CLI::App& app);
void registerMesh(CLI::App& app);
void registerMinimize(CLI::App& app);
void registerFlow(CLI::App& app);

}  // namespace trbc::cli
