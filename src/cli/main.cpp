// trbc: the command-line tool. Each subcommand lives in its own file and only parses and calls.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <iostream>

#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/version.hpp"

int main(int argc, char** argv) {
    trbc::cli::setCommandLine(argc, argv);
    CLI::App app{"trbc: a calibrated, transferable red-blood-cell membrane model"};
    app.set_version_flag("--version", std::string(trbc::kVersion));
    app.require_subcommand(1);
    trbc::cli::registerForces(app);
    trbc::cli::registerMesh(app);
    trbc::cli::registerMinimize(app);
    trbc::cli::registerSfs(app);
    trbc::cli::registerSimulate(app);
    trbc::cli::registerCampaign(app);
    trbc::cli::registerSurrogate(app);
    trbc::cli::registerSobol(app);
    trbc::cli::registerInfer(app);
    trbc::cli::registerPredict(app);
    trbc::cli::registerFlow(app);
    trbc::cli::registerCalibrate(app);
    trbc::cli::registerExport(app);
    trbc::cli::registerValidate(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // --help and --version exit 0; every other command-line error is bad input (exit 2, as
        // InputError), whatever CLI11's own code for it.
        return app.exit(e) == 0 ? 0 : 2;
    } catch (const trbc::InputError& e) {
        std::cerr << "trbc: error: " << e.what() << '\n';
        return 2;
    } catch (const trbc::NumericalError& e) {
        std::cerr << "trbc: numerical failure: " << e.what() << '\n';
        return 3;
    } catch (const std::exception& e) {
        std::cerr << "trbc: internal error: " << e.what() << '\n';
        return 4;
    }
    return 0;
}
