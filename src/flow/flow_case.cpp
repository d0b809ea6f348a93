#include "flow/flow_case.hpp"

#include <fmt/format.h>
#include <omp.h>

#include <cmath>

#include "core/hash.hpp"
#include "core/error.hpp"

namespace trbc {

std::string optionName(const OptionNamer& namer, const std::string& name) { return namer ? namer(name) : name; }

void requireOptionRange(const OptionNamer& namer, const std::string& name, double x, const OptionRange& range) {
    if (std::isfinite(x) && (range.loOpen ? x > range.lo : x >= range.lo) && x <= range.hi) return;
    const std::string unit = range.unit.empty() ? std::string() : fmt::format(" {}", range.unit);
    throw InputError(fmt::format("parameter {} = {}{}: out of range (valid: {}{:g}, {:g}]{})", optionName(namer, name), x,
                                 unit, range.loOpen ? "(" : "[", range.lo, range.hi, unit));
}

void validateStepping(const FlowCaseStepping& s, std::string_view timeUnit) {
    const OptionNamer& n = s.optionName;
    requireOptionRange(n, "frame_interval", s.frameInterval, {0.0, 1e6, true, timeUnit});
    requireOptionRange(n, "step_tol", s.stepTolerance, {0.0, 1.0, true, "R_A"});
    if (!(s.gmresTolerance >= 0.0 && s.gmresTolerance < 1.0))
        throw InputError(fmt::format("parameter {} = {}: out of range (valid: [0, 1), 0: automatic)",
                                     optionName(n, "gmres_tol"), s.gmresTolerance));
    if (s.dt != 0.0) requireOptionRange(n, "dt", s.dt, {0.0, 100.0, true, timeUnit});
    requireOptionRange(n, "max_steps", s.maxSteps, {1.0, 1e8, false, ""});
    requireOptionRange(n, "checkpoint_interval", s.checkpointInterval, {0.0, 1e7, false, "s"});
    if (s.resume && s.checkpointDirectory.empty())
        throw InputError(fmt::format("option {}: continues from the snapshots of a checkpoint directory; give one",
                                     optionName(n, "resume")));
}

CellFlowOptions stageOptions(const FlowCaseStepping& s, double tEnd, double dtMax) {
    CellFlowOptions opt;
    opt.tEnd = tEnd;
    opt.frameInterval = s.frameInterval;
    opt.errorTolerance = s.stepTolerance;
    opt.gmresTolerance = s.gmresTolerance;
    opt.maxSteps = s.maxSteps;
    if (dtMax > 0.0) opt.dtMax = dtMax;
    if (s.dt > 0.0) {
        opt.adaptive = false;
        opt.dtInitial = s.dt;
        opt.dtMax = s.dt;
    }
    return opt;
}

CellFlowCheckpoint stageCheckpoint(const FlowCaseStepping& s, const std::string& stage, const std::string& caseKey) {
    CellFlowCheckpoint c;
    if (s.checkpointDirectory.empty()) return c;
    static const std::string build = fileFingerprint("/proc/self/exe");
    c.file = s.checkpointDirectory / (stage + ".bin");
    c.intervalSeconds = s.checkpointInterval;
    c.resume = s.resume;
    c.key = fmt::format("{}|{}|build {}|threads {}", stage, caseKey, build, omp_get_max_threads());
    c.log = s.checkpointLog;
    return c;
}

CellFlowObserver stageObserver(const FlowCaseStepping& s, std::string_view stage, double tEnd, double lengthUm,
                               std::chrono::steady_clock::time_point start) {
    if (!s.progress) return {};
    return [progress = s.progress, stage, tEnd, lengthUm, start](double t, const Vertices& X) {
        const Vertices shapeUm = X * lengthUm;
        progress(FlowCaseProgress{stage, t, tEnd, shapeUm, secondsSince(start)});
    };
}

double secondsSince(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace trbc
