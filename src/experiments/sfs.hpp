#pragma once
// Stress-free state (SFS) of the cytoskeleton for a reduced volume v (docs/FORWARD_MODEL.md, stress-free state): the
// equilibrium of bending + Lim elasticity relative to a sphere, at the cell's area and the
// volume set by v, found by a converged constrained minimisation instead of the reference's
// fixed-duration damped run. Cached on disk by (v, level, model version).
#include <Eigen/Core>
#include <chrono>
#include <filesystem>
#include <functional>
#include <string>

#include "mesh/mesh.hpp"

namespace trbc {

/// Version of the SFS procedure; part of the cache key (bump when the SFS changes).
inline constexpr int kSfsModelVersion = 1;

struct SfsOptions {
    /// Stop when the largest tangential vertex force is below this, in units of kappa / R'_A
    /// (bending modulus over the SFS radius).
    double gradientTolerance = 1e-5;
    int maxIterations = 100000;
    bool multigrid = true;  ///< multigrid H0 for the L-BFGS (as ExperimentOptions::multigrid)
    std::function<void()> interruptCheck;  ///< MinimizeOptions::interruptCheck of the minimisation
    /// The minimisation stops, not converged (so nothing is cached), after this instant
    /// (`simulate --time-limit`; default: none).
    std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
};

struct StressFreeState {
    double v = 0.0;            ///< requested reduced volume
    double vTarget = 0.0;      ///< volume constraint actually imposed (capped below the mesh's maximum, D)
    int level = 0;
    Mesh mesh;                 ///< icosphere(level) connectivity; unit area 4 pi, material axis z
    // Diagnostics of the minimisation (dimensionless units of the SFS).
    double reducedVolume = 0.0, energy = 0.0, gradientNorm = 0.0;
    double tension = 0.0, pressure = 0.0;  ///< multipliers of the area and volume constraints
    int iterations = 0, evaluations = 0;
    bool converged = false;
    double wallSeconds = 0.0;
    Eigen::Vector3d principalExtents = Eigen::Vector3d::Zero();  ///< decreasing
    bool fromCache = false;
    std::string message;
};

/// Largest reduced volume imposed at a level: just below that of the icosphere itself, because
/// every polyhedron has v < 1 and v = 1 is infeasible with exact constraints (D).
double maxStressFreeReducedVolume(int level);

/// Generates the SFS: Lim reference = unit sphere (area 4 pi), seed = the oblate spheroid of
/// reduced volume vTarget (sphere scaled along material z, D "the branch matters"),
/// kb = 1, Kalpha = 11.140846, mu = 2.228169, a3 = -2, a4 = 8, b1 = 0.7, b2 = 0.75, A = 4 pi,
/// V = 4 pi vTarget / 3. Throws InputError for v outside (0, 1] or a level outside [1, 6];
/// NumericalError when the minimisation fails or the shape is not oblate.
StressFreeState generateStressFreeState(double v, int level, const SfsOptions& options = {});

/// Default cache directory: $TRBC_CACHE_DIR, else $XDG_CACHE_HOME/trbc, else ~/.cache/trbc; throws
/// InputError when none of the three is set.
std::filesystem::path defaultCacheDirectory();

/// Loads the SFS from `cacheDir` when a valid entry exists (checksum, metadata, connectivity and
/// reduced volume verified), otherwise generates and stores it (atomic rename, so concurrent
/// users never see a partial entry). A corrupt entry is reported to the log sink (core/log.hpp) and
/// rebuilt. An empty cacheDir disables the cache.
StressFreeState stressFreeState(double v, int level, const std::filesystem::path& cacheDir,
                                const SfsOptions& options = {});

/// Cache file of an entry (the .off; the metadata sits beside it as .json).
std::filesystem::path sfsCachePath(const std::filesystem::path& cacheDir, double v, int level);

}  // namespace trbc
