// One-line structured logs on stderr, in logfmt: `ts=2026-11-21T10:34:12.345Z level=info
// event=serving source="synthetic 640x480" listen=127.0.0.1:50051`. Thread-safe: whole lines,
// never interleaved.
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stevi::server {

enum class LogLevel { kDebug, kInfo, kWarning, kError };

using LogFields = std::vector<std::pair<std::string_view, std::string>>;

// The line as written (without the time stamp), for tests: level=... event=... key=value ...
// Values with spaces, quotes or '=' are quoted, with " and \ escaped; newlines become \n.
std::string FormatLogFields(LogLevel level, std::string_view event, const LogFields& fields);

// Writes ts=... then FormatLogFields(...) and a newline to stderr, at once.
void Log(LogLevel level, std::string_view event, const LogFields& fields = {});

}  // namespace stevi::server
