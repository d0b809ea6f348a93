#include "experiments/sfs.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <sstream>
#include <thread>

#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/hash.hpp"
#include "core/log.hpp"
#include "core/version.hpp"
#include "experiments/parameters.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/io.hpp"
#include "mesh/topology.hpp"
#include "mesh/validate.hpp"
#include "solvers/minimize.hpp"
#include "solvers/multigrid.hpp"

namespace trbc {
namespace {

constexpr double kFourPi = 4.0 * std::numbers::pi;

// Moduli of the SFS in units of length R'_A and energy kappa.
MembraneParameters sfsMembrane() {
    MembraneParameters p;
    p.bending.kb = 1.0;
    p.lim = {11.140846, -2.0, 8.0, 2.228169, 0.7, 0.75};
    return p;
}

// The sphere scaled along z so that its reduced volume is vTarget (bisection on the scale).
Vertices oblateSeed(const Vertices& sphere, const Faces& F, double vTarget) {
    double lo = 1e-3, hi = 1.0;
    for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        Vertices Y = sphere;
        Y.row(2) *= mid;
        (reducedVolume(Y, F) > vTarget ? hi : lo) = mid;
    }
    Vertices Y = sphere;
    Y.row(2) *= 0.5 * (lo + hi);
    return scaleToArea(Y, F, kFourPi);
}

std::string cacheKey(double v, int level) { return fmt::format("sfs_L{}_v{:.10g}_m{}", level, v, kSfsModelVersion); }

nlohmann::json diagnosticsJson(const StressFreeState& s) {
    return {{"v", s.v},
            {"v_target", s.vTarget},
            {"level", s.level},
            {"reduced_volume", s.reducedVolume},
            {"energy", s.energy},
            {"gradient_norm", s.gradientNorm},
            {"tension", s.tension},
            {"pressure", s.pressure},
            {"iterations", s.iterations},
            {"evaluations", s.evaluations},
            {"converged", s.converged},
            {"wall_s", s.wallSeconds},
            {"principal_extents", {s.principalExtents[0], s.principalExtents[1], s.principalExtents[2]}}};
}

/// The metadata's own checksum: FNV-1a of its JSON text without "meta_checksum", so that an
/// edited diagnostic (converged, energy) is seen like an edited mesh.
std::string metadataChecksum(nlohmann::json j) {
    j.erase("meta_checksum");
    return fmt::format("{:016x}", fnv1a(j.dump()));
}

// Returns false (with the reason) when the entry is missing or not trustworthy. Only regular
// files are read: a FIFO or a device in the cache would block or never end.
bool loadCached(const std::filesystem::path& off, double v, int level, const SfsOptions& opt, StressFreeState& s,
                std::string& reason) {
    std::filesystem::path meta = off;
    meta.replace_extension(".json");
    if (!std::filesystem::exists(off) || !std::filesystem::exists(meta)) {
        reason = "missing";
        return false;
    }
    if (!std::filesystem::is_regular_file(off) || !std::filesystem::is_regular_file(meta)) {
        reason = "not a regular file";
        return false;
    }
    try {
        const nlohmann::json j = nlohmann::json::parse(readFileBytes(meta));
        if (!j.contains("meta_checksum") || j.at("meta_checksum").get<std::string>() != metadataChecksum(j)) {
            reason = "metadata checksum mismatch";
            return false;
        }
        const std::string bytes = readFileBytes(off);
        if (j.at("model_version").get<int>() != kSfsModelVersion || j.at("level").get<int>() != level ||
            j.at("v").get<double>() != v || j.at("gradient_tolerance").get<double>() > opt.gradientTolerance) {
            reason = "metadata does not match the request";
            return false;
        }
        if (j.at("checksum").get<std::string>() != fmt::format("{:016x}", fnv1a(bytes))) {
            reason = "checksum mismatch";
            return false;
        }
        s.mesh = readOff(off.string());
        const Mesh ico = icosphere(level);
        if (s.mesh.F != ico.F) {
            reason = "connectivity differs from the icosphere";
            return false;
        }
        const double vTarget = j.at("diagnostics").at("v_target").get<double>();
        if (std::abs(reducedVolume(s.mesh.X, s.mesh.F) - vTarget) > 1e-6) {
            reason = "reduced volume of the stored shape differs from its metadata";
            return false;
        }
        const auto& d = j.at("diagnostics");
        s.v = v;
        s.vTarget = vTarget;
        s.level = level;
        s.reducedVolume = d.at("reduced_volume");
        s.energy = d.at("energy");
        s.gradientNorm = d.at("gradient_norm");
        s.tension = d.at("tension");
        s.pressure = d.at("pressure");
        s.iterations = d.at("iterations");
        s.evaluations = d.at("evaluations");
        s.converged = d.at("converged");
        s.wallSeconds = d.at("wall_s");
        for (int k = 0; k < 3; ++k) s.principalExtents[k] = d.at("principal_extents")[k];
        s.fromCache = true;
        s.message = "loaded from cache";
        return true;
    } catch (const std::exception& e) {
        reason = e.what();
        return false;
    }
}

void storeCached(const std::filesystem::path& off, const StressFreeState& s, const SfsOptions& opt) {
    std::filesystem::create_directories(off.parent_path());
    const std::string stamp = fmt::format(".tmp{}", std::hash<std::thread::id>{}(std::this_thread::get_id()));
    std::filesystem::path tmpOff = off, meta = off;
    tmpOff += stamp;
    meta.replace_extension(".json");
    std::filesystem::path tmpMeta = meta;
    tmpMeta += stamp;
    writeOff(tmpOff.string(), s.mesh);
    nlohmann::json j = {{"model_version", kSfsModelVersion},
                              {"trbc_version", kVersion},
                              {"v", s.v},
                              {"level", s.level},
                              {"gradient_tolerance", opt.gradientTolerance},
                              {"checksum", fmt::format("{:016x}", fnv1a(readFileBytes(tmpOff)))},
                              {"diagnostics", diagnosticsJson(s)}};
    j["meta_checksum"] = metadataChecksum(j);
    {
        std::ofstream out(tmpMeta);
        out << j.dump(2) << '\n';
        if (!out) throw InputError(fmt::format("cannot write the SFS cache entry {}", tmpMeta.string()));
    }
    // The .off goes last: a reader that finds the metadata of an older entry beside a new mesh
    // rejects it on the checksum and rebuilds.
    std::filesystem::rename(tmpMeta, meta);
    std::filesystem::rename(tmpOff, off);
}

}  // namespace

