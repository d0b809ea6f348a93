#pragma once
// Child processes of the long-running drivers (`trbc validate`, `trbc calibrate`) and the lock of
// their output directory.
//
// Each child runs `/bin/sh -c COMMAND` as the leader of its own process group. The driver, once
// forwardSignalsToChildren() has run, passes SIGINT, SIGTERM and SIGHUP on to every running
// child's group and then dies of the same signal, so that a `kill` of the driver (a batch
// scheduler, a closed terminal) leaves no orphaned solver writing into the output directory. What
// the children finished is on disk (atomic records); the next run resumes from it.
#include <filesystem>
#include <string>

namespace trbc::cli {

/// Runs `/bin/sh -c command` and waits for it: the exit status as std::system returns it.
int runChildProcess(const std::string& command);

/// The exit code of a std::system-style status: the child's exit code, 128 + signal if it was
/// killed, -1 if it could not be started.
int childExitCode(int status);

/// Installs the forwarding handlers (idempotent).
void forwardSignalsToChildren();
/// The signal being forwarded (the driver is about to die of it), or 0. A child that ends while it
/// is set was interrupted and must not be recorded as a result.
int forwardedSignal();

/// An exclusive advisory lock (flock) on DIR/NAME, held until destruction or process exit. Throws
/// InputError naming the directory and the holder's pid if another process holds it.
class DirectoryLock {
public:
    DirectoryLock(const std::filesystem::path& dir, const std::string& name, const std::string& what);
    ~DirectoryLock();
    DirectoryLock(const DirectoryLock&) = delete;
    DirectoryLock& operator=(const DirectoryLock&) = delete;

private:
    int fd_ = -1;
};

}  // namespace trbc::cli
