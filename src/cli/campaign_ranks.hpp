#pragma once
// What `trbc campaign` and `trbc flow campaign` share: the ranks of an MPI launch (built with
// TRBC_WITH_MPI, run with mpirun; one rank otherwise), the agreement on a failure that keeps every
// rank on the same path to MPI_Finalize, the progress line with rate and ETA, and the run of a
// campaign command over these (runCampaignCommand).
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "core/output_dir.hpp"
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

/// How a campaign command names itself: `command` ("flow campaign") in its lock, progress and
/// summary, `unit` what a rank computes ("cells"), `items` the rows of its table ("samples") and
/// `table` that table's file name.
struct CampaignNames {
    std::string command, unit, items, table;
};

/// Rank 0's summary line and the table's path, or "incomplete: rerun with --resume" and then
/// NumericalError; `total` is the campaign's size, `mine` rank 0's share.
void reportCampaign(const CampaignNames& names, long total, const CampaignSummary& s, const CampaignSummary& mine,
                    const std::filesystem::path& outDir, int ranks);

/// A campaign command's run: the ranks, rank 0's progress line, the output directory locked by
/// rank 0 for the whole run (every rank writes only its own part file in it) and the campaign
/// prepared (or refused) before any rank touches its part file; then every rank's share, rank 0's
/// finalisation and its report. `Options` has the members ranks, progress and outDir;
/// `prepare(c)`, `share(c, rank, ranks)` and `finalize(c, wallSeconds)` are the library's phases.
template <class Options, class Prepare, class Share, class Finalize>
void runCampaignCommand(Options& c, const CampaignNames& names, long total, Prepare prepare, Share share, Finalize finalize) {
    const Ranks ranks = startRanks();
    c.ranks = ranks.size;
    ProgressReporter reporter(ranks.size, names.unit, names.command);
    if (ranks.rank == 0) c.progress = [&reporter](const CampaignProgress& p) { reporter(p); };
    const auto t0 = SteadyClock::now();
    CampaignSummary mine, s;
    std::optional<OutputDirectory> outDir;
    runOnRanks(
        ranks,
        [&] {
            outDir.emplace(c.outDir, names.command, "--out", std::vector<std::string>{"campaign.json"});
            prepare(c);
        },
        [&] { mine = share(c, ranks.rank, ranks.size); }, [&] { s = finalize(c, secondsSince(t0)); });
    if (ranks.rank == 0) reportCampaign(names, total, s, mine, c.outDir, ranks.size);
}

}  // namespace trbc::cli
