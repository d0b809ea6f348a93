// A full disk on demand, for the fault-injection tests: loaded with LD_PRELOAD, it makes write(),
// writev() and pwrite() fail with ENOSPC on every file whose path starts with $TRBC_ENOSPC_DIR,
// once the process has written $TRBC_ENOSPC_AFTER bytes (default 0) to such files. Other files
// (the terminal, pipes, other folders) are written as usual.
#include <dlfcn.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace {

std::atomic<long> gWritten{0};

/// True when this write of n bytes to fd must fail.
bool full(int fd, std::size_t n) {
    const char* dir = std::getenv("TRBC_ENOSPC_DIR");
    if (dir == nullptr || *dir == '\0') return false;
    char link[64], path[4096];
    std::snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    const ssize_t k = ::readlink(link, path, sizeof path - 1);
    if (k <= 0) return false;
    path[k] = '\0';
    if (std::strncmp(path, dir, std::strlen(dir)) != 0) return false;
    const char* after = std::getenv("TRBC_ENOSPC_AFTER");
    const long limit = after != nullptr ? std::atol(after) : 0;
    if (gWritten.load() + static_cast<long>(n) > limit) return true;
    gWritten += static_cast<long>(n);
    return false;
}

template <class F>
F real(const char* name) {
    return reinterpret_cast<F>(::dlsym(RTLD_NEXT, name));
}

}  // namespace

extern "C" ssize_t write(int fd, const void* buf, size_t n) {
    static const auto next = real<ssize_t (*)(int, const void*, size_t)>("write");
    if (n > 0 && full(fd, n)) {
        errno = ENOSPC;
        return -1;
    }
    return next(fd, buf, n);
}

extern "C" ssize_t writev(int fd, const struct iovec* iov, int count) {
    static const auto next = real<ssize_t (*)(int, const struct iovec*, int)>("writev");
    std::size_t n = 0;
    for (int i = 0; i < count; ++i) n += iov[i].iov_len;
    if (n > 0 && full(fd, n)) {
        errno = ENOSPC;
        return -1;
    }
    return next(fd, iov, count);
}

extern "C" ssize_t pwrite(int fd, const void* buf, size_t n, off_t offset) {
    static const auto next = real<ssize_t (*)(int, const void*, size_t, off_t)>("pwrite");
    if (n > 0 && full(fd, n)) {
        errno = ENOSPC;
        return -1;
    }
    return next(fd, buf, n, offset);
}
