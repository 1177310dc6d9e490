#include "softshell/assert.h"

#include <atomic>

#include "softshell/result.h"

namespace softshell {
namespace {

std::atomic<AssertHandler> g_handler{nullptr};

}  // namespace

AssertHandler set_assert_handler(AssertHandler handler) { return g_handler.exchange(handler); }

void default_assert_handler(const char* expression, const std::string& message, const char* file, int line) {
  const std::string text = "softshell bug: " + message + " (assertion `" + expression + "` failed at " + file + ":" +
                           std::to_string(line) + ")";
  throw Exception(ErrorCode::kInternal, text);
}

namespace internal {

void assert_failed(const char* expression, const std::string& message, const char* file, int line) {
  const AssertHandler handler = g_handler.load();
  (handler ? handler : default_assert_handler)(expression, message, file, line);
}

}  // namespace internal
}  // namespace softshell
