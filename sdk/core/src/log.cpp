#include "softshell/log.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <mutex>

namespace softshell {

std::string_view to_string(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug: return "debug";
    case LogLevel::kInfo: return "info";
    case LogLevel::kWarning: return "warning";
    case LogLevel::kError: return "error";
    case LogLevel::kOff: return "off";
  }
  return "unknown";
}

Result<LogLevel> parse_log_level(std::string_view name) {
  std::string lower(name);
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  if (lower == "debug") return LogLevel::kDebug;
  if (lower == "info") return LogLevel::kInfo;
  if (lower == "warning" || lower == "warn") return LogLevel::kWarning;
  if (lower == "error") return LogLevel::kError;
  if (lower == "off" || lower == "none") return LogLevel::kOff;
  return Error{ErrorCode::kInvalidArgument,
               "unknown log level '" + std::string(name.substr(0, 40)) + "' (debug, info, warning, error, off)"};
}

LogSink stderr_log_sink() {
  return [](LogLevel level, std::string_view message) {
    using namespace std::chrono;
    const auto now = system_clock::now();
    const std::time_t seconds = system_clock::to_time_t(now);
    const auto millis = duration_cast<milliseconds>(now.time_since_epoch()).count() % 1000;
    std::tm utc{};
    gmtime_r(&seconds, &utc);
    char stamp[64];
    std::snprintf(stamp, sizeof stamp, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ ", utc.tm_year + 1900, utc.tm_mon + 1,
                  utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec, static_cast<int>(millis));
    std::string line = stamp;
    std::string_view name = to_string(level);
    line.append(name);
    line.append(8 - std::min<size_t>(name.size(), 7), ' ');
    line.append(message);
    line.push_back('\n');
    // One write(2) per line: concurrent lines do not interleave.
    size_t done = 0;
    while (done < line.size()) {
      const ssize_t n = ::write(STDERR_FILENO, line.data() + done, line.size() - done);
      if (n <= 0) break;
      done += static_cast<size_t>(n);
    }
  };
}

namespace {

std::mutex g_sdk_logger_mu;
Logger g_sdk_logger{LogLevel::kWarning, {}};

}  // namespace

void set_log_sink(LogSink sink, LogLevel threshold) {
  std::lock_guard lock(g_sdk_logger_mu);
  g_sdk_logger = Logger{threshold, std::move(sink)};
}

Logger sdk_logger() {
  std::lock_guard lock(g_sdk_logger_mu);
  return g_sdk_logger;
}

}  // namespace softshell
