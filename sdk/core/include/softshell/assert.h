#pragma once
/// \file
/// \brief `SOFTSHELL_ASSERT`: the tier for broken preconditions (bugs), with a replaceable handler.
///
/// Input from outside is validated once at the boundary (softshell/request_validation.h,
/// softshell/mesh_validation.h) and answered with a `Result`. Code behind the boundary asserts
/// what the boundary established; a failed assertion is a bug in the caller or in softshell. The
/// checks stay on in release builds (they guard memory safety and cost little next to the work).
///
/// The default handler throws `Exception(kInternal)`, which the boundary's `capture` turns into an
/// internal error and reports to the SDK log sink (softshell/log.h): a server answers that one
/// request with a 500 and keeps running. A host can install its own handler (break into a
/// debugger, abort, record in a test).

#include <string>

namespace softshell {

/// Called with the failed expression, a message for a person, and where. May throw or not
/// return; if it returns, execution continues after the assertion.
using AssertHandler = void (*)(const char* expression, const std::string& message, const char* file, int line);

/// Installs `handler` (nullptr restores the default) and returns the previous one. Thread-safe.
AssertHandler set_assert_handler(AssertHandler handler);

/// The default handler: throws Exception(kInternal) with the message, expression and place.
void default_assert_handler(const char* expression, const std::string& message, const char* file, int line);

namespace internal {
void assert_failed(const char* expression, const std::string& message, const char* file, int line);
}  // namespace internal

}  // namespace softshell

/// Checks a precondition; on failure calls the assert handler with `message` (a std::string
/// expression, evaluated only on failure).
#define SOFTSHELL_ASSERT(condition, message)                                             \
  do {                                                                                   \
    if (!(condition)) ::softshell::internal::assert_failed(#condition, (message), __FILE__, __LINE__); \
  } while (false)
