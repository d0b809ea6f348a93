// trbc campaign: the training campaign of docs/CAMPAIGN_AND_SURROGATE.md. Parses, then calls
// sampling/campaign; under MPI (built with TRBC_WITH_MPI, run with mpirun) the cells are shared
// round robin between ranks, each rank checkpointing to its own part file.
#include <fmt/format.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#ifdef TRBC_WITH_MPI
#include <mpi.h>
#endif

#include "cli/common.hpp"
#include "core/output_dir.hpp"
#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "sampling/campaign.hpp"

namespace trbc::cli {
namespace {

std::string hms(double s) {
    if (!std::isfinite(s) || s < 0) return "--";
    const long t = long(s + 0.5);
    return t >= 3600 ? fmt::format("{}h{:02}m", t / 3600, t / 60 % 60) : fmt::format("{}m{:02}s", t / 60, t % 60);
}

/// A progress bar with rate and ETA on a terminal; plain log lines (every 30 s) otherwise.
class ProgressReporter {
public:
    explicit ProgressReporter(int ranks) : ranks_(ranks), tty_(::isatty(STDERR_FILENO)) {}
    void operator()(const CampaignProgress& p) {
        const double now = p.elapsedSeconds;
        const long computed = p.cellsDone - p.cellsResumed, left = p.cellsTotal - p.cellsDone;
        const double rate = now > 0 ? computed / now : 0.0;  // cells per second, this rank
        const double eta = rate > 0 ? left / rate : NAN;
        const bool last = p.cellsDone == p.cellsTotal;
        if (tty_) {
            const int width = 30, filled = p.cellsTotal ? int(width * p.cellsDone / p.cellsTotal) : width;
            std::fprintf(stderr, "\r[%s%s] %ld/%ld cells  %ld ok %ld failed  %.1f cells/min  ETA %s   ",
                         std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(), p.cellsDone,
                         p.cellsTotal, p.rowsOk, p.rowsFailed, 60.0 * rate, hms(eta).c_str());
            if (last) std::fputc('\n', stderr);
        } else if (last || p.cellsDone == p.cellsResumed || now - lastLog_ >= 30.0) {
            lastLog_ = now;
            std::fprintf(stderr, "campaign%s: %ld/%ld cells (%ld resumed), rows %ld ok %ld failed, %.1f cells/min, elapsed %s, ETA %s\n",
                         ranks_ > 1 ? " rank 0" : "", p.cellsDone, p.cellsTotal, p.cellsResumed, p.rowsOk, p.rowsFailed,
                         60.0 * rate, hms(now).c_str(), hms(eta).c_str());
        }
        std::fflush(stderr);
    }

private:
    int ranks_;
    bool tty_;
    double lastLog_ = -1e9;
};

std::set<long> parseIdList(const std::string& text) {
    std::set<long> ids;
    std::stringstream ss(text);
    std::string item;
    while (std::getline(ss, item, ',')) {
        std::size_t used = 0;
        long id = -1;
        try {
            id = std::stol(item, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used == 0 || used != item.size() || id < 0)
            throw InputError(fmt::format("--inject-failures: '{}' is not a sample id (non-negative integer)", item));
        ids.insert(id);
    }
    return ids;
}

constexpr const char* kAnotherRankFailed = "another rank failed (see its message)";

/// Collective under MPI: every rank learns whether any rank failed, so that all take the same
/// path to MPI_Finalize (a rank that skipped a collective call would leave the others waiting).
void agreeOnFailure([[maybe_unused]] bool mpi, std::string& error) {
#ifdef TRBC_WITH_MPI
    if (!mpi) return;
    int failed = error.empty() ? 0 : 1, anyFailed = 0;
    MPI_Allreduce(&failed, &anyFailed, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    if (anyFailed && error.empty()) error = kAnotherRankFailed;
#endif
}

#ifdef TRBC_WITH_MPI
/// True when an MPI launcher (OpenMPI's mpirun/mpiexec, PMIx, or a PMI-based one such as MPICH's
/// hydra or Slurm's srun) started this process. A plain `trbc campaign` in an MPI build then runs
/// in one process without MPI_Init, which in a singleton may try to start a runtime daemon.
bool launchedByMpi() {
    for (const char* var : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
        if (std::getenv(var)) return true;
    return false;
}
#endif

struct CampaignCommandOptions {
    CampaignOptions c;
    std::string design = "uniform", out, inject, reuseFrom;
    int level = 4;
    CacheOptions cache;
};

void addCampaignOptions(CLI::App* cmd, CampaignCommandOptions& o) {
    addNumber(cmd, "--samples", o.c.samples, "number of samples (rows)", NumberRange::closed(1, 1e8))->capture_default_str();
    cmd->add_option("--design", o.design, "uniform (i.i.d., as the reference) or lhs (Latin hypercube)")
        ->capture_default_str();
    addNumber(cmd, "--seed", o.c.seed, "seed of the design", NumberRange::nonNegative())->capture_default_str();
    addNumber(cmd, "--level", o.level, "icosphere level of the meshes (4: Nv = 2562, the training level)",
              NumberRange::closed(2, 6))
        ->capture_default_str();
    addNumber(cmd, "--forces-per-cell", o.c.forcesPerCell,
                    "rows per cell: the rows of a cell share (v, mu, FvK, b2, etam) and one SFS, equilibrium, "
                    "stretching continuation and relaxation, and differ in Fext. 1 = the paper's one force per sample",
              NumberRange::closed(1, 1000))
        ->capture_default_str();
    addOutOption(cmd, o.out);
    addThreadsOption(cmd, o.c.threads, "cells run concurrently (one thread each)");
    addNumber(cmd, "--cell-time-limit", o.c.cellTimeLimit,
                    "wall-time budget of one cell (0: none); over it the cell's rows are recorded as failed with "
                    "the reason 'time limit reached' (equilibrium outputs computed before it are kept; which cells hit "
                    "it depends on the machine). Part of the settings: a resume must give the same value",
              NumberRange::closed(0.0, 1e6, "s"))
        ->capture_default_str();
    cmd->add_flag("--resume", o.c.resume, "continue the campaign in --out (same settings required; a uniform design ending on a whole cell grows: a larger --samples extends it)");
    cmd->add_option("--reuse-from", o.reuseFrom,
                    "an earlier campaign of the same design and settings with --equilibrium-symmetry inversion: each "
                    "cell still searches its lowest-energy equilibrium; where that is the symmetric disc of the earlier "
                    "rows (D, hmin, hmax equal bit for bit) their stretching and relaxation outputs are taken over, every "
                    "other cell is computed in full. The rows equal those of a run without it (wall_s aside)")
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--inject-failures", o.inject,
                    "comma-separated sample ids whose cell fails on purpose (to test failure records)");
    addSolverOptions(cmd, o.c.experiment);
    addCacheOptions(cmd, o.cache);
}

/// This process's rank and the number of ranks: under an MPI launcher MPI is initialised here
/// (and finalised by runCampaign), otherwise one rank without MPI.
struct Ranks {
    int rank = 0, size = 1;
    bool mpi = false;
};

Ranks startRanks() {
    Ranks r;
#ifdef TRBC_WITH_MPI
    r.mpi = launchedByMpi();
    if (r.mpi) {
        int provided = 0;
        MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
        MPI_Comm_rank(MPI_COMM_WORLD, &r.rank);
        MPI_Comm_size(MPI_COMM_WORLD, &r.size);
    }
#endif
    return r;
}

void runCampaign(const CampaignCommandOptions& o) {
    CampaignOptions c = o.c;
    c.design = parseDesignKind(o.design);
    c.outDir = o.out;
    c.command = commandLine();
    setProvenanceSeed(c.seed);
    c.experiment.level = o.level;
    c.experiment.cacheDir = cacheDirectory(o.cache);
    if (!o.inject.empty()) c.injectFailures = parseIdList(o.inject);
    c.reuseFrom = o.reuseFrom;
    const Ranks ranks = startRanks();
    c.ranks = ranks.size;
    ProgressReporter reporter(ranks.size);
    if (ranks.rank == 0) c.progress = [&reporter](const CampaignProgress& p) { reporter(p); };
    const auto t0 = SteadyClock::now();
    CampaignSummary share, s;
    std::string error;
    bool ioError = false;
    const auto attempt = [&](auto&& step) {
        try {
            step();
        } catch (const IoError& e) {
            error = e.what();
            ioError = true;
        } catch (const std::exception& e) {
            error = e.what();
        }
    };
    // Rank 0 locks the output directory for the whole run (every rank writes only its own part
    // file inside it) and prepares (or refuses) the campaign before any rank touches its part file.
    std::optional<OutputDirectory> outDir;
    if (ranks.rank == 0)
        attempt([&] {
            outDir.emplace(c.outDir, "campaign", "--out", std::vector<std::string>{"campaign.json"});
            prepareCampaign(c);
        });
    agreeOnFailure(ranks.mpi, error);
    if (error.empty()) attempt([&] { share = runCampaignShare(c, ranks.rank, ranks.size); });
    agreeOnFailure(ranks.mpi, error);
    if (error.empty() && ranks.rank == 0) attempt([&] { s = finalizeCampaign(c, secondsSince(t0)); });
#ifdef TRBC_WITH_MPI
    if (ranks.mpi) MPI_Finalize();
#endif
    // A rank that failed reports its own reason. Other ranks than 0 exit quietly when only
    // another rank failed: an early non-zero exit would make the launcher kill rank 0 before it
    // prints the reason, and rank 0 (or the failed rank) already gives the job its status.
    if (!error.empty() && !(ranks.rank != 0 && error == kAnotherRankFailed)) {
        if (ioError) throw IoError(error);
        throw InputError(error);
    }
    if (ranks.rank != 0) return;
    std::cout << fmt::format("campaign: {} of {} samples done ({} ok, {} failed); {} cells computed now, {} resumed; "
                             "{:.1f} s\n",
                             s.samples, c.samples, s.ok, s.failed, share.cellsComputed, share.cellsResumed,
                             s.wallSeconds);
    std::cout << (s.complete ? fmt::format("table: {}\n", (c.outDir / "samples.csv").string())
                             : std::string("incomplete: rerun with --resume\n"));
    if (!s.complete) throw NumericalError("campaign incomplete");
}

}  // namespace

void registerCampaign(CLI::App& app) {
    auto o = std::make_shared<CampaignCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "campaign",
        "Training campaign over the input box of docs/CAMPAIGN_AND_SURROGATE.md: one CSV row per sample (v, mu_uN_per_m, FvK, b2, "
        "etam_Pa_s_um, Fext_pN -> D_um, hmin_um, hmax_um, D0_um, D1_um, tc_s, status, reason, wall_s) in "
        "OUT/samples.csv, provenance in OUT/campaign.json. Checkpoints every cell; --resume continues a killed run. "
        "Under MPI (mpirun -n P trbc campaign ...) the cells are shared between ranks");
    addCampaignOptions(cmd, *o);
    cmd->callback([o]() { runCampaign(*o); });
}

}  // namespace trbc::cli
