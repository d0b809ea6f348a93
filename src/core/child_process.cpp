#include "core/child_process.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <vector>

#include "core/error.hpp"

extern char** environ;

namespace trbc {
namespace {

// Running children (process-group leaders); 0 = free slot. Lock-free so that the signal handler
// can read it.
constexpr std::size_t kSlots = 256;
std::array<std::atomic<pid_t>, kSlots> gChildren{};

std::size_t registerChild(pid_t pid) {
    for (std::size_t i = 0; i < kSlots; ++i) {
        pid_t expected = 0;
        if (gChildren[i].compare_exchange_strong(expected, pid)) return i;
    }
    return kSlots;  // more than kSlots at once: this one is not forwarded to
}

std::atomic<int> gForwardedSignal{0};

extern "C" void forwardAndDie(int sig) {
    gForwardedSignal.store(sig);
    for (std::atomic<pid_t>& slot : gChildren) {
        const pid_t pid = slot.load();
        if (pid > 0) ::kill(-pid, sig);
    }
    ::signal(sig, SIG_DFL);
    ::raise(sig);
}

}  // namespace

int forwardedSignal() { return gForwardedSignal.load(); }

int childExitCode(int status) {
    if (status == -1) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

int runChildProcess(const std::string& command) {
    // Everything the child needs is made before fork(): between fork and exec it calls only
    // async-signal-safe functions.
    std::string sh = "sh", dashC = "-c", cmd = command;
    char* argv[] = {sh.data(), dashC.data(), cmd.data(), nullptr};
    const pid_t parent = ::getpid();
    std::vector<std::string> env;
    for (char** e = environ; *e != nullptr; ++e)
        if (std::strncmp(*e, kParentPidVariable, std::strlen(kParentPidVariable)) != 0 ||
            (*e)[std::strlen(kParentPidVariable)] != '=')
            env.emplace_back(*e);
    env.push_back(fmt::format("{}={}", kParentPidVariable, parent));
    std::vector<char*> envp;
    for (std::string& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        // The shell dies with this process (SIGKILL included): PR_SET_PDEATHSIG, then a check that
        // the parent did not die before it was set. The trbc it starts does the same
        // (dieWithParent), so no solver outlives the driver.
        ::prctl(PR_SET_PDEATHSIG, SIGKILL);
        if (::getppid() != parent) ::_exit(137);
        ::setpgid(0, 0);  // its own group: kill(-pid) reaches sh and what it starts
        for (int s : {SIGINT, SIGTERM, SIGHUP}) ::signal(s, SIG_DFL);
        sigset_t none;
        sigemptyset(&none);
        ::sigprocmask(SIG_SETMASK, &none, nullptr);
        ::execve("/bin/sh", argv, envp.data());
        ::_exit(127);
    }
    ::setpgid(pid, pid);  // also here, so that kill(-pid) works before the child has run
    const std::size_t slot = registerChild(pid);
    int status = 0;
    pid_t r;
    do r = ::waitpid(pid, &status, 0);
    while (r == -1 && errno == EINTR);
    if (slot < kSlots) gChildren[slot].store(0);
    return r == pid ? status : -1;
}

namespace {

/// The parent pid and state letter of a process from /proc/PID/stat ("pid (comm) S ppid ...");
/// false when it is gone. A zombie (state Z) has died and is only waiting to be reaped.
bool processStat(pid_t pid, char& state, pid_t& parent) {
    char path[64];
    std::snprintf(path, sizeof path, "/proc/%d/stat", static_cast<int>(pid));
    std::FILE* f = std::fopen(path, "r");
    if (f == nullptr) return false;
    char buf[512] = {};
    const std::size_t n = std::fread(buf, 1, sizeof buf - 1, f);
    std::fclose(f);
    const char* close = std::strrchr(buf, ')');  // comm may hold spaces and parentheses
    if (n == 0 || close == nullptr) return false;
    int ppid = 0;
    if (std::sscanf(close + 1, " %c %d", &state, &ppid) != 2) return false;
    parent = static_cast<pid_t>(ppid);
    return true;
}

bool running(pid_t pid) {
    char state = 0;
    pid_t parent = 0;
    return processStat(pid, state, parent) && state != 'Z' && state != 'X';
}

}  // namespace

void dieWithParent() {
    const char* value = std::getenv(kParentPidVariable);
    if (value == nullptr) return;
    const pid_t driver = static_cast<pid_t>(std::strtol(value, nullptr, 10));
    ::unsetenv(kParentPidVariable);
    // The parent here is the driver or the shell it started; the shell dies with the driver
    // (runChildProcess), and this process with its parent from now on. Whatever died before this
    // point is caught below: a parent that is no longer the driver or the driver's shell (this
    // process was re-parented), or a driver that has died (a zombie not yet reaped counts as dead).
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (driver <= 0) return;
    const pid_t parent = ::getppid();
    if (parent != driver) {
        char state = 0;
        pid_t grandparent = 0;
        if (!processStat(parent, state, grandparent) || grandparent != driver) ::_exit(137);
    }
    if (!running(driver)) ::_exit(137);
}

void forwardSignalsToChildren() {
    static std::once_flag once;
    std::call_once(once, [] {
        struct sigaction sa {};
        sa.sa_handler = forwardAndDie;
        sigemptyset(&sa.sa_mask);
        for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaction(s, &sa, nullptr);
    });
}

}  // namespace trbc
