#pragma once
// What every response's `Server` header says, also on event streams (their head is written by
// the event writers, not by cpp-httplib). The version is the project's (server/http/CMakeLists.txt).

namespace softshell::http::internal {

inline constexpr const char* kServerHeader = "softshell/" SOFTSHELL_VERSION_STRING;

}  // namespace softshell::http::internal
