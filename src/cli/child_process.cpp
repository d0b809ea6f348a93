#include "cli/child_process.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <mutex>

#include "core/error.hpp"

extern char** environ;

namespace trbc::cli {
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
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    posix_spawnattr_setpgroup(&attr, 0);  // its own group: kill(-pid) reaches sh and what it starts
    sigset_t defaults;
    sigemptyset(&defaults);
    for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&defaults, s);
    posix_spawnattr_setsigdefault(&attr, &defaults);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGDEF);
    std::string sh = "sh", dashC = "-c", cmd = command;
    char* argv[] = {sh.data(), dashC.data(), cmd.data(), nullptr};
    pid_t pid = 0;
    const int err = posix_spawn(&pid, "/bin/sh", nullptr, &attr, argv, environ);
    posix_spawnattr_destroy(&attr);
    if (err != 0) return -1;
    const std::size_t slot = registerChild(pid);
    int status = 0;
    pid_t r;
    do r = ::waitpid(pid, &status, 0);
    while (r == -1 && errno == EINTR);
    if (slot < kSlots) gChildren[slot].store(0);
    return r == pid ? status : -1;
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

DirectoryLock::DirectoryLock(const std::filesystem::path& dir, const std::string& name, const std::string& what) {
    const std::filesystem::path file = dir / name;
    fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) throw InputError(fmt::format("{}: cannot open the lock file {}: {}", what, file.string(), std::strerror(errno)));
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
        char buf[32] = {};
        const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
        ::close(fd_);
        fd_ = -1;
        throw InputError(fmt::format("{}: another process (pid {}) is working in {} (lock {}); wait for it to finish or use "
                                     "another output directory",
                                     what, n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string("?"),
                                     dir.string(), file.string()));
    }
    const std::string pid = std::to_string(::getpid());
    if (::ftruncate(fd_, 0) == 0 && ::pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
        // the pid is only informative
    }
}

DirectoryLock::~DirectoryLock() {
    if (fd_ >= 0) ::close(fd_);  // releases the flock
}

}  // namespace trbc::cli
