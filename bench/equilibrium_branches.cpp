// The equilibrium's two branches near a spherical SFS (docs/EQUILIBRIUM.md "Two equilibria near
// v = 1"): for a grid of (v, FvK, b2), the symmetric equilibrium (the default), the unrestricted one
// (--equilibrium-symmetry none, multigrid H0) and the symmetric one kicked by a random vertex
// displacement of rms KICK um and relaxed without the restriction (plain L-BFGS): a kicked disc that
// comes back is a local minimum of the full problem. CSV on stdout; energies in J.
//   build/bench_equilibrium_branches [LEVEL=4] [KICK_UM=1e-3]
#include <cstdio>
#include <cstdlib>
#include <random>

#include "experiments/experiments.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "solvers/minimize.hpp"

using namespace trbc;

int main(int argc, char** argv) {
    const int level = argc > 1 ? std::atoi(argv[1]) : 4;
    const double kick = argc > 2 ? std::atof(argv[2]) : 1e-3;
    std::printf("v,FvK,b2,hmin_um_symmetric,energy_J_symmetric,hmin_um_unrestricted,energy_J_unrestricted,"
                "hmin_um_kicked,energy_J_kicked\n");
    for (double v : {0.98, 0.99, 0.995, 0.999, 1.0})
        for (double fvk : {10.0, 50.0, 200.0, 1000.0})
            for (double b2 : {0.0, 4.0}) {
                CellParameters p;
                p.v = v;
                p.FvK = fvk;
                p.b2 = b2;
                ExperimentOptions opt;
                opt.level = level;
                opt.equilibriumSymmetry = EquilibriumSymmetry::Inversion;
                const CellMeshes m = cellMeshes(stressFreeState(v, level, "", opt.sfs));
                const EquilibriumResult sym = runEquilibrium(p, m, opt);
                ExperimentOptions free = opt;
                free.equilibriumSymmetry = EquilibriumSymmetry::None;
                const EquilibriumResult unr = runEquilibrium(p, m, free);
                const MembraneModel model(m.faces, m.reference.cols(), experimentMembrane(p), &m.reference);
                std::mt19937 rng(1);
                std::normal_distribution<double> normal;
                Vertices X = sym.shape;
                for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] += kick * normal(rng);
                MinimizeOptions mo;
                mo.gradientTolerance = 1e-6 * p.mu;
                const MinimizeResult r = minimizeEnergy(model, X, mo, nullptr, {cell::area, cell::volume});
                const double hKicked = equilibriumObservables(alignPrincipalAxes(X), m.faces).hmin;
                std::printf("%g,%g,%g,%.4f,%.6e,%.4f,%.6e,%.4f,%.6e%s\n", v, fvk, b2, sym.observables.hmin,
                            sym.diagnostics.energy / cell::joule, unr.observables.hmin,
                            unr.diagnostics.energy / cell::joule, hKicked, r.energy / cell::joule,
                            r.converged ? "" : ",not converged");
                std::fflush(stdout);
            }
}
