// trbc campaign: the training campaign of docs/CAMPAIGN_AND_SURROGATE.md. Parses, then calls
// sampling/campaign; under MPI (cli/campaign_ranks.hpp) the cells are shared round robin between
// ranks, each rank checkpointing to its own part file.
#include <memory>

#include "cli/campaign_ranks.hpp"
#include "cli/common.hpp"
#include "core/error.hpp"
#include "sampling/campaign.hpp"

namespace trbc::cli {
namespace {

struct CampaignCommandOptions {
    CampaignOptions c;
    std::string design = "uniform", out, inject, reuseFrom;
    int level = 4;
    CacheOptions cache;
};

void addCampaignOptions(CLI::App* cmd, CampaignCommandOptions& o) {
    addNumber(cmd, "--samples", o.c.samples, "number of samples (rows)", NumberRange::closed(1, 1e8))->capture_default_str();
    cmd->add_option("--design", o.design, "uniform (i.i.d., as the reference) or lhs (Latin hypercube); sobol is for `trbc flow campaign`")
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

void runCampaign(const CampaignCommandOptions& o) {
    CampaignOptions c = o.c;
    c.design = parseDesignKind(o.design);
    c.outDir = o.out;
    c.command = commandLine();
    setProvenanceSeed(c.seed);
    c.experiment.level = o.level;
    c.experiment.cacheDir = cacheDirectory(o.cache);
    if (!o.inject.empty()) for (long id : parseIntegerList(o.inject, "--inject-failures", "a sample id", 0)) c.injectFailures.insert(id);
    c.reuseFrom = o.reuseFrom;
    runCampaignCommand(c, {"campaign", "cells", "samples", "samples.csv"}, c.samples, prepareCampaign, runCampaignShare,
                       finalizeCampaign);
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