double maxStressFreeReducedVolume(int level) {
    const Mesh ico = icosphere(level);
    return reducedVolume(ico.X, ico.F) - 2e-4;
}

StressFreeState generateStressFreeState(double v, int level, const SfsOptions& opt) {
    if (!(v > 0.0 && v <= 1.0))
        throw InputError(fmt::format("SFS reduced volume v = {} is outside (0, 1]", v));
    if (level < 1 || level > 6) throw InputError(fmt::format("SFS mesh level {} is outside [1, 6]", level));
    const auto t0 = std::chrono::steady_clock::now();
    StressFreeState s;
    s.v = v;
    s.level = level;
    s.vTarget = std::min(v, maxStressFreeReducedVolume(level));
    const Mesh ico = icosphere(level);
    const Vertices sphere = scaleToArea(ico.X, ico.F, kFourPi);
    const MembraneModel model(ico.F, ico.X.cols(), sfsMembrane(), &sphere);
    s.mesh.F = ico.F;
    s.mesh.X = oblateSeed(sphere, ico.F, s.vTarget);
    MinimizeOptions mo;
    mo.gradientTolerance = opt.gradientTolerance;
    mo.maxIterations = opt.maxIterations;
    mo.interruptCheck = opt.interruptCheck;
    mo.deadline = opt.deadline;
    // Multigrid H0 with the stiffness model of the experiments (R_c = 0.5 um in units of R'_A).
    std::optional<IcosphereMultigrid> mg;
    if (opt.multigrid) {
        // As in the experiments (experiments.cpp, staticOptions): evaluations at level 4 for
        // v = 0.65 / 0.8 / 0.95 / 1: 412 / 381 / 216 / 221 -> 259 / 425 / 214 / 288.
        mo.preconditionerScaleInterval = 2;
        const MembraneParameters mp = sfsMembrane();
        const Topology topo = buildTopology(ico.F, ico.X.cols());
        const double l0 = meanEdgeLength(sphere, topo);
        mg = IcosphereMultigrid::build(ico.F, membraneStiffness(mp.lim.Kalpha, mp.lim.mu, mp.bending.kb,
                                                                 kFourPi / double(ico.X.cols()), l0,
                                                                 0.5 / std::sqrt(cell::area / kFourPi)));
    }
    const Preconditioner pre = asPreconditioner(mg);
    const MinimizeResult r = minimizeEnergy(model, s.mesh.X, mo, nullptr, {kFourPi, kFourPi * s.vTarget / 3.0},
                                            pre ? &pre : nullptr);
    s.converged = r.converged;
    s.iterations = r.iterations;
    s.evaluations = r.evaluations;
    s.energy = r.energy;
    s.gradientNorm = r.gradientNorm;
    if (r.multipliers.size() == 2) {
        s.tension = r.multipliers[0];
        s.pressure = r.multipliers[1];
    }
    s.reducedVolume = reducedVolume(s.mesh.X, s.mesh.F);
    s.principalExtents = extents(alignPrincipalAxes(s.mesh.X));
    s.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.message = r.message;
    if (!r.converged)
        throw NumericalError(fmt::format("SFS for v = {} at level {} did not converge: {}", v, level, r.message));
    const Eigen::Vector3d& e = s.principalExtents;
    if (s.vTarget < 0.98 && (e[1] < 0.97 * e[0] || e[2] > 0.9 * e[1]))
        throw NumericalError(fmt::format("SFS for v = {} is not oblate (principal extents {:.4f}, {:.4f}, {:.4f})",
                                         v, e[0], e[1], e[2]));
    return s;
}

