#pragma once
/// \file
/// \brief Access tokens: reading a server's token file (`--auth-token-file`).
///
/// With `ServerOptions::auth_token` set, every request needs `Authorization: Bearer <token>`
/// except `GET /health`, the browser app's own files (`/`, `/index.html`, `/app/...`: public
/// code, no data) and CORS preflights (`OPTIONS`, which browsers send without credentials).
/// Others get 401 with `WWW-Authenticate: Bearer realm="softshell"`; the token is never taken
/// from a URL (docs/api-notes.md, Authentication).

#include <string>
#include <vector>

#include "softshell/result.h"

namespace softshell::http {

/// Shortest token accepted (characters).
inline constexpr size_t kMinAuthTokenLength = 16;
/// Largest token file read (bytes): a token file holds one token.
inline constexpr size_t kMaxAuthTokenFileBytes = 4096;

/// A token read from its file, and what a person should hear about the file.
struct AuthTokenFile {
  std::string token;
  /// E.g. that the file is readable by group or others.
  std::vector<std::string> warnings;
};

/// Reads the token in `path`: the file's text without trailing whitespace (a newline). Refused
/// (kIoError for a file that is missing or cannot be read, kInvalidArgument otherwise, each
/// naming the file and what to do): an empty token, one shorter than `kMinAuthTokenLength`, one
/// with characters outside visible ASCII (`!`..`~`: no spaces, no control characters), a file
/// larger than `kMaxAuthTokenFileBytes`.
Result<AuthTokenFile> read_auth_token_file(const std::string& path);

/// Whether `token` could be a server's token (the checks of `read_auth_token_file`); the reason
/// otherwise.
Result<void> check_auth_token(const std::string& token);

}  // namespace softshell::http
