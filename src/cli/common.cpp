#include "cli/common.hpp"

#include <unistd.h>

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <string>
#include <string_view>
#include <vector>

#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"

namespace trbc::cli {
namespace {
std::string g_commandLine;
}

void setCommandLine(int argc, char** argv) {
    // Quoted where the shell would split or expand, so that the provenance can be pasted back.
    g_commandLine.clear();
    for (int i = 0; i < argc; ++i) {
        const std::string a = argv[i];
        const bool plain = !a.empty() && std::all_of(a.begin(), a.end(), [](unsigned char c) {
            return std::isalnum(c) || std::string_view("-_=:,./+@%").find(char(c)) != std::string_view::npos;
        });
        g_commandLine += (i ? " " : "") + (plain ? a : shellQuote(a));
    }
    setProvenanceCommand(g_commandLine);  // the provenance line of every CSV table
}

namespace {
/// %g without the exponent's plus sign and leading zeros: 1e8, 1.5e-6.
std::string shortNumber(double x) {
    std::string s = fmt::format("{:g}", x);
    const std::size_t e = s.find('e');
    if (e == std::string::npos) return s;
    std::string exponent = s.substr(e + 1);
    const bool negative = exponent[0] == '-';
    exponent.erase(0, exponent.find_first_not_of("+-0"));
    return s.substr(0, e + 1) + (negative ? "-" : "") + (exponent.empty() ? "0" : exponent);
}
}  // namespace

std::string NumberRange::describe() const {
    const bool haveLo = std::isfinite(lo), haveHi = std::isfinite(hi);
    std::string s;
    if (haveLo && haveHi)
        s = fmt::format("{}{}, {}{}", loOpen ? "(" : "[", shortNumber(lo), shortNumber(hi), hiOpen ? ")" : "]");
    else if (haveLo)
        s = fmt::format("{} {}", loOpen ? ">" : ">=", shortNumber(lo));
    else if (haveHi)
        s = fmt::format("{} {}", hiOpen ? "<" : "<=", shortNumber(hi));
    else
        s = "any finite number";
    return unit.empty() ? s : s + " " + unit;
}

CLI::Validator numberValidator(const NumberRange& range, bool integer) {
    return CLI::Validator(
        [range, integer](std::string& text) -> std::string {
            const std::string valid = "(valid: " + range.describe() + ")";
            const char* begin = text.c_str();
            char* end = nullptr;
            errno = 0;
            const double x = std::strtod(begin, &end);
            const bool whole = !text.empty() && end == begin + text.size() && !std::isspace(static_cast<unsigned char>(text[0]));
            if (!whole) return fmt::format("'{}' is not a number {}", text, valid);
            if (!std::isfinite(x)) return fmt::format("'{}' is not a finite number {}", text, valid);
            if (integer) {
                const std::size_t digits = text[0] == '-' || text[0] == '+' ? 1 : 0;
                if (text.size() == digits || text.find_first_not_of("0123456789", digits) != std::string::npos)
                    return fmt::format("'{}' is not a whole number {}", text, valid);
            }
            if (!range.contains(x)) return fmt::format("{} is out of range {}", text, valid);
            return {};
        },
        range.describe(), "NUMBER");
}

std::string commandLine() { return g_commandLine; }

CLI::Option* addThreadsOption(CLI::App* cmd, int& threads, const std::string& help, int minThreads, int maxThreads) {
    CLI::Option* o = addNumber(cmd, "--threads", threads, help, NumberRange::closed(minThreads, maxThreads));
    return threads != 0 ? o->capture_default_str() : o;
}

CLI::Option* addOutOption(CLI::App* cmd, std::string& out, const std::string& help, bool required) {
    return cmd->add_option("--out", out, help)->required(required);
}

CLI::Option* addDataDirOption(CLI::App* cmd, std::string& dataDir) {
    return cmd->add_option("--data-dir", dataDir,
                           "experimental data directory with equilibrium/, stretching/, relaxation/ (default: $TRBC_EXPERIMENT_DATA, "
                           "else the shipped copy data/experiments)");
}

std::filesystem::path experimentDirectory(const std::string& dataDir) {
    return dataDir.empty() ? defaultExperimentDirectory() : std::filesystem::path(dataDir);
}

void addSurrogateModelOption(CLI::App* cmd, std::string& model) {
    cmd->add_option("--model", model, "surrogate model directory (default: the shipped surrogates)");
}

std::filesystem::path surrogateModelDirectory(const std::string& model) {
    return model.empty() ? defaultSurrogateDirectory() : std::filesystem::path(model);
}

void addModulusOptions(CLI::App* app, ModulusOptions& m) {
    auto& b = m.p.bending;
    auto& l = m.p.lim;
    auto& g = m.p.penalty;
    // Moduli in the mesh's own units: 1e12 is far beyond any use and keeps energies and forces of a
    // mesh of sensible size finite; the Lim coefficients multiply strain invariants of order one.
    const NumberRange modulus = NumberRange::closed(0.0, 1e12, "(mesh units)"), coefficient = NumberRange::closed(-1e6, 1e6);
    addNumber(app, "--kb", b.kb, "Juelicher bending modulus kb (energy units; 0 = off)", modulus)->group("Bending");
    addNumber(app, "--C0", b.C0, "spontaneous curvature C0 (1/length; H0 = C0/2)", NumberRange::closed(-1e6, 1e6, "1/length"))->group("Bending");
    addNumber(app, "--kad", b.kad, "area-difference modulus k_AD (energy; 0 = off)", modulus)->group("Bending");
    addNumber(app, "--DA0", b.DA0, "reference area difference Delta A0 / delta (length)", NumberRange::closed(-1e6, 1e6, "length"))->group("Bending");
    addNumber(app, "--ka", l.Kalpha, "Lim area-dilation modulus K_alpha (energy/area; 0 = off)", modulus)->group("Lim");
    addNumber(app, "--a3", l.a3, "Lim coefficient a3", coefficient)->group("Lim");
    addNumber(app, "--a4", l.a4, "Lim coefficient a4", coefficient)->group("Lim");
    addNumber(app, "--mu", l.mu, "Lim shear modulus mu (energy/area; 0 = off)", modulus)->group("Lim");
    addNumber(app, "--b1", l.b1, "Lim coefficient b1", coefficient)->group("Lim");
    addNumber(app, "--b2", l.b2, "Lim coefficient b2", coefficient)->group("Lim");
    addNumber(app, "--kA", g.kA, "global area penalty kA, U = kA/2 (A-A0)^2/A0 (0 = off)", modulus)->group("Penalties");
    addNumber(app, "--A0", m.A0, "target area A0 (required when --kA > 0)", NumberRange::positive("(mesh units)"))
        ->group("Penalties")
        ->each([&m](const std::string&) { m.haveA0 = true; });
    addNumber(app, "--kV", g.kV, "global volume penalty kV, U = kV/2 (V-V0)^2/V0 (0 = off)", modulus)->group("Penalties");
    addNumber(app, "--V0", m.V0, "target volume V0 (required when --kV > 0)", NumberRange::positive("(mesh units)"))
        ->group("Penalties")
        ->each([&m](const std::string&) { m.haveV0 = true; });
}

void addInPlaneLawOptions(CLI::App* app, ModulusOptions& m) {
    app->add_option("--law", m.law,
                    "in-plane law of each face against --reference: lim (Lim et al. 2008; --ka --a3 --a4 --mu --b1 --b2), "
                    "neo-hookean, W = Gs/2 (I1 - 1 + 1/(I2 + 1)), or skalak, W = Gs/4 (I1^2 + 2 I1 - 2 I2 + C I2^2) "
                    "(--Gs, --skalak-c)")
        ->check(CLI::IsMember({"lim", "neo-hookean", "skalak"}))
        ->capture_default_str()
        ->group("In-plane law");
    addNumber(app, "--Gs", m.p.capsule.Gs,
              "shear modulus Gs of the neo-hookean and skalak laws (energy/area; 0 = off); area-dilation modulus "
              "3 Gs (neo-hookean), Gs (1 + 2 C) (skalak)",
              NumberRange::closed(0.0, 1e12, "(mesh units)"))
        ->group("In-plane law");
    addNumber(app, "--skalak-c", m.p.capsule.C, "Skalak coefficient C (dimensionless; > -1/2 so that Gs (1 + 2 C) > 0)",
              NumberRange::leftOpen(-0.5, 1e6))
        ->group("In-plane law");
}

MembraneParameters checkedParameters(const ModulusOptions& m) {
    MembraneParameters p = m.p;
    p.law = m.law == "neo-hookean" ? InPlaneLaw::NeoHookean : m.law == "skalak" ? InPlaneLaw::Skalak : InPlaneLaw::Lim;
    return checkedMembraneParameters(p, m.haveA0, m.A0, m.haveV0, m.V0, "--");
}

ProgressLine::ProgressLine(std::string command, std::chrono::duration<double> interval)
    : command_(std::move(command)), start_(std::chrono::steady_clock::now()) {
    ticker_ = std::thread([this, interval] {
        std::unique_lock lock(mutex_);
        while (!wake_.wait_for(lock, interval, [this] { return done_; }))
            if (!stage_.empty()) print(", running");
    });
}

ProgressLine::~ProgressLine() {
    {
        std::lock_guard lock(mutex_);
        done_ = true;
    }
    wake_.notify_all();
    ticker_.join();
}

void ProgressLine::stage(const std::string& what) {
    std::lock_guard lock(mutex_);
    stage_ = what;
    print("");
}

std::string ProgressLine::current() const {
    std::lock_guard lock(mutex_);
    return stage_;
}

double ProgressLine::elapsedSeconds() const {
    return secondsSince(start_);
}

void ProgressLine::print(const char* suffix) const {
    std::cerr << fmt::format("{}: {} ({:.0f} s{})\n", command_, stage_, elapsedSeconds(), suffix) << std::flush;
}

void addSolverOptions(CLI::App* cmd, ExperimentOptions& e) {
    addNumber(cmd, "--tol", e.staticTolerance, "static states stop when the largest tangential vertex force < tol * mu * l0",
              NumberRange::leftOpen(0.0, 1.0, "(relative)"))
        ->capture_default_str();
    addNumber(cmd, "--max-iter", e.maxIterations, "iteration limit of each static minimisation", NumberRange::closed(1, 1e9))
        ->capture_default_str();
    addNumber(cmd, "--relax-tol", e.relaxErrorTolerance, "relaxation: local error per time step (largest vertex displacement)",
              NumberRange::leftOpen(0.0, 1.0, "um"))
        ->capture_default_str();
    addNumber(cmd, "--relax-inner-tol", e.relaxInnerTolerance,
              "relaxation: each implicit step stops when the largest vertex force residual < this * mu * l0",
              NumberRange::leftOpen(0.0, 1.0, "(relative)"))
        ->capture_default_str();
    cmd->add_flag("--overdamped", e.overdamped,
                  "relaxation without the reference's artificial vertex mass (Gamma dX/dt = -dU/dX; docs/FORWARD_MODEL.md, relaxation)");
    cmd->add_option_function<std::string>(
           "--preconditioner", [&e](const std::string& a) { e.multigrid = e.sfs.multigrid = a == "multigrid"; },
           "H0 of the L-BFGS of the SFS, the static states and the relaxation's implicit steps: multigrid on the "
           "icosphere hierarchy, or none (scaled identity, block-Jacobi in the relaxation; forward-model "
           "revision 2; docs/FORWARD_MODEL.md)")
        ->check(CLI::IsMember({"multigrid", "none"}))
        ->default_str("multigrid");
    cmd->add_option_function<std::string>(
           "--equilibrium-symmetry",
           [&e](const std::string& a) { e.equilibriumSymmetry = equilibriumSymmetryFromName(a, "--equilibrium-symmetry"); },
           "equilibrium shape: the lowest-energy state of the centrally symmetric disc and the unrestricted minima "
           "reached from seeded thermal kicks of it (lowest), the disc alone, minimised within the centrally "
           "symmetric shapes of the biconcave start (inversion), or one unrestricted minimisation (none: disc or "
           "undimpled cup near v = 1 depending on the solver's path); docs/FORWARD_MODEL.md")
        ->check(CLI::IsMember({equilibriumSymmetryName(EquilibriumSymmetry::Lowest),
                               equilibriumSymmetryName(EquilibriumSymmetry::Inversion),
                               equilibriumSymmetryName(EquilibriumSymmetry::None)}))
        ->default_str(equilibriumSymmetryName(EquilibriumSymmetry::Lowest));
    addNumber(cmd, "--equilibrium-seed", e.kicks.seed,
              "seed of the thermal kicks of --equilibrium-symmetry lowest (kick k of round r draws stream (seed, r, k))",
              NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--equilibrium-kicks", e.kicks.perRound,
              "kicks per round of --equilibrium-symmetry lowest (rounds continue while one reaches a state lower by > kT)",
              NumberRange::closed(1, 100))
        ->capture_default_str();
    cmd->add_option_function<std::string>(
           "--in-plane-axis",
           [&e](const std::string& a) {
               e.inPlaneAxis = a == inPlaneAxisName(InPlaneAxis::LargestVariance) ? InPlaneAxis::LargestVariance
                                                                                  : InPlaneAxis::FarthestVertex;
           },
           "bead axis of the resting cell: through the vertex farthest from the symmetry axis (forward-model "
           "revision 2) or the alignment's in-plane axis of largest variance (docs/FORWARD_MODEL.md)")
        ->check(CLI::IsMember({inPlaneAxisName(InPlaneAxis::FarthestVertex), inPlaneAxisName(InPlaneAxis::LargestVariance)}))
        ->default_str(inPlaneAxisName(InPlaneAxis::FarthestVertex));
}

std::filesystem::path pythonInterpreter() {
    if (const char* py = std::getenv("TRBC_PYTHON")) return py;
    return std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
}

namespace {

/// The items of a comma-separated list, each converted whole by `convert` (std::stol, std::stod);
/// `bad(item)` is the error for an item that does not convert whole or that `accept` refuses.
template <class Value, class Convert, class Accept, class Bad>
std::vector<Value> parseList(const std::string& text, Convert convert, Accept accept, Bad bad) {
    std::vector<Value> out;
    for (const std::string& item : splitList(text)) {
        std::size_t used = 0;
        Value x{};
        try {
            x = convert(item, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used == 0 || used != item.size() || !accept(x)) throw bad(item);
        out.push_back(x);
    }
    return out;
}

}  // namespace

std::vector<long> parseIntegerList(const std::string& text, const std::string& option, const std::string& what, long minValue,
                                   long maxValue) {
    const std::string range = maxValue == std::numeric_limits<long>::max() ? fmt::format("integer >= {}", minValue)
                                                                            : fmt::format("integer in [{}, {}]", minValue, maxValue);
    return parseList<long>(
        text, [](const std::string& s, std::size_t* used) { return std::stol(s, used); },
        [&](long n) { return n >= minValue && n <= maxValue; },
        [&](const std::string& item) { return InputError(fmt::format("{}: '{}' is not {} ({})", option, item, what, range)); });
}

std::vector<double> parseNumberList(const std::string& text, const std::string& option, const std::string& hint) {
    return parseList<double>(
        text, [](const std::string& s, std::size_t* used) { return std::stod(s, used); }, [](double) { return true; },
        [&](const std::string& item) { return InputError(fmt::format("{}: '{}' is not a number ({})", option, item, hint)); });
}

}  // namespace trbc::cli
