#pragma once
// Wall-clock intervals of the drivers and the records they write (wall_s): a monotonic clock, so
// that a clock adjustment during a run does not show up as negative or inflated times.
#include <chrono>

namespace trbc {

using SteadyClock = std::chrono::steady_clock;

/// Seconds elapsed since t0.
inline double secondsSince(SteadyClock::time_point t0) { return std::chrono::duration<double>(SteadyClock::now() - t0).count(); }

}  // namespace trbc
