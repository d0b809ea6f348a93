#include "sampling/part_file.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/error.hpp"
#include "core/file_io.hpp"

namespace trbc {

PartFile::PartFile(std::filesystem::path path, const std::string& header, const std::string& kept) : path_(std::move(path)) {
    writeFileAtomically(path_, header + "\n" + kept);
    fd_ = ::open(path_.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
    if (fd_ < 0) throw IoError(fmt::format("cannot open {} for appending: {}", path_.string(), std::strerror(errno)));
}

PartFile::~PartFile() {
    if (fd_ >= 0) ::close(fd_);
}

void PartFile::append(const std::string& block) {
    std::size_t off = 0;
    while (off < block.size()) {
        const ssize_t n = ::write(fd_, block.data() + off, block.size() - off);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) throw IoError(fmt::format("cannot append to {}: {}", path_.string(), std::strerror(errno)));
        off += std::size_t(n);
    }
    // EINVAL/EROFS: a file system without fsync (a pipe, a read-only overlay's special files).
    if (::fsync(fd_) != 0 && errno != EINVAL && errno != EROFS)
        throw IoError(fmt::format("cannot append to {}: {}", path_.string(), std::strerror(errno)));
}

}  // namespace trbc
