#pragma once
/// \file
/// \brief For C++ libraries that add C ABI entry points on top of the SDK (the embedded server's
/// `ss_session_create_embedded`, softshell_embedded_c.h): wrap a C++ `Session` into an
/// `ss_session` handle, run code under the C ABI's error policy, and log through the C log
/// callback. Not for applications.

#include <functional>
#include <memory>
#include <string_view>

#include "softshell/executor.h"
#include "softshell/session.h"
#include "softshell/softshell_c.h"

namespace softshell::c_api {

/// A new `ss_session` handle sharing ownership of `session` (released by `ss_session_destroy`
/// and by the last operation still running on it). Throws `Exception(kInvalidArgument)` for null.
SS_API ss_session* wrap_session(std::shared_ptr<Session> session);

/// The C++ session behind a live `ss_session` handle. Throws `Exception(kInvalidArgument)` for
/// NULL or a handle that is not a live session.
SS_API std::shared_ptr<Session> session_of(const ss_session* handle);

/// The host's task system as an `Executor` (each task boxed and handed to `enqueue`). Throws
/// `Exception(kInvalidArgument)` for NULL `enqueue` or `concurrency` < 1.
SS_API std::shared_ptr<Executor> executor_of(const ss_task_system& tasks);

/// Logs a message (level: SS_LOG_*) to the SDK's process-wide sink (softshell/log.h), which is the
/// C log callback when `ss_set_log_callback` installed one. Thread-safe; never throws.
SS_API void log_message(int32_t level, std::string_view message) noexcept;

/// Runs `fn` and returns SS_OK, or the status of what it threw (`softshell::Exception` -> its code,
/// std::bad_alloc -> SS_RESOURCE_EXHAUSTED, anything else -> SS_INTERNAL) with the message stored
/// for `ss_last_error_message()`, prefixed by `function`. Never throws.
SS_API ss_status guard(const char* function, const std::function<void()>& fn) noexcept;

}  // namespace softshell::c_api
