#pragma once
// Errors that reach the user. Every message names the offending file/line, parameter or key
// and, where it applies, the valid range; the CLI prints it and exits non-zero.
#include <stdexcept>
#include <string>

namespace trbc {

/// Bad user input: malformed file, parameter out of range, missing file.
class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// A numerical procedure that did not reach its goal (no convergence, NaN state).
class NumericalError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// The operating system refused a read or a write (disk full, no permission, file system gone):
/// not a property of the input nor of the numerics, so never recorded as a result. Exit 5, with
/// the system's message (strerror).
class IoError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

}  // namespace trbc
