#include "sampling/campaign.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <optional>
#include <sstream>

#include "core/clock.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/file_io.hpp"
#include "core/version.hpp"
#include "sampling/part_file.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

fs::path partsDir(const CampaignOptions& o) { return o.outDir / "parts"; }
fs::path partPath(const CampaignOptions& o, int rank) { return partsDir(o) / fmt::format("rank{}.csv", rank); }
fs::path provenancePath(const CampaignOptions& o) { return o.outDir / "campaign.json"; }
fs::path samplesPath(const CampaignOptions& o) { return o.outDir / "samples.csv"; }
fs::path equilibriaDir(const CampaignOptions& o) { return o.outDir / "equilibria"; }
fs::path equilibriaPath(const CampaignOptions& o) { return o.outDir / "equilibria.csv"; }

/// Everything that decides the rows; a resume must match it exactly.
nlohmann::json settingsJson(const CampaignOptions& o) {
    const ExperimentOptions& e = o.experiment;
    nlohmann::json j = {{"design", designName(o.design)},
            {"samples", o.samples},
            {"forces_per_cell", o.forcesPerCell},
            {"seed", o.seed},
            {"level", e.level},
            {"static_tolerance", e.staticTolerance},
            {"max_iterations", e.maxIterations},
            {"relax_error_tolerance", e.relaxErrorTolerance},
            {"relax_inner_tolerance", e.relaxInnerTolerance},
            {"overdamped", e.overdamped},
            {"vertex_mass_kg", e.vertexMassKg},
            {"isotropic_friction", e.isotropicFriction},
            {"relax_duration_s", e.relaxDuration},
            {"relax_samples", e.relaxSamples},
            {"forward_model_revision", kForwardModelRevision},
            {"sfs_gradient_tolerance", e.sfs.gradientTolerance},
            {"inject_failures", std::vector<long>(o.injectFailures.begin(), o.injectFailures.end())}};
    // Only when not the default, so that campaigns made before the option existed still resume.
    if (e.inPlaneAxis != InPlaneAxis::FarthestVertex) j["in_plane_axis"] = inPlaneAxisName(e.inPlaneAxis);
    // Campaigns made before the multigrid H0 existed have no key and resume with --preconditioner none.
    if (e.multigrid) j["preconditioner"] = "multigrid";
    // Campaigns made before it existed have no key and resume with --equilibrium-symmetry none; those
    // of the symmetric disc say "inversion" (and resume with --equilibrium-symmetry inversion).
    if (e.equilibriumSymmetry != EquilibriumSymmetry::None)
        j["equilibrium_symmetry"] = equilibriumSymmetryName(e.equilibriumSymmetry);
    if (e.equilibriumSymmetry == EquilibriumSymmetry::Lowest) {
        j["equilibrium_seed"] = e.kicks.seed;
        j["equilibrium_kicks"] = e.kicks.perRound;
    }
    // Decides which rows fail (and depends on the machine's speed), so a resume must keep it.
    if (o.cellTimeLimit > 0) j["cell_time_limit_s"] = o.cellTimeLimit;
    return j;
}

void writeJsonAtomically(const fs::path& path, const nlohmann::json& j) { writeFileAtomically(path, j.dump(2) + "\n"); }

/// A uniform design is drawn row by row (sampling/design.cpp), so a campaign of more samples
/// extends one of fewer with the same settings, provided the old one ends on a whole cell.
bool canGrow(const nlohmann::json& oldSettings, const nlohmann::json& settings) {
    if (!oldSettings.contains("samples") || settings["design"] != "uniform") return false;
    const long before = oldSettings["samples"].get<long>(), after = settings["samples"].get<long>();
    const long perCell = settings["forces_per_cell"].get<long>();
    if (after < before || before % perCell != 0) return false;
    nlohmann::json same = oldSettings;
    same["samples"] = settings["samples"];
    return same == settings;
}

