// Version, statuses, the error guard, the log callback, and the struct layouts the bindings rely on.

#include <cstddef>
#include <mutex>
#include <string>
#include <string_view>

#include "c_api_internal.h"
#include "softshell/log.h"
#include "softshell/softshell_c_bridge.h"

// The layouts that C, C# (P/Invoke, sequential layout; bindings/csharp/Softshell.cs) and Unreal
// rely on. Changing one is an ABI break: bump SS_ABI_VERSION (and the C# file).
static_assert(SS_ABI_VERSION == 4u);
static_assert(sizeof(ss_vec3) == 24 && sizeof(ss_quat) == 32 && sizeof(ss_pose) == 56);
static_assert(sizeof(ss_surface_point) == 24 && offsetof(ss_surface_point, u) == 8);
static_assert(sizeof(ss_material) == 32 && sizeof(ss_geom_id) == 16);
static_assert(sizeof(ss_ray) == 64 && offsetof(ss_ray, t_min) == 48);
static_assert(sizeof(ss_limit_sample) == 96);
static_assert(sizeof(ss_pick) == 184 && offsetof(ss_pick, estimate) == 8 && offsetof(ss_pick, t) == 152 &&
              offsetof(ss_pick, iterations) == 176);
static_assert(sizeof(ss_grab_options) == 8 && sizeof(ss_floor_options) == 16);
static_assert(sizeof(ss_remote_options) == 16 + sizeof(void*) && offsetof(ss_remote_options, auth_token) == 16);
static_assert(sizeof(ss_geometry_status) == 24 && offsetof(ss_geometry_status, progress) == 16);
// SS_LOG_* are softshell::LogLevel's values.
static_assert(static_cast<int>(softshell::LogLevel::kDebug) == SS_LOG_DEBUG &&
              static_cast<int>(softshell::LogLevel::kWarning) == SS_LOG_WARNING &&
              static_cast<int>(softshell::LogLevel::kOff) == SS_LOG_OFF);

// The header's version macros follow the project's version (CMakeLists.txt).
static_assert(SS_VERSION_MAJOR == SOFTSHELL_VERSION_MAJOR && SS_VERSION_MINOR == SOFTSHELL_VERSION_MINOR &&
                  SS_VERSION_PATCH == SOFTSHELL_VERSION_PATCH,
              "softshell_c.h's SS_VERSION_* differ from project(VERSION) in CMakeLists.txt");
static_assert(std::string_view(SS_VERSION_STRING) == SOFTSHELL_VERSION_STRING,
              "softshell_c.h's SS_VERSION_STRING differs from project(VERSION) in CMakeLists.txt");

namespace softshell::c_api {
namespace {

thread_local std::string g_message;  // NOLINT(cppcoreguidelines-avoid-non-const-global-variables)

// The C log callback. It is reached through the SDK's process-wide log sink (softshell/log.h),
// so that the C ABI's own messages, the embedded server's and the SDK's (failed assertions,
// internal errors) all arrive there.
struct LogTarget {
  std::mutex mutex;
  ss_log_callback callback = nullptr;
  void* user_data = nullptr;
  int32_t min_level = SS_LOG_OFF;
};

LogTarget& log_target() {
  static auto* target = new LogTarget;  // never destroyed: background threads may log at exit
  return *target;
}

// The SDK sink while a C callback is installed.
void deliver_to_c(LogLevel level, std::string_view message) {
  try {
    const std::string text(message);
    LogTarget& t = log_target();
    std::lock_guard lock(t.mutex);  // one message at a time, and never after the callback was removed
    const auto l = static_cast<int32_t>(level);
    if (t.callback != nullptr && l >= t.min_level) t.callback(l, text.c_str(), t.user_data);
  } catch (...) {
    // Out of memory while logging: the message is dropped.
  }
}

}  // namespace

void log(int32_t level, std::string_view message) noexcept {
  try {
    sdk_logger().log(static_cast<LogLevel>(level), message);
  } catch (...) {
    // A sink that throws (or no memory to copy it): the message is dropped.
  }
}

ss_status guard(const char* function, const std::function<void()>& fn) noexcept {
  try {
    try {
      fn();
      g_message.clear();
      return SS_OK;
    } catch (const CStatus& s) {  // the C ABI's own statuses (buffer too small, not ready)
      g_message = std::string(function) + ": " + s.message;
      return s.status;
    } catch (...) {
      const Error error = error_from(std::current_exception());
      g_message = std::string(function) + ": " + error.message;
      return static_cast<ss_status>(error.code);
    }
  } catch (...) {
    // Even storing the message failed (out of memory).
    return SS_RESOURCE_EXHAUSTED;
  }
}

}  // namespace softshell::c_api

extern "C" {

const char* ss_version(void) { return SS_VERSION_STRING; }

uint32_t ss_version_number(void) { return SS_VERSION_NUMBER; }

uint32_t ss_abi_version(void) { return SS_ABI_VERSION; }

const char* ss_last_error_message(void) { return softshell::c_api::g_message.c_str(); }

const char* ss_status_name(ss_status status) {
  switch (status) {
    case SS_OK: return "ok";
    case SS_INVALID_ARGUMENT: return "invalid_argument";
    case SS_UNPROCESSABLE: return "unprocessable";
    case SS_NOT_FOUND: return "not_found";
    case SS_PAYLOAD_TOO_LARGE: return "payload_too_large";
    case SS_UNSUPPORTED_MEDIA_TYPE: return "unsupported_media_type";
    case SS_NOT_ACCEPTABLE: return "not_acceptable";
    case SS_RESOURCE_EXHAUSTED: return "resource_exhausted";
    case SS_UNAVAILABLE: return "unavailable";
    case SS_CANCELLED: return "cancelled";
    case SS_IO_ERROR: return "io_error";
    case SS_INTERNAL: return "internal";
    case SS_CONFLICT: return "conflict";
    case SS_BUFFER_TOO_SMALL: return "buffer_too_small";
    case SS_NOT_READY: return "not_ready";
    default: return "unknown_status";
  }
}

ss_status ss_set_log_callback(ss_log_callback callback, void* user_data, int32_t min_level) {
  return softshell::c_api::guard("ss_set_log_callback", [&] {
    if (min_level < SS_LOG_DEBUG || min_level > SS_LOG_OFF) {
      softshell::fail(softshell::ErrorCode::kInvalidArgument,
                      "min_level must be SS_LOG_DEBUG (0) .. SS_LOG_OFF (4), got " + std::to_string(min_level));
    }
    auto& t = softshell::c_api::log_target();
    {
      std::lock_guard lock(t.mutex);
      t.callback = callback;
      t.user_data = user_data;
      t.min_level = callback == nullptr ? SS_LOG_OFF : min_level;
    }
    if (callback == nullptr) {
      softshell::set_log_sink({}, softshell::LogLevel::kOff);
    } else {
      softshell::set_log_sink(softshell::c_api::deliver_to_c, static_cast<softshell::LogLevel>(min_level));
    }
  });
}

}  // extern "C"
