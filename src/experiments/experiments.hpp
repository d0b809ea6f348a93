#pragma once
// The three single-cell experiments of docs/FORWARD_MODEL.md (equilibrium, two-bead stretching, relaxation
// after stretching), chained as SFS -> equilibrium -> stretching -> relaxation, in physical
// units (um, pN, s). Static states are constrained minimisations (A = A0, V = V0 exactly, exact constraints);
// the stretching continues over force levels; the relaxation integrates the overdamped
// membrane-viscous dynamics with adaptive variational BDF2 steps.
#include <Eigen/Core>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "experiments/hochmuth.hpp"
#include "experiments/observables.hpp"
#include "experiments/parameters.hpp"
#include "experiments/sfs.hpp"
#include "experiments/thermal_undulations.hpp"
#include "mesh/mesh.hpp"

namespace trbc {

/// How the resting cell's in-plane axes are fixed before stretching (see
/// docs/FORWARD_MODEL.md "In-plane orientation"): the axis through the vertex farthest from the
/// symmetry axis (forward-model revision 2, the default), or the alignment's axis of largest in-plane variance.
enum class InPlaneAxis { FarthestVertex, LargestVariance };

/// How the equilibrium shape is found (docs/EQUILIBRIUM.md "Two equilibria near v = 1"):
/// Lowest: the lowest-energy of the centrally symmetric minimum reached from the biconcave start and
/// the unrestricted minima reached from seeded thermal kicks of it (EquilibriumKicks); Inversion: that
/// symmetric minimum alone, the dimpled disc; None: one unrestricted minimisation from the biconcave
/// start (near v = 1 disc or undimpled cup depending on the solver's path).
enum class EquilibriumSymmetry { Lowest, Inversion, None };

/// "lowest", "inversion", "none" (CLI, Python and campaign.json spelling).
const char* equilibriumSymmetryName(EquilibriumSymmetry s);
/// The mode of a name; throws InputError naming `option` and the valid names otherwise.
EquilibriumSymmetry equilibriumSymmetryFromName(const std::string& name, const std::string& option);

/// The kicks of EquilibriumSymmetry::Lowest: in each round, `perRound` shapes = the lowest state so far plus
/// min(k, 3) times the thermal l = 2, 3 undulation of stream (seed, round, k), k = 1..perRound
/// (experiments/thermal_undulations.hpp, at `temperatureK`), each minimised without restriction; a state
/// lower by more than kT replaces it and starts the next round, and the search stops after a round
/// without one (or after maxRounds).
struct EquilibriumKicks {
    std::uint64_t seed = 20261127;
    int perRound = 3;
    int maxRounds = 5;
    double temperatureK = kBodyTemperatureK;
};

struct ExperimentOptions {
    int level = 4;                       ///< icosphere level of every mesh (Nv = 10 4^L + 2)
    /// Static states stop when the largest tangential vertex force is below
    /// staticTolerance * mu * l0 (l0 = mean edge length; 1e-6 suffices for exact constraints).
    double staticTolerance = 1e-5;
    int maxIterations = 200000;
    /// Relaxation: local error per step (max vertex displacement, um) and inner tolerance
    /// (relative, like staticTolerance).
    double relaxErrorTolerance = 5e-3;
    double relaxInnerTolerance = 1e-3;
    /// Relaxation dynamics: false = the reference's second-order dynamics with the vertex
    /// mass below (baseline); true = overdamped Gamma dX/dt = -dU/dX (no inertia).
    bool overdamped = false;
    double vertexMassKg = 1e-11;         ///< reference vertex mass (1e-11 kg = 1e-5 pN s^2/um)
    /// Overdamped only: isotropic friction eps, relative to gamma, that regularises the
    /// edge-friction matrix on rigid and near-isometric motions (exact constraints). tc at the reference point,
    /// level 3: 0.1981 s (eps 1e-3), 0.1815 (1e-4), 0.1795 (1e-5), 0.1792 (1e-6).
    double isotropicFriction = 1e-5;
    double relaxDuration = 1.0;          ///< s
    int relaxSamples = 100;              ///< at t = k duration / samples, k = 1..samples
    InPlaneAxis inPlaneAxis = InPlaneAxis::FarthestVertex;
    /// Static states (equilibrium, stretching): L-BFGS starts from a multigrid H0 of the scalar
    /// stiffness 0.05 mu I + mu L + kb/l0^2 L^2 on the icosphere hierarchy (solvers/multigrid.hpp);
    /// false: the plain scaled-identity H0 (forward-model revision 2 and earlier).
    bool multigrid = true;
    /// Equilibrium (docs/EQUILIBRIUM.md "Two equilibria near v = 1", "The lowest-energy equilibrium"):
    /// the lowest-energy state found from the symmetric disc and seeded thermal kicks of it (default),
    /// the disc alone (minimised within the centrally symmetric shapes), or one unrestricted minimisation.
    EquilibriumSymmetry equilibriumSymmetry = EquilibriumSymmetry::Lowest;
    EquilibriumKicks kicks;
    std::filesystem::path cacheDir;      ///< SFS cache (empty: no cache)
    SfsOptions sfs;
    /// Equilibrium, stretching and the relaxation's inner solves stop, not converged, after this
    /// instant (a campaign cell's wall-time budget; default: none).
    std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
    /// Passed on to every minimisation and time step of the experiments (MinimizeOptions::interruptCheck).
    std::function<void()> interruptCheck;
    /// Told the name of each stage of runSample as it starts (a command's progress on stderr).
    std::function<void(const std::string&)> progress;
};

/// "farthest-vertex" or "largest-variance" (CLI and provenance spelling).
const char* inPlaneAxisName(InPlaneAxis a);

struct SolverDiagnostics {
    bool converged = false;
    int iterations = 0;        ///< minimiser iterations or accepted time steps
    int evaluations = 0;       ///< force evaluations
    double wallSeconds = 0.0;
    double gradientNorm = 0.0; ///< pN (static states)
    double tension = 0.0;      ///< area multiplier, pN/um (static states)
    double pressure = 0.0;     ///< volume multiplier, pN/um^2 (static states)
    /// Static states: the minimised objective, pN um (membrane energy; in stretching minus the bead
    /// forces' work). Tells apart two converged equilibria of one cell (e.g. disc and cup near v = 1).
    double energy = 0.0;
    std::string message;
};

/// The experiments' mesh data for one sample: Lim reference (SFS rescaled to A0) and the
/// equilibrium's initial shape (Evans-Fung map of the icosphere about the SFS material axis z).
/// With `symmetricReference` (every EquilibriumSymmetry but None) the reference is the SFS's
/// centrally symmetric part (the SFS minimiser keeps the symmetry to its tolerance).
struct CellMeshes {
    Faces faces;
    Vertices reference;
    Vertices initial;
    std::vector<Eigen::Index> inversionPartners;  ///< of the icosphere (inversionPartners)
};
CellMeshes cellMeshes(const StressFreeState& sfs, bool symmetricReference = true);
/// Whether a mode uses the SFS's symmetric part as reference (all but None, which keeps the raw SFS).
inline bool usesSymmetricReference(EquilibriumSymmetry s) { return s != EquilibriumSymmetry::None; }

/// One minimisation of the equilibrium search (EquilibriumResult::candidates).
struct EquilibriumCandidate {
    /// "biconcave": from the Evans-Fung start (restricted to the centrally symmetric shapes unless
    /// EquilibriumSymmetry::None); "kick": from the lowest state of the previous round plus a thermal kick.
    std::string start;
    int round = 0, kick = 0;   ///< the kick's stream (seed, round, kick); 0 for the biconcave start
    bool converged = false;
    double energy = 0.0;       ///< pN um
    double hmin = 0.0;         ///< um
    double asymmetry = 0.0;    ///< inversionAsymmetry of the minimised shape (0: centrally symmetric)
    int evaluations = 0;
    double wallSeconds = 0.0;
};

struct EquilibriumResult {
    EquilibriumObservables observables;  ///< um
    Vertices shape;                      ///< aligned (alignment), um
    ThicknessProfile profile;
    /// force evaluations and wall time of all candidates together; the rest of the chosen one
    SolverDiagnostics diagnostics;
    /// "symmetric" (the centrally symmetric disc), "kicked" (a lower state reached from a kick) or
    /// "unrestricted" (EquilibriumSymmetry::None).
    std::string branch;
    double energyGap = 0.0;    ///< pN um: energy of the symmetric disc minus that of the chosen state
    double kickRms = 0.0;      ///< um: radial rms of the kicks (undulationRms), 0 without kicks
    std::vector<EquilibriumCandidate> candidates;
};
EquilibriumResult runEquilibrium(const CellParameters& p, const CellMeshes& meshes, const ExperimentOptions& opt);

/// Bead forces of stretching on an aligned shape (fixed vertex sets and vectors). Throws NumericalError
/// if a contact set is empty.
Vertices beadForces(const Vertices& alignedShape, const Faces& faces, double fextPn);

struct StretchPoint {
    double fext = 0.0;                   ///< pN
    StretchObservables observables;      ///< um
    SolverDiagnostics diagnostics;
};
/// Static equilibrium under the bead forces for every force of `forces` (sorted ascending;
/// each level starts from the previous solution). Shapes are returned when `shapes` is given.
std::vector<StretchPoint> runStretching(const CellParameters& p, const CellMeshes& meshes, const Vertices& equilibrium,
                                        std::vector<double> forces, const ExperimentOptions& opt,
                                        std::vector<Vertices>* shapes = nullptr);

struct RelaxationResult {
    double preStretchForce = 0.0;        ///< pN
    std::vector<double> t, L, W, z;      ///< s, um, um, -; t = 0 (release) first
    HochmuthFit fit;                     ///< on the samples t >= duration / samples (relaxation)
    SolverDiagnostics preStretch, dynamics;
    int rejectedSteps = 0;
    Vertices released, final;            ///< aligned shape at release, shape at the end
};
RelaxationResult runRelaxation(const CellParameters& p, const CellMeshes& meshes, const Vertices& equilibrium,
                               const ExperimentOptions& opt);

/// Which experiments a sample runs (stretching and relaxation need the equilibrium).
struct ExperimentSet {
    bool equilibrium = true, stretching = true, relaxation = true;
};

struct SampleResult {
    CellParameters parameters;
    double fext = 0.0;
    StressFreeState sfs;
    EquilibriumResult equilibrium;
    std::vector<StretchPoint> stretching;  ///< the requested force first, then any curve levels
    RelaxationResult relaxation;
    std::vector<Vertices> stretchShapes;
};

/// One forward-model sample: SFS(v) (cached), then the chosen experiments. `curveForces`: extra
/// force levels for a whole stretching curve (continuation). Throws NumericalError when a stage
/// fails to converge.
SampleResult runSample(const CellParameters& p, double fextPn, const ExperimentSet& which,
                       const ExperimentOptions& opt, const std::vector<double>& curveForces = {},
                       bool keepShapes = false);

}  // namespace trbc
