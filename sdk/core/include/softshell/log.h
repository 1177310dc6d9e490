#pragma once
/// \file
/// \brief Logging: levels, installable sinks and `Logger`. Nothing in softshell writes to
/// stdout/stderr on its own; every message goes to a sink the embedding application chooses.
///
/// Two places take a sink: a `Logger` value that a component is given (the server layers: each
/// service or HTTP listener logs where its owner says), and the process-wide SDK sink
/// (`set_log_sink`) for code that has no owner to ask (failed assertions, internal errors caught at
/// a boundary). Both default to nowhere; `stderr_log_sink()` is the ready-made terminal sink.

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "softshell/result.h"

namespace softshell {

/// Severity, in increasing order; kOff as a threshold disables logging.
enum class LogLevel : uint8_t { kDebug, kInfo, kWarning, kError, kOff };

/// "debug", "info", "warning", "error", "off".
std::string_view to_string(LogLevel level);
/// Parses a level name (as above, case-insensitive; "warn" is accepted); kInvalidArgument otherwise.
Result<LogLevel> parse_log_level(std::string_view name);

/// Receives one complete message (no trailing newline). Called from any thread, possibly
/// concurrently: a sink must be thread-safe.
using LogSink = std::function<void(LogLevel level, std::string_view message)>;

/// A sink that writes `2024-05-01T12:00:00.123Z info  message` lines to stderr, one write per
/// line (lines of concurrent threads do not interleave).
LogSink stderr_log_sink();

/// A threshold and a sink. Copyable; copies share nothing mutable.
/// Thread-safety: `log` may be called concurrently (the sink must allow it).
struct Logger {
  LogLevel level = LogLevel::kInfo;  ///< messages below this level are dropped
  LogSink sink;                      ///< where messages go; empty = nowhere

  bool enabled(LogLevel l) const { return sink && l >= level && level != LogLevel::kOff; }
  void log(LogLevel l, std::string_view message) const {
    if (enabled(l)) sink(l, message);
  }
  void debug(std::string_view m) const { log(LogLevel::kDebug, m); }
  void info(std::string_view m) const { log(LogLevel::kInfo, m); }
  void warning(std::string_view m) const { log(LogLevel::kWarning, m); }
  void error(std::string_view m) const { log(LogLevel::kError, m); }
};

/// Installs the process-wide SDK sink and its threshold (default: no sink). Thread-safe; a
/// message being delivered while the sink is replaced goes to the old or the new one.
void set_log_sink(LogSink sink, LogLevel threshold = LogLevel::kWarning);

/// The process-wide SDK logger (a copy of what `set_log_sink` installed).
Logger sdk_logger();

}  // namespace softshell
