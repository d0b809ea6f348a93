#pragma once
// The output-directory contract of every command that writes a directory (campaign, infer,
// validate, export, sobol, calibrate):
//  - one writer at a time: an exclusive flock on DIR/.trbc.lock, held while the command runs and
//    released by the kernel when the process ends, however it ends; so a lock file left by a
//    killed run never blocks the next one, and a clean exit removes it;
//  - only its own folders: a folder that holds files is used only when it carries the marker
//    DIR/.trbc-output of the same command (or an earlier output of it, recognised by its files);
//  - a folder made by a run that fails before writing anything is removed again.
// Records inside are written with writeFileAtomically (file_io.hpp).
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace trbc {

/// The lock and marker file names inside an output directory.
inline constexpr const char* kOutputLockName = ".trbc.lock";
inline constexpr const char* kOutputMarkerName = ".trbc-output";

class OutputDirectory {
public:
    /// Creates `dir` if needed, locks it and checks that it is new, empty or an output of
    /// `trbc <command>`. `earlier`: file names that mark an output of the command written before
    /// the marker existed; `inputs`: files of the run itself that may sit in the folder (its
    /// configuration). InputError naming `option`, the folder and, for a lock held elsewhere, the
    /// holder's pid.
    OutputDirectory(const std::filesystem::path& dir, std::string command, std::string option = "--out",
                    const std::vector<std::string>& earlier = {}, const std::vector<std::filesystem::path>& inputs = {});
    ~OutputDirectory();
    OutputDirectory(const OutputDirectory&) = delete;
    OutputDirectory& operator=(const OutputDirectory&) = delete;

    const std::filesystem::path& path() const { return dir_; }

private:
    void lock(const std::string& option);
    void checkContents(const std::string& option, const std::string& shown, const std::vector<std::string>& earlier,
                       const std::vector<std::filesystem::path>& inputs);
    void release();
    std::filesystem::path dir_;
    std::string command_;
    int fd_ = -1;
    bool created_ = false;
    int uncaught_ = 0;
};

/// Checks a name that becomes part of a file name (a data set, a validation case): 1 to 100
/// characters of [A-Za-z0-9_.-], not "." or "..". InputError "<what> '<name>': ..." otherwise.
void checkFileName(std::string_view name, std::string_view what);

/// Throws InputError unless the file's directory exists and is writable (checked before a long run).
void ensureWritableFile(const std::string& path);
/// Creates the directory if needed; throws InputError unless it is writable.
void ensureWritableDirectory(const std::string& dir);

}  // namespace trbc
