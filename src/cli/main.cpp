// trbc: the command-line tool. Each subcommand lives in its own file and only parses and calls.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iostream>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <string>
#include <vector>

#include "core/child_process.hpp"
#include "core/simd.hpp"
#include "cli/common.hpp"
#include "core/error.hpp"
#include "core/version.hpp"

namespace {

/// Levenshtein distance, for "did you mean" on a mistyped command.
std::size_t editDistance(const std::string& a, const std::string& b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diagonal = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diagonal = up;
        }
    }
    return row[b.size()];
}

/// The leading words of the command line name (sub)commands: an unknown one is an error that lists
/// the valid ones and suggests the closest, instead of CLI11's "A subcommand is required".
void checkCommandWords(CLI::App& app, int argc, char** argv) {
    CLI::App* current = &app;
    for (int i = 1; i < argc; ++i) {
        const std::vector<CLI::App*> subs = current->get_subcommands([](CLI::App*) { return true; });
        const std::string word = argv[i];
        if (subs.empty() || word.empty() || word[0] == '-') return;
        CLI::App* next = nullptr;
        std::string names, closest;
        std::size_t best = 3;  // suggest only within two edits
        for (CLI::App* s : subs) {
            if (s->get_name() == word) next = s;
            names += (names.empty() ? "" : ", ") + s->get_name();
            if (const std::size_t d = editDistance(word, s->get_name()); d < best) best = d, closest = s->get_name();
        }
        if (!next) {
            const std::string where = current == &app ? std::string("trbc") : "trbc ... " + current->get_name();
            throw trbc::InputError(fmt::format("unknown command '{}' after '{}'{} (commands: {})", word, where,
                                               closest.empty() ? "" : fmt::format("; did you mean '{}'?", closest), names));
        }
        current = next;
    }
    // Out of words where a (sub)command must follow: list them.
    const std::vector<CLI::App*> subs = current->get_subcommands([](CLI::App*) { return true; });
    if (!subs.empty()) {
        std::string names;
        for (CLI::App* s : subs) names += (names.empty() ? "" : ", ") + s->get_name();
        throw trbc::InputError(fmt::format("'{}' needs a command: one of {} (add --help for what each does)",
                                           current == &app ? std::string("trbc") : current->get_name(), names));
    }
}

/// Freed memory stays in the heap. The flow steps allocate and free the same few MB every step
/// (operators, factorisation, Krylov basis); glibc's defaults (a dynamic mapping threshold from
/// 128 kB, freed heap tops above twice it returned) hand much of it back and map it again as
/// fresh zeroed pages: 0.27 s of system time per level-3 shear rotation, 0.01 s with the fixed
/// thresholds below (docs/PERFORMANCE.md). Every subcommand gets them: the peak memory is that of
/// the same allocations; what is freed is kept for reuse instead of returned.
void keepFreedMemory() {
#if defined(__GLIBC__)
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 64 << 20);
#endif
}

}  // namespace

int main(int argc, char** argv) {
    trbc::dieWithParent();
    keepFreedMemory();
    trbc::cli::setCommandLine(argc, argv);
    CLI::App app{"trbc: a calibrated, transferable red-blood-cell membrane model"};
    // The revision beside the version, as every record's provenance names the build: scripts that
    // keep a finished run compare it, so that a rebuilt binary runs again.
    app.set_version_flag("--version", fmt::format("{} ({})", trbc::kVersion, trbc::gitDescribe()));
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
    // Command-line errors in the same "trbc: error: ..." form as every other bad input.
    app.failure_message([](const CLI::App*, const CLI::Error& e) {
        return fmt::format("trbc: error: {}\nRun with --help for the options and their valid ranges.\n", e.what());
    });
    try {
        // TRBC_SIMD is read once; a bad value must fail here, not inside a parallel region.
        (void)trbc::simd::active();
        checkCommandWords(app, argc, argv);
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // --help and --version exit 0; every other command-line error is bad input (exit 2, as
        // InputError), whatever CLI11's own code for it.
        return app.exit(e) == 0 ? 0 : 2;
    } catch (const trbc::InputError& e) {
        std::cerr << "trbc: error: " << e.what() << '\n';
        return 2;
    } catch (const trbc::IoError& e) {
        std::cout.flush();
        std::cerr << "trbc: I/O error: " << e.what() << '\n';
        return 5;
    } catch (const trbc::NumericalError& e) {
        std::cerr << "trbc: numerical failure: " << e.what() << '\n';
        return 3;
    } catch (const std::exception& e) {
        std::cerr << "trbc: internal error: " << e.what() << '\n';
        return 4;
    }
    // A result printed to a full disk is no result.
    errno = 0;
    std::cout.flush();
    if (!std::cout) {
        std::cerr << "trbc: I/O error: cannot write the standard output: " << (errno != 0 ? std::strerror(errno) : "write failed") << '\n';
        return 5;
    }
    return 0;
}