void validateOptions(const CampaignOptions& o) {
    // The cells' 5-D and the forces' 1-D Sobol' sequences would share their first coordinate (v
    // and Fext perfectly correlated); the flow campaign has one design of all its inputs.
    if (o.design == DesignKind::Sobol)
        throw InputError("--design sobol is for `trbc flow campaign`; the cell campaign takes uniform or lhs");
    if (o.samples < 1 || o.samples > 100'000'000)
        throw InputError(fmt::format("--samples {} is outside [1, 1e8]", o.samples));
    if (o.forcesPerCell < 1 || o.forcesPerCell > 1000)
        throw InputError(fmt::format("--forces-per-cell {} is outside [1, 1000]", o.forcesPerCell));
    if (o.threads < 1 || o.threads > 1024) throw InputError(fmt::format("--threads {} is outside [1, 1024]", o.threads));
    // Level 1 (42 vertices) has no bead contact set at the stretching's 2 um contact diameter.
    if (o.experiment.level < 2 || o.experiment.level > 6)
        throw InputError(fmt::format("--level {} is outside [2, 6]", o.experiment.level));
    if (o.outDir.empty()) throw InputError("--out: an output directory is required");
    if (!(o.cellTimeLimit >= 0.0 && o.cellTimeLimit <= 1e6))
        throw InputError(fmt::format("--cell-time-limit {} is outside [0, 1e6] s (0: none)", o.cellTimeLimit));
}

/// " key (<haveWord> X, <wantWord> Y)" for every setting that differs between `have` and `want`.
std::string settingsDiff(const nlohmann::json& have, const nlohmann::json& want, const char* haveWord, const char* wantWord) {
    std::string diff;
    for (auto& [k, v] : want.items())
        if (!have.contains(k) || have[k] != v)
            diff += fmt::format(" {} ({} {}, {} {})", k, haveWord, have.value(k, nlohmann::json()).dump(), wantWord, v.dump());
    for (auto& [k, v] : have.items())
        if (!want.contains(k)) diff += fmt::format(" {} ({} {}, {} not set)", k, haveWord, v.dump(), wantWord);
    return diff;
}

/// The settings a campaign of the symmetric disc would have with otherwise the same settings as `o`.
nlohmann::json donorSettings(const CampaignOptions& o) {
    nlohmann::json j = settingsJson(o);
    j["equilibrium_symmetry"] = equilibriumSymmetryName(EquilibriumSymmetry::Inversion);
    j.erase("equilibrium_seed");
    j.erase("equilibrium_kicks");
    return j;
}

/// Refuses a CampaignOptions::reuseFrom that is not a campaign of the symmetric disc with this
/// campaign's other settings (its sample count aside).
void checkDonor(const CampaignOptions& o) {
    if (o.experiment.equilibriumSymmetry != EquilibriumSymmetry::Lowest)
        throw InputError("--reuse-from: only a campaign of the lowest-energy equilibrium (--equilibrium-symmetry lowest) "
                         "reuses one of the symmetric disc");
    const fs::path json = o.reuseFrom / "campaign.json";
    nlohmann::json donor;
    try {
        std::ifstream in(json);
        if (!in) throw std::runtime_error("cannot open it");
        donor = nlohmann::json::parse(in).at("settings");
    } catch (const std::exception& e) {
        throw InputError(fmt::format("--reuse-from: {}: not a campaign ({})", json.string(), e.what()));
    }
    nlohmann::json want = donorSettings(o);
    want["samples"] = donor.value("samples", nlohmann::json());
    if (donor != want)
        throw InputError(fmt::format("--reuse-from: {} is not this campaign's design with the symmetric disc "
                                     "(equilibrium_symmetry \"inversion\"):{}",
                                     json.string(), settingsDiff(donor, want, "is", "needs")));
}

/// The rows of CampaignOptions::reuseFrom by sample id (none without it), after checkDonor.
std::map<long, CampaignRow> donorRows(const CampaignOptions& o) {
    std::map<long, CampaignRow> rows;
    if (o.reuseFrom.empty()) return rows;
    checkDonor(o);
    for (CampaignRow& r : readCampaignRows(o.reuseFrom)) rows.emplace(r.point.sampleId, std::move(r));
    return rows;
}

