#pragma once
// What `trbc campaign` and `trbc flow campaign` share: the ranks of an MPI launch (built with
// TRBC_WITH_MPI, run with mpirun; one rank otherwise), the agreement on a failure that keeps every
// rank on the same path to MPI_Finalize, and the progress line with rate and ETA.
#include <functional>
#include <string>

#include "sampling/campaign.hpp"

namespace trbc::cli {

/// This process's rank and the number of ranks: under an MPI launcher MPI is initialised here (and
/// finalised by runOnRanks), otherwise one rank without MPI.
struct Ranks {
    int rank = 0, size = 1;
    bool mpi = false;
};
Ranks startRanks();

/// A progress bar with rate and ETA on a terminal; plain log lines (every 30 s) otherwise. `unit`
/// names what is counted ("cells", "cases").
class ProgressReporter {
public:
    ProgressReporter(int ranks, std::string unit, std::string command);
    void operator()(const CampaignProgress& p);

private:
    int ranks_;
    bool tty_;
    std::string unit_, command_;
    double lastLog_ = -1e9;
};

/// The three collective phases of a campaign: `prepare` on rank 0 (it also locks the output
/// directory), `share` on every rank, `finalize` on rank 0, with every rank learning after each
/// phase whether any failed. Finalises MPI. Throws the failure on the rank that had it (IoError or
/// InputError); other ranks return quietly when only another rank failed.
void runOnRanks(const Ranks& ranks, const std::function<void()>& prepare, const std::function<void()>& share,
                const std::function<void()>& finalize);

}  // namespace trbc::cli
