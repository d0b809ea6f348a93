#pragma once
// What the flow cases of flow/shear_case.hpp and flow/tube_case.hpp share: the options of the
// time stepping and the snapshots, the progress reports, the names of the options in the
// messages, and the stage set-up built from them (docs/FLOW.md).
#include <chrono>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>

#include "flow/cell_flow.hpp"

namespace trbc {

/// Reported at t = 0 and at every frame of each stage.
struct FlowCaseProgress {
    std::string_view stage;  ///< "settling" (the tube's first stage) or "main"
    double t, tEnd;          ///< in the case's time unit: 1/rate (shear), R/V (tube)
    const Vertices& shapeUm; ///< the cell now, um
    double wallSeconds;      ///< since the case began
};

/// The name of an option in the messages of InputError. The library names the options as the
/// JSON outputs and the Python binding do (radius_um, settle_R_over_V); `trbc flow` maps these
/// names to its command-line options (--radius, --settle).
using OptionNamer = std::function<std::string(const std::string& name)>;

/// Time stepping, snapshots and reports of a flow case; times in the case's time unit.
struct FlowCaseStepping {
    double frameInterval = 0.1;   ///< frames at k frameInterval (interpolated)
    double stepTolerance = 1e-3;  ///< local error per step, largest vertex displacement, R_A
    double gmresTolerance = 0.0;  ///< relative residual of each step's solve; 0: automatic (effectiveGmresTolerance)
    double dt = 0.0;              ///< > 0: fixed steps of dt, no step control
    int maxSteps = 200000;        ///< time-step attempts per stage; the stage fails beyond it
    /// Snapshots of each stage in checkpointDirectory/STAGE.bin (docs/FLOW.md "Checkpoints");
    /// empty: none. The caller removes the directory once it has written what the case gives.
    std::filesystem::path checkpointDirectory;
    double checkpointInterval = 60.0;  ///< wall seconds between snapshots (0: after every step)
    bool resume = false;               ///< continue from the snapshots (needs checkpointDirectory)
    std::function<void(const FlowCaseProgress&)> progress;
    std::function<void(const std::string&)> checkpointLog;  ///< a snapshot resumed, or why not
    OptionNamer optionName;  ///< empty: the library's names
};

/// `name` as the caller calls it (FlowCaseStepping::optionName).
std::string optionName(const OptionNamer& namer, const std::string& name);

/// The valid values of a numeric option: lo < x (loOpen) or lo <= x, and x <= hi.
struct OptionRange {
    double lo, hi;
    bool loOpen;
    std::string_view unit;
};
/// Throws InputError "parameter NAME = X UNIT: out of range (valid: (lo, hi] UNIT)" unless x is
/// finite and inside the range.
void requireOptionRange(const OptionNamer& namer, const std::string& name, double x, const OptionRange& range);

/// Checks the ranges of `trbc flow`'s stepping options (frame_interval, step_tol, dt, max_steps,
/// checkpoint_interval; resume needs a checkpoint directory); `timeUnit` names the case's unit.
void validateStepping(const FlowCaseStepping& s, std::string_view timeUnit);

/// The integrator options of one stage lasting tEnd (a fixed dt switches the step control off;
/// dtMax > 0 caps the adaptive step).
CellFlowOptions stageOptions(const FlowCaseStepping& s, double tEnd, double dtMax);

/// Snapshots of one stage (none without a checkpoint directory). The key holds what the
/// integrator cannot see: the stage, the case's parameters (`caseKey`), the binary itself (its
/// bytes: another build may step differently) and the thread count (the tube wall's blocked LU
/// depends on it).
CellFlowCheckpoint stageCheckpoint(const FlowCaseStepping& s, const std::string& stage, const std::string& caseKey);

/// The observer of one stage: FlowCaseProgress to s.progress (none without one); lengthUm
/// converts the internal shape to um, `start` is the case's start.
CellFlowObserver stageObserver(const FlowCaseStepping& s, std::string_view stage, double tEnd, double lengthUm,
                               std::chrono::steady_clock::time_point start);

/// Seconds since `start`.
double secondsSince(std::chrono::steady_clock::time_point start);

}  // namespace trbc
