#pragma once
// The append-only checkpoint of one rank of a campaign (parts/rank<r>.csv): rows are appended in
// blocks, one write() and one fsync per block, so a kill at any moment (SIGKILL included) leaves
// each block whole, torn at its end, or absent. On open, the file is rewritten atomically with the
// rows the caller keeps (its finished, whole records), so new rows never follow a torn line.
#include <filesystem>
#include <string>

namespace trbc {

class PartFile {
public:
    /// Writes `header` + "\n" + `kept` (whole lines, each ending in "\n") to `path` atomically, then
    /// opens it for appending. IoError naming the file and the system's reason.
    PartFile(std::filesystem::path path, const std::string& header, const std::string& kept);
    ~PartFile();
    PartFile(const PartFile&) = delete;
    PartFile& operator=(const PartFile&) = delete;

    /// Appends `block` (whole lines) with one write() (retried on EINTR and short writes) and fsync.
    void append(const std::string& block);
    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
    int fd_ = -1;
};

}  // namespace trbc