std::filesystem::path defaultCacheDirectory() {
    if (const char* d = std::getenv("TRBC_CACHE_DIR"); d && *d) return d;
    if (const char* d = std::getenv("XDG_CACHE_HOME"); d && *d) return std::filesystem::path(d) / "trbc";
    if (const char* h = std::getenv("HOME"); h && *h) return std::filesystem::path(h) / ".cache" / "trbc";
    // Not a folder in whatever the current directory happens to be: the user names one.
    throw InputError("no SFS cache directory: TRBC_CACHE_DIR, XDG_CACHE_HOME and HOME are all unset; give --cache DIR "
                     "(or set one of them), or --no-cache");
}

std::filesystem::path sfsCachePath(const std::filesystem::path& cacheDir, double v, int level) {
    return cacheDir / (cacheKey(v, level) + ".off");
}

StressFreeState stressFreeState(double v, int level, const std::filesystem::path& cacheDir, const SfsOptions& opt) {
    if (cacheDir.empty()) return generateStressFreeState(v, level, opt);
    const std::filesystem::path off = sfsCachePath(cacheDir, v, level);
    StressFreeState s;
    std::string reason;
    if (loadCached(off, v, level, opt, s, reason)) return s;
    if (reason != "missing")
        logMessage(LogLevel::Warning, fmt::format("SFS cache entry {} rejected ({}); regenerating", off.string(), reason));
    s = generateStressFreeState(v, level, opt);
    try {
        storeCached(off, s, opt);
    } catch (const std::exception& e) {
        logMessage(LogLevel::Warning, fmt::format("could not store the SFS in the cache {} ({}); continuing without it",
                                                  cacheDir.string(), e.what()));
    }
    return s;
}

}  // namespace trbc
