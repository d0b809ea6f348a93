// The convergence table of docs/flow_verification.md: the exact-solution checks of the
// boundary-integral Stokes solver (flow/stokes_verification.hpp) at icosphere levels 1-4,
// matrix-free at level 4; several minutes on 2 cores.
//   build/bench_stokes_convergence_table
#include <chrono>
#include <cstdio>

#include "flow/boundary_integral.hpp"
#include "flow/stokes_verification.hpp"
#include "mesh/icosphere.hpp"

using namespace trbc;
using namespace trbc::stokes_verification;

int main() {
    std::printf("| level | Nv | drag (transl.) | torque (rot.) | shear: Omega, U | shear: stresslet | "
                "HR U, lambda=0.1 | HR U, lambda=1 | HR U, lambda=5 | HR field max, lambda=0.1/1/5 | "
                "GMRES its transl./shear/HR 0.1/HR 5 | seconds |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int level = 1; level <= 4; ++level) {
        const auto t0 = std::chrono::steady_clock::now();
        const BoundaryIntegralOperators ops(icosphere(level));
        int i1 = 0, i3 = 0, i01 = 0, i5 = 0;
        const double e1 = translatingSphereError(ops, &i1), e2 = rotatingSphereError(ops);
        const auto e3 = shearedSphereErrors(level, &i3);
        const auto h01 = hadamardRybczynskiErrors(ops, 0.1, &i01), h1 = hadamardRybczynskiErrors(ops, 1.0),
                   h5 = hadamardRybczynskiErrors(ops, 5.0, &i5);
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::printf("| %d | %ld | %.2e | %.2e | %.1e | %.2e | %.2e | %.2e | %.2e | %.1e / %.1e / %.1e | "
                    "%d / %d / %d / %d | %.1f |\n",
                    level, static_cast<long>(ops.numVertices()), e1, e2, e3.first, e3.second, h01.first,
                    h1.first, h5.first, h01.second, h1.second, h5.second, i1, i3, i01, i5, s);
        std::fflush(stdout);
    }
    return 0;
}
