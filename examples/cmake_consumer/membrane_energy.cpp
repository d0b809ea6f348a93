// The membrane energy of a cell exported by `trbc export`, evaluated with trbc's membrane model
// (trbc::membrane): the equilibrium shape against the stress-free state, Juelicher bending plus the
// Lim in-plane law, in the physical units of the export (um, J/um^2, J). Prints the terms as JSON.
//   membrane_energy EXPORT_DIR
#include <nlohmann/json.hpp>

#include <fstream>
#include <iostream>

#include "core/error.hpp"
#include "membrane/model.hpp"
#include "mesh/io.hpp"

int main(int argc, char** argv) {
    if (argc != 2) {
        std::cerr << "usage: membrane_energy EXPORT_DIR (the --out folder of `trbc export`)\n";
        return 2;
    }
    const std::string dir = argv[1];
    try {
        std::ifstream in(dir + "/cell.json");
        if (!in) throw trbc::InputError(dir + "/cell.json: cannot open");
        const nlohmann::json cell = nlohmann::json::parse(in);
        const trbc::Mesh sfs = trbc::readOff(dir + "/sfs.off");
        const trbc::Mesh eq = trbc::readOff(dir + "/equilibrium.off");

        // mu in uN/m = 1e-18 J/um^2; the Lim coefficients are dimensionless; K_alpha = mu.
        const double mu = cell["physical"]["mu_uN_per_m"].get<double>() * 1e-18;
        const nlohmann::json& d = cell["dimensionless"];
        trbc::MembraneParameters p;
        p.bending.kb = cell["physical"]["kb_J"].get<double>();
        p.lim = {.Kalpha = mu, .a3 = d["a3"].get<double>(), .a4 = d["a4"].get<double>(),
                 .mu = mu, .b1 = d["b1"].get<double>(), .b2 = d["b2"].get<double>()};
        const trbc::MembraneModel model(eq.F, eq.X.cols(), p, &sfs.X);
        trbc::EnergyTerms terms;
        trbc::Vertices grad;
        model.evaluate(eq.X, &grad, &terms);
        std::cout << nlohmann::json{{"bending_J", terms.bending},
                                    {"lim_J", terms.lim},
                                    {"total_J", terms.total()},
                                    {"max_force_N", grad.colwise().norm().maxCoeff() * 1e6},
                                    {"vertices", eq.X.cols()}}
                         .dump(2)
                  << "\n";
    } catch (const std::exception& e) {
        std::cerr << "membrane_energy: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
