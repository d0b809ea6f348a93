#include "core/file_io.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.hpp"

namespace trbc {
namespace {

/// Writes all of `text` to `fd`; the errno of the first failure, or 0.
int writeAll(int fd, std::string_view text) {
    std::size_t off = 0;
    while (off < text.size()) {
        const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
        if (n < 0) {
            if (errno == EINTR) continue;
            return errno;
        }
        off += static_cast<std::size_t>(n);
    }
    return 0;
}

std::atomic<unsigned long> gTemporaries{0};

}  // namespace

void writeFileAtomically(const std::filesystem::path& path, std::string_view text) {
    std::error_code ec;
    const auto kind = std::filesystem::status(path, ec).type();
    if (kind != std::filesystem::file_type::not_found && kind != std::filesystem::file_type::regular &&
        kind != std::filesystem::file_type::none) {
        // A device or a pipe (/dev/stdout, /dev/full) cannot be replaced: written in place, and its
        // errors (a full device) surface at the write and the close.
        const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
        int err = fd < 0 ? errno : writeAll(fd, text);
        if (fd >= 0 && ::close(fd) != 0 && err == 0) err = errno;
        if (err != 0) throw IoError(fmt::format("cannot write {}: {}", path.string(), std::strerror(err)));
        return;
    }
    // PATH.tmp.<pid>.<n>, created exclusively: two writers (threads or processes) never share a temporary.
    std::filesystem::path tmp;
    int fd = -1;
    for (int attempt = 0; fd < 0 && attempt < 1000; ++attempt) {
        tmp = path;
        tmp += fmt::format(".tmp.{}.{}", ::getpid(), gTemporaries++);
        fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
        if (fd < 0 && errno != EEXIST) break;
    }
    if (fd < 0) throw IoError(fmt::format("cannot write {}: {}", path.string(), std::strerror(errno)));
    int err = writeAll(fd, text);
    if (::close(fd) != 0 && err == 0) err = errno;
    if (err != 0) {
        ::unlink(tmp.c_str());
        throw IoError(fmt::format("cannot write {}: {}", path.string(), std::strerror(err)));
    }
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        err = errno;
        ::unlink(tmp.c_str());
        throw IoError(fmt::format("cannot replace {}: {}", path.string(), std::strerror(err)));
    }
}

std::string readFileBytes(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    return bytes.str();
}

std::optional<nlohmann::json> tryReadJson(const std::filesystem::path& path) {
    if (!std::filesystem::is_regular_file(path)) return std::nullopt;
    nlohmann::json j = nlohmann::json::parse(readFileBytes(path), nullptr, false);
    if (j.is_discarded()) return std::nullopt;
    return j;
}

}  // namespace trbc
