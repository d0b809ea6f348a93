// The tables of the tube wall in docs/flow_verification.md: the rigid sphere's drag and free
// speed against Haberman & Sayre (1958) over the sphere level and the wall points per ring
// (flow/stokes_verification.hpp), the free sphere at large beta, and a red cell's velocity at a
// fixed shape against the wall resolution. Minutes on 2 cores.
//   build/bench_tube_convergence_table [table|large|cell]   (default: table)

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "core/scratch_dir.hpp"
#include "experiments/parameters.hpp"
#include "flow/cell_flow.hpp"
#include "flow/stokes_verification.hpp"
#include "flow/tube.hpp"
#include "mesh/geometry.hpp"

using namespace trbc;
using namespace trbc::stokes_verification;

namespace {

const std::filesystem::path& cacheDir() {
    static const std::filesystem::path d = processTemporaryDirectory("trbc_tube_table_cache_");
    return d;
}

/// Cell velocity (mean vertex velocity, cm/s) at a fixed shape against the wall resolution:
/// Table 1 cell fitted into the 6.6 um tube at 30 mmHg/mm (the production case's first state).
void cellVelocityVsWall() {
    for (int level : {2, 3}) {
        const CellParameters p = paperTable1Cell();
        const ShearCell c = prepareShearCell(p, level, cacheDir());
        const double R = 3.3, pg = 30.0, V = pg / 45.0 * 1e4, T = R / V;
        FlowConditions fc;
        fc.etaOut = fc.etaIn = 1.003;
        fc.timeScale = T;
        const CellFlowModel model(p, fc, c.faces, c.reference);
        const double L = model.scales().length;
        const Vertices X0 = model.toInternal(fitIntoTube(c.initial, c.faces, R, 0.1 * R, fc.A0, fc.V0));
        for (int N : {12, 16, 24, 32, 40}) {
            TubeSetup s;
            s.radius = R / L;
            s.centreLineSpeed = pg * 1.33322e5 * std::pow(R * 1e-6, 2) / (4.0 * 1.003e-3) * 1e6 * T / L;
            s.halfLength = 1.15 * X0.row(0).cwiseAbs().maxCoeff() + 2.0 * s.radius;
            s.pointsPerRing = N;
            s.vertexWeight = model.targetArea() / static_cast<double>(X0.cols());
            const auto t0 = std::chrono::steady_clock::now();
            const TubeEnvironment env(s);
            const VelocityEvaluation u = membraneVelocity(model, X0, {}, &env);
            const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            std::printf("| %d | %d | %ld | %.5f | %d | %.1f |\n", level, N, static_cast<long>(env.wall().numVertices()),
                        u.velocity.row(0).mean() * L / T * 1e-4, u.gmresIterations, sec);
        }
    }
}

void freeSphereLarge() {
    for (double beta : {0.6, 0.7})
        for (int N : {16, 24, 32}) {
            const TubeWall w(1.0, beta + 2.5, N);
            RigidBodyResult r;
            const double e = freeSphereError(sphereOps(3, beta), w, beta, &r);
            std::printf("beta %.1f N %d: U/Uc %.5f (HS %.5f, error %.2e)\n", beta, N, r.velocity.x(), habermanFreeSpeed(beta), e);
        }
}

// Level-by-resolution table for docs/flow_verification.md.
void levelByResolution() {
    std::printf("| sphere level | wall points per ring | wall vertices | drag 0.3 | drag 0.5 | free sphere 0.4 | seconds |\n");
    for (int level : {2, 3})
        for (int N : {12, 16, 24, 32, 40}) {
            const auto t0 = std::chrono::steady_clock::now();
            const TubeWall w3(1.0, 0.3 + 2.5, N), w5(1.0, 0.5 + 2.5, N), w4(1.0, 0.4 + 2.5, N);
            const double d3 = dragError(sphereOps(level, 0.3), w3, 0.3);
            const double d5 = dragError(sphereOps(level, 0.5), w5, 0.5);
            const double f4 = freeSphereError(sphereOps(level, 0.4), w4, 0.4);
            const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            std::printf("| %d | %d | %ld | %.2e | %.2e | %.2e | %.1f |\n", level, N, static_cast<long>(w4.numVertices()), d3,
                        d5, f4, s);
        }
}

}  // namespace

int main(int argc, char** argv) {
    const std::string which = argc > 1 ? argv[1] : "table";
    if (which == "table") {
        levelByResolution();
    } else if (which == "large") {
        freeSphereLarge();
    } else if (which == "cell") {
        cellVelocityVsWall();
    } else {
        std::fprintf(stderr, "bench_tube_convergence_table: '%s' is not a table (valid: table, large, cell)\n", which.c_str());
        return 2;
    }
    std::error_code ec;
    std::filesystem::remove_all(cacheDir(), ec);
    return 0;
}