/// Groups the design rows by cell (they are contiguous).
std::vector<std::vector<CampaignPoint>> cellsOf(const std::vector<CampaignPoint>& pts) {
    std::vector<std::vector<CampaignPoint>> cells;
    for (const CampaignPoint& q : pts) {
        if (cells.empty() || cells.back().front().cellId != q.cellId) cells.emplace_back();
        cells.back().push_back(q);
    }
    return cells;
}

/// A finished row belongs to the design point of its sample id (rows are written with 17
/// significant digits; sameDesignValue allows for another build's last bits).
bool sameInputs(const CampaignPoint& row, const CampaignPoint& design) {
    const auto same = sameDesignValue;
    return row.cellId == design.cellId && same(row.p.v, design.p.v) && same(row.p.mu, design.p.mu) && same(row.p.FvK, design.p.FvK) &&
           same(row.p.b2, design.p.b2) && same(row.p.etam, design.p.etam) && same(row.fext, design.fext);
}

/// The donor rows of one cell in its order, or none when any is missing or holds other inputs.
std::optional<std::vector<CampaignRow>> donorCell(const std::map<long, CampaignRow>& donor, const std::vector<CampaignPoint>& cell) {
    std::vector<CampaignRow> rows;
    for (const CampaignPoint& q : cell) {
        const auto it = donor.find(q.sampleId);
        if (it == donor.end() || !sameInputs(it->second.point, q)) return std::nullopt;
        rows.push_back(it->second);
    }
    return rows;
}

fs::path equilibriaPart(const CampaignOptions& o, int rank) { return equilibriaDir(o) / fmt::format("rank{}.csv", rank); }
const char* kEquilibriaHeader = "cell_id,branch,energy_gap_J,reused";

std::string formatCellRecord(const CampaignCellRecord& r) {
    return fmt::format("{},{},{:.17g},{}", r.cellId, r.branch.empty() ? "none" : r.branch, r.energyGapJ, r.reused ? 1 : 0);
}

/// The last record of every cell in equilibria/*.csv (a killed run may have written the record of a
/// cell whose rows never landed; that cell's later record replaces it).
std::map<long, CampaignCellRecord> cellRecords(const CampaignOptions& o) {
    std::map<long, CampaignCellRecord> out;
    if (!fs::exists(equilibriaDir(o))) return out;
    std::vector<fs::path> files;
    for (const auto& entry : fs::directory_iterator(equilibriaDir(o)))
        if (entry.path().extension() == ".csv") files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
        std::ifstream in(f);
        std::string line;
        while (std::getline(in, line)) {
            if (line.empty() || line == kEquilibriaHeader) continue;
            std::istringstream ls(line);
            std::string id, branch, gap, reused;
            if (!std::getline(ls, id, ',') || !std::getline(ls, branch, ',') || !std::getline(ls, gap, ',') ||
                !std::getline(ls, reused) || (reused != "0" && reused != "1"))
                continue;  // a torn line of a killed run
            try {
                CampaignCellRecord r;
                r.cellId = std::stol(id);
                r.branch = branch == "none" ? "" : branch;
                r.energyGapJ = gap == "nan" ? NAN : std::stod(gap);
                r.reused = reused == "1";
                out[r.cellId] = r;
            } catch (const std::exception&) {
            }
        }
    }
    return out;
}

