#include "core/log.hpp"

#include <iostream>
#include <mutex>

namespace trbc {
namespace {

void writeToStderr(LogLevel, const std::string& message) { std::cerr << "trbc: " + message + "\n"; }

// One lock for the sink and its calls: messages from OpenMP threads neither interleave nor race a
// replacement of the sink.
std::mutex& sinkMutex() {
    static std::mutex m;
    return m;
}

LogSink& currentSink() {
    static LogSink sink = writeToStderr;
    return sink;
}

}  // namespace

LogSink setLogSink(LogSink sink) {
    std::lock_guard<std::mutex> lock(sinkMutex());
    LogSink previous = std::move(currentSink());
    currentSink() = sink ? std::move(sink) : LogSink(writeToStderr);
    return previous;
}

void logMessage(LogLevel level, const std::string& message) {
    std::lock_guard<std::mutex> lock(sinkMutex());
    currentSink()(level, message);
}

}  // namespace trbc
