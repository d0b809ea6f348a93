#pragma once
// Child processes of the long-running drivers (`trbc validate`, `trbc calibrate`).
//
// Each child runs `/bin/sh -c COMMAND` as the leader of its own process group. The driver, once
// forwardSignalsToChildren() has run, passes SIGINT, SIGTERM and SIGHUP on to every running
// child's group and then dies of the same signal, so that a `kill` of the driver (a batch
// scheduler, a closed terminal) leaves no orphaned solver writing into the output directory. What
// the children finished is on disk (atomic records); the next run resumes from it.
#include <filesystem>
#include <string>

namespace trbc {

/// The variable that tells a trbc child the driver's pid (dieWithParent).
inline constexpr const char* kParentPidVariable = "TRBC_PARENT_PID";

/// Runs `/bin/sh -c command` and waits for it: the exit status as std::system returns it. The
/// shell gets SIGKILL when the driver dies, however it dies (PR_SET_PDEATHSIG), and
/// TRBC_PARENT_PID in its environment.
int runChildProcess(const std::string& command);

/// In a trbc started by runChildProcess (TRBC_PARENT_PID set): die by SIGKILL with the parent
/// process, and exit at once if the driver is gone already. Nothing otherwise. Called first in main().
void dieWithParent();

/// The exit code of a std::system-style status: the child's exit code, 128 + signal if it was
/// killed, -1 if it could not be started.
int childExitCode(int status);

/// Installs the forwarding handlers (idempotent).
void forwardSignalsToChildren();
/// The signal being forwarded (the driver is about to die of it), or 0. A child that ends while it
/// is set was interrupted and must not be recorded as a result.
int forwardedSignal();

}  // namespace trbc