/// Rows of the finished cells found in the part files (torn tails and unfinished cells dropped),
/// keyed by sample id. A cell counts only when one file holds all its rows, and is taken whole from
/// the first such file in name order: a run killed mid-write and resumed with other ranks can leave
/// a cell in two files, and its rows must not mix two computations.
std::map<long, CampaignRow> finishedRows(const CampaignOptions& o, const std::vector<std::vector<CampaignPoint>>& cells) {
    std::map<long, CampaignRow> rows;
    if (!fs::exists(partsDir(o))) return rows;
    std::vector<fs::path> parts;
    for (const auto& entry : fs::directory_iterator(partsDir(o)))
        if (entry.path().extension() == ".csv" && fs::file_size(entry.path()) > 0) parts.push_back(entry.path());
    std::sort(parts.begin(), parts.end());
    for (const fs::path& part : parts) {
        std::map<long, CampaignRow> inFile;
        for (CampaignRow& r : readCampaignCsv(part, true)) inFile.emplace(r.point.sampleId, std::move(r));
        for (const auto& cell : cells) {
            if (rows.count(cell.front().sampleId)) continue;
            bool complete = true;
            for (const CampaignPoint& q : cell) {
                const auto it = inFile.find(q.sampleId);
                if (it == inFile.end()) {
                    complete = false;
                } else if (!sameInputs(it->second.point, q)) {
                    throw InputError(fmt::format("{}: sample {} holds inputs other than the design's (v {} against {}, "
                                                 "Fext_pN {} against {}): the part files belong to another design or seed",
                                                 part.string(), q.sampleId, it->second.point.p.v, q.p.v,
                                                 it->second.point.fext, q.fext));
                }
            }
            if (complete)
                for (const CampaignPoint& q : cell) rows.emplace(q.sampleId, std::move(inFile.at(q.sampleId)));
        }
    }
    std::erase_if(rows, [&](const auto& kv) { return kv.first >= o.samples; });
    return rows;
}

/// This rank's part file, holding its finished cells only (PartFile), open for appending.
std::unique_ptr<PartFile> openPartFile(const CampaignOptions& o, int rank, const std::map<long, CampaignRow>& finished) {
    const fs::path part = partPath(o, rank);
    std::string keep;
    if (fs::exists(part) && fs::file_size(part) > 0) {
        for (const CampaignRow& r : readCampaignCsv(part, true))
            if (finished.count(r.point.sampleId)) keep += formatCampaignRow(r) + "\n";
    }
    return std::make_unique<PartFile>(part, campaignCsvHeader(), keep);
}

void markFailed(std::vector<CampaignRow>& rows, const std::string& reason) {
    for (CampaignRow& r : rows)
        if (r.reason.empty()) r.reason = reason;
}

/// Wall time per row and the status: "ok" when all six outputs are finite.
std::vector<CampaignRow> finishCellRows(std::vector<CampaignRow> rows, SteadyClock::time_point t0) {
    const double wall = secondsSince(t0) / double(rows.size());
    for (CampaignRow& r : rows) {
        r.wallSeconds = wall;
        const double out[6] = {r.D, r.hmin, r.hmax, r.D0, r.D1, r.tc};
        const bool finite = std::all_of(out, out + 6, [](double x) { return std::isfinite(x); });
        if (finite) {
            r.status = "ok";
            r.reason.clear();
        } else {
            r.status = "failed";
            if (r.reason.empty()) r.reason = "non-finite output";
        }
    }
    return rows;
}

/// The equilibrium observables of `rows` equal the donor's bit for bit. Together with the branch
/// "symmetric" this identifies the donor's equilibrium shape: the symmetric minimisation is the same
/// computation in both forward models, and a shape that differed in any vertex would move D, hmin
/// or hmax in their last digits.
bool sameEquilibrium(const std::vector<CampaignRow>& donor, const std::vector<CampaignRow>& rows) {
    if (donor.size() != rows.size()) return false;
    for (std::size_t i = 0; i < rows.size(); ++i)
        if (!(donor[i].D == rows[i].D && donor[i].hmin == rows[i].hmin && donor[i].hmax == rows[i].hmax)) return false;
    return true;
}

void takeOverOutputs(const std::vector<CampaignRow>& donor, std::vector<CampaignRow>& rows) {
    for (std::size_t i = 0; i < rows.size(); ++i) {
        rows[i].D0 = donor[i].D0, rows[i].D1 = donor[i].D1, rows[i].tc = donor[i].tc;
        rows[i].reason = donor[i].reason;
    }
}

}  // namespace

