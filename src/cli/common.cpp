#include "cli/common.hpp"

#include <unistd.h>

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "core/error.hpp"

namespace trbc::cli {
namespace {
std::string g_commandLine;
}

void setCommandLine(int argc, char** argv) {
    g_commandLine.clear();
    for (int i = 0; i < argc; ++i) g_commandLine += (i ? " " : "") + std::string(argv[i]);
}

std::string commandLine() { return g_commandLine; }

void addModulusOptions(CLI::App* app, ModulusOptions& m) {
    auto& b = m.p.bending;
    auto& l = m.p.lim;
    auto& g = m.p.penalty;
    app->add_option("--kb", b.kb, "Juelicher bending modulus kb (energy units; 0 = off)")->group("Bending");
    app->add_option("--C0", b.C0, "spontaneous curvature C0 (1/length; H0 = C0/2)")->group("Bending");
    app->add_option("--kad", b.kad, "area-difference modulus k_AD (energy; 0 = off)")->group("Bending");
    app->add_option("--DA0", b.DA0, "reference area difference Delta A0 / delta (length)")->group("Bending");
    app->add_option("--ka", l.Kalpha, "Lim area-dilation modulus K_alpha (energy/area; 0 = off)")->group("Lim");
    app->add_option("--a3", l.a3, "Lim coefficient a3")->group("Lim");
    app->add_option("--a4", l.a4, "Lim coefficient a4")->group("Lim");
    app->add_option("--mu", l.mu, "Lim shear modulus mu (energy/area; 0 = off)")->group("Lim");
    app->add_option("--b1", l.b1, "Lim coefficient b1")->group("Lim");
    app->add_option("--b2", l.b2, "Lim coefficient b2")->group("Lim");
    app->add_option("--kA", g.kA, "global area penalty kA, U = kA/2 (A-A0)^2/A0 (0 = off)")->group("Penalties");
    app->add_option("--A0", m.A0, "target area A0 (required when --kA > 0)")->group("Penalties")
        ->each([&m](const std::string&) { m.haveA0 = true; });
    app->add_option("--kV", g.kV, "global volume penalty kV, U = kV/2 (V-V0)^2/V0 (0 = off)")->group("Penalties");
    app->add_option("--V0", m.V0, "target volume V0 (required when --kV > 0)")->group("Penalties")
        ->each([&m](const std::string&) { m.haveV0 = true; });
}

MembraneParameters checkedParameters(const ModulusOptions& m) {
    return checkedMembraneParameters(m.p, m.haveA0, m.A0, m.haveV0, m.V0, "--");
}

void ensureWritableFile(const std::string& path) {
    std::filesystem::path dir = std::filesystem::path(path).parent_path();
    if (dir.empty()) dir = ".";
    if (!std::filesystem::is_directory(dir))
        throw InputError(fmt::format("cannot write {}: directory {} does not exist", path, dir.string()));
    if (::access(dir.c_str(), W_OK) != 0)
        throw InputError(fmt::format("cannot write {}: directory {} is not writable", path, dir.string()));
    if (std::filesystem::is_directory(path)) throw InputError(fmt::format("cannot write {}: it is a directory", path));
}

void ensureWritableDirectory(const std::string& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (!std::filesystem::is_directory(dir))
        throw InputError(fmt::format("cannot create the output directory {}{}", dir, ec ? ": " + ec.message() : ""));
    if (::access(dir.c_str(), W_OK) != 0) throw InputError(fmt::format("output directory {} is not writable", dir));
}

void addSolverOptions(CLI::App* cmd, ExperimentOptions& e) {
    cmd->add_option("--tol", e.staticTolerance,
                    "static states stop when the largest tangential vertex force < tol * mu * l0")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--max-iter", e.maxIterations, "iteration limit of each static minimisation")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--relax-tol", e.relaxErrorTolerance,
                    "relaxation: local error per time step (largest vertex displacement, um)")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--relax-inner-tol", e.relaxInnerTolerance,
                    "relaxation: each implicit step stops when the largest vertex force residual < this * mu * l0")
        ->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_flag("--overdamped", e.overdamped,
                  "relaxation without the reference's artificial vertex mass (Gamma dX/dt = -dU/dX; MODEL.md E.3)");
    cmd->add_option_function<std::string>(
           "--preconditioner", [&e](const std::string& a) { e.multigrid = e.sfs.multigrid = a == "multigrid"; },
           "H0 of the L-BFGS of the SFS, the static states and the relaxation's implicit steps: multigrid on the "
           "icosphere hierarchy, or none (scaled identity, block-Jacobi in the relaxation; forward-model "
           "revision 2; docs/FORWARD_MODEL.md)")
        ->check(CLI::IsMember({"multigrid", "none"}))
        ->default_str("multigrid");
    cmd->add_option_function<std::string>(
           "--equilibrium-symmetry", [&e](const std::string& a) { e.symmetricEquilibrium = a == "inversion"; },
           "equilibrium shape: minimised within the centrally symmetric shapes of the biconcave start (inversion: "
           "the disc that E.1's dynamics reaches, also for a near-spherical SFS) or unrestricted (none: disc or "
           "undimpled cup near v = 1 depending on the solver's path; campaigns before session 22); "
           "docs/FORWARD_MODEL.md")
        ->check(CLI::IsMember({"inversion", "none"}))
        ->default_str("inversion");
    cmd->add_option_function<std::string>(
           "--in-plane-axis",
           [&e](const std::string& a) {
               e.inPlaneAxis = a == inPlaneAxisName(InPlaneAxis::LargestVariance) ? InPlaneAxis::LargestVariance
                                                                                  : InPlaneAxis::FarthestVertex;
           },
           "bead axis of the resting cell: through the vertex farthest from the symmetry axis (forward-model "
           "revision 2) or E.0's in-plane axis of largest variance (docs/FORWARD_MODEL.md)")
        ->check(CLI::IsMember({inPlaneAxisName(InPlaneAxis::FarthestVertex), inPlaneAxisName(InPlaneAxis::LargestVariance)}))
        ->default_str(inPlaneAxisName(InPlaneAxis::FarthestVertex));
}

NumericTable readThetaNewSamples(const std::filesystem::path& in, const char* option) {
    const std::filesystem::path file = std::filesystem::is_directory(in) ? in / "samples.csv" : in;
    if (!std::filesystem::exists(file))
        throw InputError(fmt::format("{} {}: no samples.csv (run `trbc infer` first; e.g. DIR/phase3/theta_new)", option, in.string()));
    static const std::vector<std::string> columns = {"v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"};
    NumericTable t = readNumericTable(file, columns);
    for (const std::string& c : columns)
        if (t.find(c) < 0)
            throw InputError(fmt::format("{}: column '{}' missing: {} must be a theta_new posterior (columns v, "
                                         "mu_uN_per_m, kb_J, b2, etam_Pa_s_um)", file.string(), c, option));
    if (t.values.rows() < 2) throw InputError(fmt::format("{}: fewer than two samples", file.string()));
    return t;
}

std::string shellQuote(const std::filesystem::path& p) {
    std::string s = "'";
    for (char c : p.string()) s += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return s + "'";
}

std::filesystem::path pythonInterpreter() {
    if (const char* py = std::getenv("TRBC_PYTHON")) return py;
    return std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
}

}  // namespace trbc::cli
