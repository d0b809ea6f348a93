#pragma once
// The library's messages (a rejected cache entry, a cache that cannot be written) go to one
// settable sink instead of a stream, so that a program embedding the library decides where they
// appear. The default sink writes "trbc: <message>" to stderr.
#include <functional>
#include <string>

namespace trbc {

enum class LogLevel { Info, Warning };

using LogSink = std::function<void(LogLevel level, const std::string& message)>;

/// Replaces the sink and returns the previous one; an empty function restores the default. The
/// sink is called under a lock, one message at a time, from whichever thread logs.
LogSink setLogSink(LogSink sink);

/// Hands `message` (one line, no trailing newline) to the sink.
void logMessage(LogLevel level, const std::string& message);

}  // namespace trbc