std::vector<CampaignRow> runCampaignCell(const std::vector<CampaignPoint>& cell, std::uint64_t seed,
                                         const ExperimentOptions& opt, bool injectFailure,
                                         const std::vector<CampaignRow>* donor, CampaignCellRecord* record) {
    const auto t0 = SteadyClock::now();
    std::vector<CampaignRow> rows(cell.size());
    for (std::size_t i = 0; i < cell.size(); ++i) {
        rows[i].point = cell[i];
        rows[i].seed = seed;
    }
    const CellParameters& p = cell.front().p;
    std::string stage = "stress-free state";
    try {
        const StressFreeState sfs = stressFreeState(p.v, opt.level, opt.cacheDir, opt.sfs);
        const CellMeshes meshes = cellMeshes(sfs, usesSymmetricReference(opt.equilibriumSymmetry));
        stage = "equilibrium";
        if (injectFailure) throw NumericalError("injected failure (--inject-failures)");
        const EquilibriumResult eq = runEquilibrium(p, meshes, opt);
        for (CampaignRow& r : rows) r.D = eq.observables.D, r.hmin = eq.observables.hmin, r.hmax = eq.observables.hmax;
        if (record) record->branch = eq.branch, record->energyGapJ = eq.energyGap / cell::joule;
        if (donor && eq.branch == "symmetric" && sameEquilibrium(*donor, rows)) {
            takeOverOutputs(*donor, rows);
            if (record) record->reused = true;
            return finishCellRows(std::move(rows), t0);
        }

        stage = "stretching";
        std::vector<double> forces;
        for (const CampaignPoint& q : cell) forces.push_back(q.fext);
        try {
            const auto pts = runStretching(p, meshes, eq.shape, forces, opt);  // continuation, ascending
            std::vector<std::size_t> order(cell.size());
            std::iota(order.begin(), order.end(), 0);
            std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return forces[a] < forces[b]; });
            for (std::size_t k = 0; k < order.size(); ++k)
                rows[order[k]].D0 = pts[k].observables.D0, rows[order[k]].D1 = pts[k].observables.D1;
        } catch (const NumericalError&) {
            // The continuation broke somewhere: solve each force from the equilibrium shape.
            for (std::size_t i = 0; i < cell.size(); ++i) {
                try {
                    const auto pt = runStretching(p, meshes, eq.shape, {forces[i]}, opt);
                    rows[i].D0 = pt[0].observables.D0, rows[i].D1 = pt[0].observables.D1;
                } catch (const NumericalError& e) {
                    rows[i].reason = fmt::format("stretching at {:.4g} pN: {}", forces[i], e.what());
                }
            }
        }

        stage = "relaxation";
        try {
            const RelaxationResult rx = runRelaxation(p, meshes, eq.shape, opt);
            for (CampaignRow& r : rows) r.tc = rx.fit.tc;
        } catch (const NumericalError& e) {
            markFailed(rows, fmt::format("relaxation: {}", e.what()));
        }
    } catch (const std::exception& e) {
        markFailed(rows, fmt::format("{}: {}", stage, e.what()));
    }
    return finishCellRows(std::move(rows), t0);
}

