#pragma once
// The training campaign (docs/CAMPAIGN_AND_SURROGATE.md, campaign): a design over the input box, the forward model
// per cell, one CSV row per sample, continuous checkpointing and resume.
//
// Files in the output directory:
//   campaign.json      provenance: command, version, seed, design, sizes, options; final counts
//   parts/rank<r>.csv  the checkpoint: rows appended cell by cell (one write + fsync per cell)
//   samples.csv        the finished table, all rows sorted by sample_id (written once all cells are done)
//   equilibria/rank<r>.csv, equilibria.csv  per cell: the chosen equilibrium branch, the energy gap to
//                      the symmetric disc and whether the outputs were taken over (reuse_from)
// A run killed at any moment (SIGKILL included) and restarted with resume loses no finished cell
// and repeats none: a cell counts as done when all its rows are in a part file; a torn last line
// or the rows of an unfinished cell are discarded on restart.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "experiments/experiments.hpp"
#include "sampling/campaign_table.hpp"
#include "sampling/design.hpp"

namespace trbc {

struct CampaignProgress {
    long cellsDone = 0, cellsTotal = 0;        ///< this process, including resumed cells
    long cellsResumed = 0;                     ///< found done at start
    long rowsOk = 0, rowsFailed = 0;
    double elapsedSeconds = 0.0;               ///< since this process started
};

struct CampaignOptions {
    DesignKind design = DesignKind::Uniform;
    long samples = 1000;
    int forcesPerCell = 1;
    std::uint64_t seed = 1;
    int threads = 1;                           ///< cells run concurrently, one thread each
    int ranks = 1;                             ///< MPI ranks sharing the cells (provenance only)
    /// Wall-time budget of one cell in seconds (0: none). A cell that exceeds it becomes failed rows
    /// whose reason says "time limit reached" (the relaxation, which every row needs, runs last);
    /// outputs computed before the limit (the equilibrium's) stay in their columns.
    double cellTimeLimit = 0.0;
    std::filesystem::path outDir;
    bool resume = false;
    /// An earlier campaign of the same design and settings but the symmetric disc as equilibrium
    /// (equilibrium_symmetry "inversion"), for a campaign of the lowest-energy equilibrium. Every cell
    /// still searches its equilibrium (disc and kicks). Where it keeps the disc, and D, hmin and hmax
    /// equal the earlier rows' bit for bit, the equilibrium shape is the earlier one, so the stretching
    /// and relaxation outputs (and failure reasons) are taken over; every other cell is computed in full.
    std::filesystem::path reuseFrom;
    ExperimentOptions experiment;
    std::set<long> injectFailures;             ///< sample ids whose cell fails on purpose (tests)
    std::string command;                       ///< for provenance
    std::function<void(const CampaignProgress&)> progress;  ///< after every cell (serialised)
};

struct CampaignSummary {
    long samples = 0, ok = 0, failed = 0;
    long cellsComputed = 0, cellsResumed = 0;
    double wallSeconds = 0.0;
    bool complete = false;                     ///< samples.csv written
};

/// What a cell's equilibrium search chose (equilibria.csv).
struct CampaignCellRecord {
    long cellId = -1;
    std::string branch;          ///< EquilibriumResult::branch; empty when the equilibrium failed
    double energyGapJ = NAN;     ///< symmetric disc minus the chosen state, J
    bool reused = false;         ///< stretching and relaxation taken from CampaignOptions::reuseFrom
};

/// A finished unit of a campaign (a cell of rows, a flow case): its rows' counts and how to store
/// them (append to the part file; called serialised, in completion order).
struct CampaignUnit {
    long ok = 0, failed = 0;
    std::function<void()> commit;
};

/// The loop both campaigns share: units 0..n-1 run on `threads` OpenMP threads, one thread each
/// (nested OpenMP off), in dynamic order; `work(k)` computes unit k in parallel, its commit runs
/// serialised, then `prog` counts it and `progress` (if any) is called. An exception from a commit
/// (a full disk) stops the units not started yet, whose rows would be lost anyway; it is rethrown as
/// IoError with the system's reason once the started units finish. `prog` arrives with the
/// resumed units counted; the summary holds them and the n computed ones.
CampaignSummary runCampaignUnits(std::size_t n, int threads, CampaignProgress prog, SteadyClock::time_point t0,
                                 const std::function<CampaignUnit(std::size_t)>& work,
                                 const std::function<void(const CampaignProgress&)>& progress);

/// Runs the forward model for the rows of one cell (all share SFS, equilibrium, the stretching
/// continuation over their forces and one relaxation). Never throws for a numerical failure:
/// the affected outputs stay nan and the rows say why. `donor`: the cell's rows of an earlier
/// campaign of the symmetric disc (CampaignOptions::reuseFrom), in the order of `cell`.
std::vector<CampaignRow> runCampaignCell(const std::vector<CampaignPoint>& cell, std::uint64_t seed,
                                         const ExperimentOptions& opt, bool injectFailure = false,
                                         const std::vector<CampaignRow>* donor = nullptr,
                                         CampaignCellRecord* record = nullptr);

/// Creates the output directory and the provenance of a new campaign (refusing to overwrite one
/// without resume), or checks that a resumed campaign was made with the same settings. Call once
/// before any rank runs (rank 0 under MPI).
void prepareCampaign(const CampaignOptions& opt);

/// Runs the cells assigned to `rank` of `ranks` (round robin; ranks = 1 without MPI) that are not
/// done yet, appending to parts/rank<rank>.csv (after prepareCampaign).
CampaignSummary runCampaignShare(const CampaignOptions& opt, int rank = 0, int ranks = 1);

/// Merges the part files into samples.csv (sorted by sample id) when every cell is done, and
/// writes the final provenance. Call once, after all ranks finished (rank 0 under MPI).
CampaignSummary finalizeCampaign(const CampaignOptions& opt, double wallSeconds);

/// The rows of a campaign directory: samples.csv when the campaign is complete, otherwise the
/// finished cells of its part files (`complete` says which). A path to a CSV file reads that table.
std::vector<CampaignRow> readCampaignRows(const std::filesystem::path& dirOrFile, bool* complete = nullptr);

/// Equilibrium branch per cell id from DIR/equilibria.csv: 1 where the lowest-energy search kept a
/// state reached by a kick, 0 otherwise. Empty when there is no such file (a table file, or a
/// campaign made before the records). InputError naming the file and line for a malformed one.
std::map<long, int> readCampaignBranches(const std::filesystem::path& dirOrFile);

/// Convenience: prepareCampaign + runCampaignShare + finalizeCampaign in one process.
CampaignSummary runCampaign(const CampaignOptions& opt);

}  // namespace trbc
