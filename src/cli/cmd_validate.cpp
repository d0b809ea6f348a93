// trbc validate: the options of the flow-validation set (docs/VALIDATE.md); the run itself is
// runValidation (analysis/validation_run.hpp).
#include <memory>

#include "analysis/validation_run.hpp"
#include "cli/common.hpp"

namespace trbc::cli {
namespace {

struct ValidateCommandOptions {
    std::string config, out, posterior, shard, surrogate, direct, thresholdProtocol;
    std::vector<std::string> only, imports;
    int jobs = 0, threads = 0, level = 0, draws = 0;
    std::uint64_t seed = 1;
    bool quiet = false, dryRun = false, retryFailed = false;
};

void addValidateOptions(CLI::App* cmd, ValidateCommandOptions& o) {
    cmd->add_option("--config", o.config, "validation configuration (TOML), e.g. configs/validation.toml")->required();
    addOutOption(cmd, o.out);
    cmd->add_option("--posterior", o.posterior,
                    "cell = the calibrated cell (the means) of this theta_new posterior (DIR/phase3/theta_new of `trbc infer`), overriding [cell]; "
                    "--draws takes its samples");
    addNumber(cmd, "--draws", o.draws,
              "also run every case for N draws of the posterior's samples (--posterior or [cell] posterior), chosen with "
              "--seed; tabulates the median and 5-95 % band of each observable (bands.csv, draws.csv, validation.md); 0: "
              "the configured cell only",
              NumberRange::closed(0, 100000));
    addNumber(cmd, "--seed", o.seed, "seed of the choice of the --draws samples (recorded in validation.json and each draw's record)",
              NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--level", o.level,
              "icosphere level of the shear cases (overrides run.level; the tube keeps tube.level unless that is 0)",
              NumberRange::closed(1, 4));
    addNumber(cmd, "--jobs", o.jobs, "cases run at the same time (overrides run.jobs)", NumberRange::closed(1, 256));
    addThreadsOption(cmd, o.threads, "OpenMP threads per case (overrides run.threads)");
    cmd->add_option("--only", o.only, "run only these kinds of case (angle, ttf, threshold, tube; repeatable or comma-separated); "
                                      "the tables cover what has been run")
        ->delimiter(',')
        ->check(CLI::IsMember({"angle", "ttf", "threshold", "tube"}));
    cmd->add_option("--threshold-protocol", o.thresholdProtocol,
                    "protocol of the threshold cases, overriding [shear] threshold_protocol: in-plane (one run per rate from "
                    "the configured start), ensemble (threshold_members random starts) or fluctuating (threshold_members "
                    "cells at temperature_K, the default; docs/FLOW_THERMAL.md)")
        ->check(CLI::IsMember({"in-plane", "ensemble", "fluctuating"}));
    cmd->add_option("--shard", o.shard,
                    "run only part K of N of the (selected) initial cases, e.g. 2/4 on the second of four machines, each with "
                    "its own OUT: dealt round-robin, one part per angle, TTF or tube case and per threshold viscosity (its "
                    "refinements stay with it); merge the parts with --import");
    cmd->add_option("--import", o.imports,
                    "another validate OUT directory (repeatable): a finished case recorded there with the same key (same "
                    "command, cell and version) is copied into OUT with its outputs instead of being run, e.g. the parts "
                    "of a --shard run")
        ->check(CLI::ExistingDirectory);
    cmd->add_flag("--retry-failed", o.retryFailed, "run again the cases recorded as failed (a transient failure; "
                                                  "by default a failed case is kept like a finished one)");
    cmd->add_flag("--dry-run", o.dryRun, "list the initial cases and their commands, marking those recorded in OUT with the same key "
                                      "([finished], or [failed] for a kept failure); run nothing");
    cmd->add_flag("--quiet", o.quiet, "no progress lines on stderr");
    cmd->add_option("--surrogate", o.surrogate,
                    "flow networks (a `trbc flow train` directory): predict every angle, TTF and threshold case of the config "
                    "for the --draws through them in seconds instead of running any case (surrogate_bands.csv, .md, .json)")
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--direct", o.direct,
                    "with --surrogate: a finished `trbc validate --draws N` output directory of the same config and posterior; its "
                    "angle, TTF and threshold cases are compared with the networks at the same draws and over the --draws "
                    "(surrogate_cross_check.csv, .md; docs/FLOW_NETWORKS.md)")
        ->check(CLI::ExistingDirectory);
}

void runValidate(const ValidateCommandOptions& o) {
    ValidationRunOptions r;
    r.config = o.config, r.out = o.out, r.posterior = o.posterior, r.surrogate = o.surrogate, r.direct = o.direct;
    r.only = o.only, r.imports = o.imports, r.shard = o.shard, r.thresholdProtocol = o.thresholdProtocol;
    r.jobs = o.jobs, r.threads = o.threads, r.level = o.level, r.draws = o.draws, r.seed = o.seed;
    r.quiet = o.quiet, r.dryRun = o.dryRun, r.retryFailed = o.retryFailed;
    r.exe = std::filesystem::read_symlink("/proc/self/exe");
    r.scripts = scriptDirectory();
    r.python = pythonInterpreter();
    r.experimentDir = defaultExperimentDirectory();
    r.command = commandLine();
    runValidation(r);
}

}  // namespace

void registerValidate(CLI::App& app) {
    auto o = std::make_shared<ValidateCommandOptions>();
    CLI::App* cmd = app.add_subcommand(
        "validate", "Run the flow-validation set of docs/VALIDATE.md (inclination angle, tank-treading frequency, "
                    "tumbling/tank-treading threshold in shear flow; velocity and length in a microtube) with `trbc flow`, "
                    "compare every case with the experimental scatter and draw the paper's figures. Resumable: run the same "
                    "command again after an interruption and only unfinished cases run. With --draws N, every case also "
                    "runs for N draws of the posterior and each observable gets its median and 5-95 % band. Writes OUT/shear.csv, "
                    "threshold.csv, tube.csv, comparison.csv, validation.md, validation.json, figures/ and cases/");
    addValidateOptions(cmd, *o);
    cmd->callback([o]() { runValidate(*o); });
}

}  // namespace trbc::cli