void prepareCampaign(const CampaignOptions& o) {
    validateOptions(o);
    if (!o.reuseFrom.empty()) checkDonor(o);  // refuse a wrong donor before anything is written
    std::error_code ec;
    fs::create_directories(partsDir(o), ec);
    if (ec) throw InputError(fmt::format("--out: cannot create {}: {}", partsDir(o).string(), ec.message()));
    const nlohmann::json settings = settingsJson(o);
    if (fs::exists(provenancePath(o))) {
        if (!o.resume)
            throw InputError(fmt::format("--out: {} already holds a campaign; add --resume to continue it or choose "
                                         "another directory",
                                         o.outDir.string()));
        nlohmann::json old;
        try {
            std::ifstream in(provenancePath(o));
            old = nlohmann::json::parse(in);
        } catch (const std::exception& e) {
            throw InputError(fmt::format("{}: cannot parse: {}", provenancePath(o).string(), e.what()));
        }
        const bool grows = old.contains("settings") && canGrow(old["settings"], settings);
        if (!grows && (!old.contains("settings") || old["settings"] != settings)) {
            const nlohmann::json before = old.contains("settings") && old["settings"].is_object() ? old["settings"]
                                                                                                  : nlohmann::json::object();
            std::string diff = settingsDiff(before, settings, "was", "now");
            if (before.contains("samples") && before["samples"] != settings["samples"])
                diff += fmt::format("; only a uniform design whose samples fill whole cells grows (a larger --samples "
                                    "extends it), an lhs design or a smaller --samples cannot");
            throw InputError(fmt::format("--resume: {} was made with different settings:{}", provenancePath(o).string(), diff));
        }
        nlohmann::json j = old;
        nlohmann::json entry = withBuild({{"command", o.command}, {"ranks", o.ranks}, {"threads", o.threads}});
        if (!o.reuseFrom.empty()) entry["reuse_from"] = o.reuseFrom.string();
        if (grows && old["settings"]["samples"] != settings["samples"]) {
            entry["grown_from_samples"] = old["settings"]["samples"];
            j["settings"] = settings;
            j["status"] = "incomplete";
            // samples.csv held the smaller set; the parts hold every row and rebuild it when complete.
            fs::remove(samplesPath(o));
        }
        j["resumed_by"].push_back(entry);
        writeJsonAtomically(provenancePath(o), j);
        return;
    }
    if (fs::exists(samplesPath(o)) || !fs::is_empty(partsDir(o)))
        throw InputError(fmt::format("--out: {} holds campaign files but no campaign.json; choose another directory",
                                     o.outDir.string()));
    nlohmann::json j = withBuild({{"command", o.command},
                                  {"ranks", o.ranks},
                                  {"threads", o.threads},
                                  {"status", "running"},
                                  {"settings", settings},
                                  {"columns", campaignCsvHeader()},
                                  {"units", "um, pN, s; mu in uN/m, etam in Pa s um"},
                                  {"note", "rows of one cell share (v, mu, FvK, b2, etam) and differ in Fext; "
                                           "wall_s is the row's share of its cell's wall time"}});
    if (!o.reuseFrom.empty()) {
        j["reuse_from"] = o.reuseFrom.string();
        j["reuse_note"] = "cells whose equilibrium is the symmetric disc of reuse_from (reused = 1 in equilibria.csv) "
                          "carry its stretching and relaxation outputs and failure reasons; their wall_s is the "
                          "equilibrium search's alone";
    }
    writeJsonAtomically(provenancePath(o), j);
}

CampaignSummary runCampaignShare(const CampaignOptions& o, int rank, int ranks) {
    validateOptions(o);
    if (rank < 0 || rank >= ranks) throw InputError(fmt::format("rank {} is outside [0, {})", rank, ranks));
    const auto t0 = SteadyClock::now();
    const auto cells = cellsOf(campaignDesign(o.design, o.samples, o.forcesPerCell, o.seed));
    const auto finished = finishedRows(o, cells);
    const auto donor = donorRows(o);
    const auto part = openPartFile(o, rank, finished);
    std::error_code ec;
    fs::create_directories(equilibriaDir(o), ec);
    std::ofstream records(equilibriaPart(o, rank), std::ios::app);
    if (ec || !records)
        throw IoError(fmt::format("cannot append to {}: {}", equilibriaPart(o, rank).string(), ec ? ec.message() : std::strerror(errno)));

    std::vector<std::size_t> pending;
    CampaignProgress prog;
    for (std::size_t c = 0; c < cells.size(); ++c) {
        if (long(c) % ranks != rank) continue;
        ++prog.cellsTotal;
        if (finished.count(cells[c].front().sampleId)) {
            ++prog.cellsResumed;
            for (const CampaignPoint& q : cells[c]) (finished.at(q.sampleId).ok() ? prog.rowsOk : prog.rowsFailed)++;
        } else {
            pending.push_back(c);
        }
    }
    prog.cellsDone = prog.cellsResumed;
    if (o.progress) o.progress(prog);

    return runCampaignUnits(pending.size(), o.threads, prog, t0, [&](std::size_t k) {
        const auto& cell = cells[pending[k]];
        const bool inject = std::any_of(cell.begin(), cell.end(), [&](const CampaignPoint& q) { return o.injectFailures.count(q.sampleId); });
        ExperimentOptions experiment = o.experiment;
        if (o.cellTimeLimit > 0)
            experiment.deadline = SteadyClock::now() + std::chrono::duration_cast<SteadyClock::duration>(
                                                     std::chrono::duration<double>(o.cellTimeLimit));
        const auto donated = o.reuseFrom.empty() ? std::nullopt : donorCell(donor, cell);
        CampaignCellRecord record;
        record.cellId = cell.front().cellId;
        const auto rows = runCampaignCell(cell, o.seed, experiment, inject, donated ? &*donated : nullptr, &record);
        CampaignUnit unit;
        std::string block;
        for (const CampaignRow& r : rows) {
            block += formatCampaignRow(r) + "\n";
            (r.ok() ? unit.ok : unit.failed)++;
        }
        unit.commit = [&, block = std::move(block), record] {
            // The record first: a cell counts as done only once its rows are appended.
            records << formatCellRecord(record) << std::endl;
            if (!records)
                throw IoError(fmt::format("cannot append to {}: {}", equilibriaPart(o, rank).string(), std::strerror(errno)));
            part->append(block);
        };
        return unit;
    }, o.progress);
}

