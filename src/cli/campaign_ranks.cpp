#include "cli/campaign_ranks.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>

#ifdef TRBC_WITH_MPI
#include <mpi.h>
#endif

#include "core/error.hpp"

namespace trbc::cli {
namespace {

std::string hms(double s) {
    if (!std::isfinite(s) || s < 0) return "--";
    const long t = long(s + 0.5);
    return t >= 3600 ? fmt::format("{}h{:02}m", t / 3600, t / 60 % 60) : fmt::format("{}m{:02}s", t / 60, t % 60);
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
/// hydra or Slurm's srun) started this process. A plain run in an MPI build then runs in one
/// process without MPI_Init, which in a singleton may try to start a runtime daemon.
bool launchedByMpi() {
    for (const char* var : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
        if (std::getenv(var)) return true;
    return false;
}
#endif

}  // namespace

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

ProgressReporter::ProgressReporter(int ranks, std::string unit, std::string command)
    : ranks_(ranks), tty_(::isatty(STDERR_FILENO)), unit_(std::move(unit)), command_(std::move(command)) {}

void ProgressReporter::operator()(const CampaignProgress& p) {
    const double now = p.elapsedSeconds;
    const long computed = p.cellsDone - p.cellsResumed, left = p.cellsTotal - p.cellsDone;
    const double rate = now > 0 ? computed / now : 0.0;  // per second, this rank
    const double eta = rate > 0 ? left / rate : NAN;
    const bool last = p.cellsDone == p.cellsTotal;
    if (tty_) {
        const int width = 30, filled = p.cellsTotal ? int(width * p.cellsDone / p.cellsTotal) : width;
        std::fprintf(stderr, "\r[%s%s] %ld/%ld %s  %ld ok %ld failed  %.1f %s/min  ETA %s   ",
                     std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(), p.cellsDone, p.cellsTotal,
                     unit_.c_str(), p.rowsOk, p.rowsFailed, 60.0 * rate, unit_.c_str(), hms(eta).c_str());
        if (last) std::fputc('\n', stderr);
    } else if (last || p.cellsDone == p.cellsResumed || now - lastLog_ >= 30.0) {
        lastLog_ = now;
        std::fprintf(stderr, "%s%s: %ld/%ld %s (%ld resumed), %ld ok %ld failed, %.1f %s/min, elapsed %s, ETA %s\n",
                     command_.c_str(), ranks_ > 1 ? " rank 0" : "", p.cellsDone, p.cellsTotal, unit_.c_str(), p.cellsResumed,
                     p.rowsOk, p.rowsFailed, 60.0 * rate, unit_.c_str(), hms(now).c_str(), hms(eta).c_str());
    }
    std::fflush(stderr);
}

void runOnRanks(const Ranks& ranks, const std::function<void()>& prepare, const std::function<void()>& share,
                const std::function<void()>& finalize) {
    std::string error;
    bool ioError = false;
    const auto attempt = [&](const std::function<void()>& step) {
        try {
            step();
        } catch (const IoError& e) {
            error = e.what();
            ioError = true;
        } catch (const std::exception& e) {
            error = e.what();
        }
    };
    if (ranks.rank == 0) attempt(prepare);
    agreeOnFailure(ranks.mpi, error);
    if (error.empty()) attempt(share);
    agreeOnFailure(ranks.mpi, error);
    if (error.empty() && ranks.rank == 0) attempt(finalize);
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
}

void reportCampaign(const CampaignNames& names, long total, const CampaignSummary& s, const CampaignSummary& mine,
                    const std::filesystem::path& outDir, int ranks) {
    std::cout << fmt::format("{}: {} of {} {} done ({} ok, {} failed); {}{} computed now: {}, resumed: {}; {:.1f} s\n", names.command,
                             s.samples, total, names.items, s.ok, s.failed, ranks > 1 ? "rank 0: " : "", names.unit,
                             mine.cellsComputed, mine.cellsResumed, s.wallSeconds);
    std::cout << (s.complete ? fmt::format("table: {}\n", (outDir / names.table).string())
                             : std::string("incomplete: rerun with --resume\n"));
    if (!s.complete) throw NumericalError(names.command + " incomplete");
}

}  // namespace trbc::cli
