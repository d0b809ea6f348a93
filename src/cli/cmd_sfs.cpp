// trbc sfs: the stress-free state for a reduced volume (docs/FORWARD_MODEL.md, stress-free state), cached by (v, level, version).
#include <fmt/format.h>

#include <iostream>
#include <memory>

#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/version.hpp"
#include "experiments/parameters.hpp"
#include "experiments/sfs.hpp"
#include "mesh/geometry.hpp"
#include "mesh/io.hpp"

namespace trbc::cli {

void addCacheOptions(CLI::App* cmd, CacheOptions& c) {
    cmd->add_option("--cache", c.dir, "SFS cache directory (default: $TRBC_CACHE_DIR, $XDG_CACHE_HOME/trbc or ~/.cache/trbc)");
    cmd->add_flag("--no-cache", c.disabled, "neither read nor write the SFS cache");
}

std::filesystem::path cacheDirectory(const CacheOptions& c) {
    if (c.disabled) return {};
    return c.dir.empty() ? defaultCacheDirectory() : std::filesystem::path(c.dir);
}

void registerSfs(CLI::App& app) {
    struct Opts {
        double v = 0.95;
        int level = 4;
        std::string out;
        CacheOptions cache;
        double tolerance = SfsOptions{}.gradientTolerance;
        std::string preconditioner = "multigrid";
    };
    auto o = std::make_shared<Opts>();
    CLI::App* cmd = app.add_subcommand(
        "sfs", "Stress-free state of the cytoskeleton for a reduced volume v (docs/FORWARD_MODEL.md, stress-free state), written at the "
               "cell area A0 = 135 um^2 (um), cached on disk by (v, level, model version)");
    addNumber(cmd, "--v", o->v, "reduced volume v (prior [0.65, 1])", NumberRange::leftOpen(0.0, 1.0))->required();
    addNumber(cmd, "--level", o->level, "icosphere level (Nv = 10 4^L + 2)", NumberRange::closed(1, 6))->capture_default_str();
    addOutOption(cmd, o->out, "output mesh (.off, .ply or .vtk), in um at area 135 um^2");
    cmd->add_option("--preconditioner", o->preconditioner,
                    "H0 of the L-BFGS: multigrid on the icosphere hierarchy, or none (docs/FORWARD_MODEL.md)")
        ->check(CLI::IsMember({"multigrid", "none"}))->capture_default_str();
    addNumber(cmd, "--tol", o->tolerance, "stop when the largest tangential force is below this",
              NumberRange::leftOpen(0.0, 1.0, "kappa / R'_A"))
        ->capture_default_str();
    addCacheOptions(cmd, o->cache);
    cmd->callback([o]() {
        ensureWritableFile(o->out);
        SfsOptions so;
        so.gradientTolerance = o->tolerance;
        so.multigrid = o->preconditioner == "multigrid";
        ProgressLine progress("sfs");
        progress.stage(fmt::format("stress-free state (v = {:g}, level {})", o->v, o->level));
        const StressFreeState s = stressFreeState(o->v, o->level, cacheDirectory(o->cache), so);
        Mesh out = s.mesh;
        out.X = scaleToArea(out.X, out.F, cell::area);
        writeMesh(o->out, out);
        nlohmann::json j;
        j["sfs"] = sfsJson(s);
        j["mesh"] = meshSummary(out);
        j["output"] = o->out;
        j["provenance"] = withBuild({{"command", commandLine()}, {"sfs_model_version", kSfsModelVersion}});
        std::cout << j.dump(2) << std::endl;
    });
}

}  // namespace trbc::cli