CampaignSummary runCampaignUnits(std::size_t n, int threads, CampaignProgress prog, SteadyClock::time_point t0,
                                 const std::function<CampaignUnit(std::size_t)>& work,
                                 const std::function<void(const CampaignProgress&)>& progress) {
    std::string error;
    std::atomic<bool> stop{false};
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (std::size_t k = 0; k < n; ++k) {
        if (stop.load()) continue;
        omp_set_num_threads(1);  // one thread per unit: the loops inside stay serial
        const CampaignUnit unit = work(k);
#pragma omp critical(trbc_campaign_commit)
        {
            try {
                unit.commit();
            } catch (const std::exception& e) {
                if (error.empty()) error = e.what();
                stop = true;
            }
            ++prog.cellsDone;
            prog.rowsOk += unit.ok, prog.rowsFailed += unit.failed;
            prog.elapsedSeconds = secondsSince(t0);
            if (progress) progress(prog);
        }
    }
    if (!error.empty()) throw IoError(error);
    CampaignSummary s;
    s.cellsComputed = long(n);
    s.cellsResumed = prog.cellsResumed;
    s.ok = prog.rowsOk;
    s.failed = prog.rowsFailed;
    s.samples = s.ok + s.failed;
    s.wallSeconds = secondsSince(t0);
    return s;
}

CampaignSummary finalizeCampaign(const CampaignOptions& o, double wallSeconds) {
    const auto pts = campaignDesign(o.design, o.samples, o.forcesPerCell, o.seed);
    const auto rows = finishedRows(o, cellsOf(pts));
    CampaignSummary s;
    s.wallSeconds = wallSeconds;
    for (const auto& [id, r] : rows) (r.ok() ? s.ok : s.failed)++;
    s.samples = long(rows.size());
    s.complete = s.samples == o.samples;
    nlohmann::json j;
    {
        std::ifstream in(provenancePath(o));
        j = nlohmann::json::parse(in);
    }
    if (s.complete) {
        std::string csv = csvProvenance() + campaignCsvHeader() + "\n";
        for (const auto& [id, r] : rows) csv += formatCampaignRow(r) + "\n";
        writeFileAtomically(samplesPath(o), csv);
        j["status"] = "complete";
        // Per finished cell (of those with a record: campaigns made before the records have none).
        const auto records = cellRecords(o);
        std::string eq = csvProvenance() + "cell_id,v,FvK,branch,energy_gap_J,reused\n";
        std::map<std::string, long> branches;
        long reused = 0, lastCell = -1;
        for (const auto& [id, r] : rows) {
            if (r.point.cellId == lastCell) continue;  // rows are sorted, cells contiguous
            lastCell = r.point.cellId;
            const auto it = records.find(r.point.cellId);
            if (it == records.end()) continue;
            const CampaignCellRecord& c = it->second;
            const std::string branch = c.branch.empty() ? "none" : c.branch;
            eq += fmt::format("{},{:.17g},{:.17g},{},{:.17g},{}\n", c.cellId, r.point.p.v, r.point.p.FvK, branch,
                              c.energyGapJ, c.reused ? 1 : 0);
            ++branches[branch];
            reused += c.reused;
        }
        writeFileAtomically(equilibriaPath(o), eq);
        j["equilibrium_branches"] = branches;
        j["cells_reused"] = reused;
    } else {
        j["status"] = "incomplete";
    }
    j["samples_ok"] = s.ok;
    j["samples_failed"] = s.failed;
    j["samples_done"] = s.samples;
    j["last_run_wall_s"] = wallSeconds;
    writeJsonAtomically(provenancePath(o), j);
    return s;
}

