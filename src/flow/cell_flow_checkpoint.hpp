#pragma once
// Snapshots of the BDF2 integrator of flow/cell_flow.cpp (CellFlowOptions::checkpoint): the state
// the next step reads (the last three states, the tension, the step history)
// and the result so far. Binary with native doubles, so a resumed run continues bit for bit (a
// snapshot is read back by the same build on the same machine); written whole by
// writeFileAtomically with an FNV-1a checksum of the payload, so a kill at any moment leaves the
// previous snapshot intact and a damaged file is detected, never half-read.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "flow/cell_flow.hpp"
#include "solvers/bdf2.hpp"

namespace trbc {

/// What the next BDF2 step of integrateCellFlow reads: the integrator works on this struct, so a
/// snapshot holds it whole.
struct CellFlowState {
    bdf2::History steps;            ///< the last three states and the steps between them
    double tension = 0.0;           ///< area multiplier of the last accepted step
    double t = 0.0;                 ///< time of steps.X
    double dt = 0.0;                ///< the step to ask for next
    std::uint64_t nextFrame = 0;    ///< index of the next frame time
    std::uint64_t framesChecked = 0;  ///< frames the stop criterion has seen
};

struct CellFlowSnapshot {
    CellFlowState state;
    std::vector<double> environmentRecords;  ///< FlowEnvironment::records()
    CellFlowResult result;                   ///< so far; completed = true in the snapshot of a finished run
};

/// Writes the snapshot to `file` atomically, tagged with `fingerprint` (the run it belongs to).
void writeCellFlowSnapshot(const std::filesystem::path& file, const CellFlowSnapshot& s, std::uint64_t fingerprint);

/// The snapshot in `file` if it is intact and tagged with `fingerprint`; otherwise nullopt and
/// `why` says what was found (missing, damaged, another run).
std::optional<CellFlowSnapshot> readCellFlowSnapshot(const std::filesystem::path& file, std::uint64_t fingerprint,
                                                     std::string& why);

}  // namespace trbc
