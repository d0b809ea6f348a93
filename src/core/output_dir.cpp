#include "core/output_dir.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <exception>

#include "core/error.hpp"
#include "core/file_io.hpp"

namespace fs = std::filesystem;

namespace trbc {

OutputDirectory::OutputDirectory(const fs::path& dir, std::string command, std::string option, const std::vector<std::string>& earlier,
                                 const std::vector<fs::path>& inputs)
    : dir_(fs::absolute(dir).lexically_normal()), command_(std::move(command)), uncaught_(std::uncaught_exceptions()) {
    std::error_code ec;
    if (fs::exists(dir_, ec) && !fs::is_directory(dir_, ec))
        throw InputError(fmt::format("{} {}: not a directory", option, dir.string()));
    created_ = !fs::exists(dir_, ec);
    fs::create_directories(dir_, ec);
    if (ec) throw InputError(fmt::format("{} {}: cannot create the directory: {}", option, dir.string(), ec.message()));
    lock(option);
    try {
        checkContents(option, dir.string(), earlier, inputs);
    } catch (...) {
        release();  // a throwing constructor runs no destructor
        throw;
    }
}

void OutputDirectory::release() {
    if (fd_ < 0) return;
    ::unlink((dir_ / kOutputLockName).c_str());  // while still held: see lock()
    ::close(fd_);
    fd_ = -1;
}

void OutputDirectory::checkContents(const std::string& option, const std::string& shown, const std::vector<std::string>& earlier,
                                    const std::vector<fs::path>& inputs) {
    std::error_code ec;
    const fs::path marker = dir_ / kOutputMarkerName;
    const std::string mine = "trbc " + command_ + "\n";
    if (fs::exists(marker)) {
        const std::string theirs = readFileBytes(marker);
        if (theirs == mine) return;
        if (theirs.rfind("trbc ", 0) == 0)  // another command's output
            throw InputError(fmt::format("{} {}: the directory holds the output of `{}`, not of `trbc {}`; choose a new or empty "
                                         "directory",
                                         option, shown, theirs.substr(0, theirs.find('\n')), command_));
    }
    bool recognised = false;
    for (const std::string& name : earlier) recognised = recognised || fs::exists(dir_ / name);
    if (!recognised)
        for (const auto& e : fs::directory_iterator(dir_)) {
            const std::string name = e.path().filename().string();
            if (name == kOutputLockName || name == kOutputMarkerName) continue;
            bool input = false;
            for (const fs::path& in : inputs) input = input || fs::equivalent(e.path(), in, ec);
            if (input) continue;
            throw InputError(fmt::format("{} {}: the directory holds files ({}, ...) that `trbc {}` did not write (no {}); "
                                         "choose a new or empty directory",
                                         option, shown, name, command_, kOutputMarkerName));
        }
    writeFileAtomically(marker, mine);
}

void OutputDirectory::lock(const std::string& option) {
    const fs::path file = dir_ / kOutputLockName;
    // The lock file is removed by its holder on exit. A run that opened the file just before
    // then holds a lock on an unlinked inode: it checks that the path still names the inode it
    // locked, and otherwise tries again on the new file.
    for (int attempt = 0; attempt < 100; ++attempt) {
        fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        if (fd_ < 0)
            throw InputError(fmt::format("{} {}: cannot open the lock file {}: {}", option, dir_.string(), file.string(),
                                         std::strerror(errno)));
        if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
            const int err = errno;
            char buf[32] = {};
            const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
            ::close(fd_);
            fd_ = -1;
            if (err != EWOULDBLOCK)
                throw InputError(fmt::format("{} {}: cannot lock {}: {}", option, dir_.string(), file.string(), std::strerror(err)));
            throw InputError(fmt::format("{} {}: another trbc process (pid {}) is writing into this directory; wait for it to "
                                         "finish or choose another directory",
                                         option, dir_.string(), n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : "?"));
        }
        struct stat held {}, named {};
        if (::fstat(fd_, &held) == 0 && ::stat(file.c_str(), &named) == 0 && held.st_ino == named.st_ino &&
            held.st_dev == named.st_dev) {
            const std::string pid = std::to_string(::getpid());
            if (::ftruncate(fd_, 0) == 0 && ::pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
                // the pid is only informative
            }
            return;
        }
        ::close(fd_);
        fd_ = -1;
    }
    throw InputError(fmt::format("{} {}: cannot lock {}: it keeps being replaced", option, dir_.string(), file.string()));
}

OutputDirectory::~OutputDirectory() {
    std::error_code ec;
    if (created_ && std::uncaught_exceptions() > uncaught_) {
        // A failed first run leaves no folder behind, unless it wrote a file in it.
        bool empty = true;
        for (auto it = fs::recursive_directory_iterator(dir_, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
            const std::string name = it->path().filename().string();
            const bool ours = it.depth() == 0 && (name == kOutputLockName || name == kOutputMarkerName);
            empty = empty && (ours || it->is_directory(ec));
        }
        if (empty && !ec) {
            ::unlink((dir_ / kOutputLockName).c_str());  // while still held: see lock()
            fs::remove_all(dir_, ec);
        }
    }
    release();
}

void checkFileName(std::string_view name, std::string_view what) {
    constexpr std::size_t kMax = 100;
    const auto shown = [&] {
        std::string s;
        for (char ch : name.substr(0, 40)) s += (ch >= 32 && ch < 127) ? ch : '?';
        return name.size() > 40 ? s + "..." : s;
    };
    if (name.empty()) throw InputError(fmt::format("{}: the name is empty (1 to {} characters of A-Z a-z 0-9 _ . -)", what, kMax));
    if (name.size() > kMax)
        throw InputError(fmt::format("{} '{}': {} characters, at most {} (A-Z a-z 0-9 _ . -)", what, shown(), name.size(), kMax));
    if (name == "." || name == "..") throw InputError(fmt::format("{} '{}': not a valid name ('.' and '..' name directories)", what, name));
    for (char ch : name)
        if (!((ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z') || (ch >= '0' && ch <= '9') || ch == '_' || ch == '.' || ch == '-'))
            throw InputError(fmt::format("{} '{}': the character {} is not allowed (only A-Z a-z 0-9 _ . -, at most {} characters)",
                                         what, shown(), (ch >= 32 && ch < 127) ? fmt::format("'{}'", ch) : fmt::format("0x{:02x}", (unsigned char)ch),
                                         kMax));
}

void ensureWritableFile(const std::string& path) {
    std::filesystem::path dir = std::filesystem::path(path).parent_path();
    if (dir.empty()) dir = ".";
    if (!std::filesystem::is_directory(dir))
        throw InputError(fmt::format("cannot write {}: directory {} does not exist", path, dir.string()));
    if (::access(dir.c_str(), W_OK) != 0)
        throw InputError(fmt::format("cannot write {}: directory {} is not writable", path, dir.string()));
    if (std::filesystem::is_directory(path)) throw InputError(fmt::format("cannot write {}: it is a directory", path));
}

void ensureWritableDirectory(const std::string& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (!std::filesystem::is_directory(dir))
        throw InputError(fmt::format("cannot create the output directory {}{}", dir, ec ? ": " + ec.message() : ""));
    if (::access(dir.c_str(), W_OK) != 0) throw InputError(fmt::format("output directory {} is not writable", dir));
}

}  // namespace trbc