std::vector<CampaignRow> readCampaignRows(const fs::path& path, bool* complete) {
    if (complete) *complete = true;
    if (fs::is_regular_file(path)) return readCampaignCsv(path);
    if (!fs::is_directory(path)) throw InputError(fmt::format("campaign data {} does not exist", path.string()));
    if (fs::exists(path / "samples.csv")) return readCampaignCsv(path / "samples.csv");
    if (complete) *complete = false;
    std::vector<CampaignRow> rows;
    if (!fs::exists(path / "parts") || !fs::exists(path / "campaign.json"))
        throw InputError(fmt::format("{} holds neither samples.csv nor the campaign.json and parts/ of a campaign", path.string()));
    // The finished cells of the design recorded in campaign.json.
    CampaignOptions o;
    o.outDir = path;
    try {
        std::ifstream in(provenancePath(o));
        const nlohmann::json j = nlohmann::json::parse(in).at("settings");
        o.design = parseDesignKind(j.at("design").get<std::string>());
        o.samples = j.at("samples").get<long>();
        o.forcesPerCell = j.at("forces_per_cell").get<int>();
        o.seed = j.at("seed").get<std::uint64_t>();
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: cannot read the campaign settings: {}", provenancePath(o).string(), e.what()));
    }
    for (auto& [id, r] : finishedRows(o, cellsOf(campaignDesign(o.design, o.samples, o.forcesPerCell, o.seed))))
        rows.push_back(std::move(r));
    return rows;
}

std::map<long, int> readCampaignBranches(const fs::path& dirOrFile) {
    std::map<long, int> out;
    const fs::path path = dirOrFile / "equilibria.csv";
    if (!fs::is_directory(dirOrFile) || !fs::exists(path)) return out;
    std::ifstream in(path);
    std::string line;
    long lineNo = 1;
    bool header = static_cast<bool>(std::getline(in, line));
    while (header && line.starts_with('#')) header = static_cast<bool>(std::getline(in, line)), ++lineNo;  // the provenance line
    if (!header || line != "cell_id,v,FvK,branch,energy_gap_J,reused")
        throw InputError(fmt::format("{}:{}: expected the header cell_id,v,FvK,branch,energy_gap_J,reused", path.string(), lineNo));
    while (std::getline(in, line)) {
        ++lineNo;
        const std::vector<std::string> f = splitList(line);
        long id = -1;
        try {
            std::size_t used = 0;
            if (f.size() == 6) id = std::stol(f[0], &used);
            if (used != f[0].size()) id = -1;
        } catch (const std::exception&) {
        }
        if (id < 0) throw InputError(fmt::format("{}:{}: expected 6 fields starting with a cell id, got '{}'", path.string(), lineNo, line));
        out[id] = f[3] == "kicked" ? 1 : 0;
    }
    return out;
}

CampaignSummary runCampaign(const CampaignOptions& o) {
    prepareCampaign(o);
    const CampaignSummary share = runCampaignShare(o, 0, 1);
    CampaignSummary s = finalizeCampaign(o, share.wallSeconds);
    s.cellsComputed = share.cellsComputed;
    s.cellsResumed = share.cellsResumed;
    return s;
}

}  // namespace trbc
