// Access tokens: the token file (--auth-token-file) and the check of every request.
#include "softshell/http/auth.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string_view>

#include <strings.h>
#include <sys/stat.h>

#include "context.h"
#include "auth.h"  // after context.h: httplib.h last (see listener.h)

namespace softshell::http {

Result<void> check_auth_token(const std::string& token) {
  if (token.empty()) return Error{ErrorCode::kInvalidArgument, "the access token is empty"};
  for (size_t i = 0; i < token.size(); ++i) {
    const auto c = static_cast<unsigned char>(token[i]);
    if (c < 0x21 || c > 0x7e) {
      return Error{ErrorCode::kInvalidArgument,
                   "the access token has a character outside visible ASCII at position " + std::to_string(i + 1) +
                       " (tokens are one word of the characters ! to ~, no spaces)"};
    }
  }
  if (token.size() < kMinAuthTokenLength) {
    return Error{ErrorCode::kInvalidArgument, "the access token has " + std::to_string(token.size()) +
                                                  " characters; at least " + std::to_string(kMinAuthTokenLength) +
                                                  " are needed (e.g. `openssl rand -hex 32`)"};
  }
  return {};
}

Result<AuthTokenFile> read_auth_token_file(const std::string& path) {
  const std::string named = "the token file '" + path + "'";
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int e = errno;
    return Error{ErrorCode::kIoError, named + (e == ENOENT ? " does not exist" : std::string(": ") + std::strerror(e))};
  }
  if (!S_ISREG(st.st_mode)) return Error{ErrorCode::kInvalidArgument, named + " is not a regular file"};
  if (static_cast<size_t>(st.st_size) > kMaxAuthTokenFileBytes) {
    return Error{ErrorCode::kInvalidArgument, named + " is larger than " + std::to_string(kMaxAuthTokenFileBytes) +
                                                  " bytes; it should hold one token"};
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Error{ErrorCode::kIoError, named + " cannot be read: " + std::strerror(errno)};
  }
  std::string text(static_cast<size_t>(st.st_size), '\0');  // at most kMaxAuthTokenFileBytes
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  if (in.bad()) return Error{ErrorCode::kIoError, named + " cannot be read"};
  text.resize(static_cast<size_t>(in.gcount()));
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ' || text.back() == '\t')) {
    text.pop_back();
  }
  if (auto ok = check_auth_token(text); !ok) {
    return Error{ErrorCode::kInvalidArgument, named + ": " + ok.error().message};
  }
  AuthTokenFile out{std::move(text), {}};
  if ((st.st_mode & (S_IRGRP | S_IROTH)) != 0) {
    out.warnings.push_back(named + " is readable by " +
                           ((st.st_mode & S_IROTH) != 0 ? std::string("other users") : std::string("its group")) +
                           "; make it private: chmod 600 '" + path + "'");
  }
  return out;
}

namespace internal {
namespace {

// Compares in time that depends only on the expected token's length, not on where the given
// one differs (no byte-by-byte timing oracle).
bool same_token(std::string_view expected, std::string_view given) {
  unsigned char diff = given.size() == expected.size() ? 0 : 1;
  for (size_t i = 0; i < expected.size(); ++i) {
    const unsigned char g = i < given.size() ? static_cast<unsigned char>(given[i]) : 0;
    diff |= static_cast<unsigned char>(g ^ static_cast<unsigned char>(expected[i]));
  }
  return diff == 0;
}

// Requests answered without a token: liveness, the browser app's files (public code, no data;
// the page takes the token from its URL fragment) and CORS preflights (sent without credentials).
bool exempt(const httplib::Request& req) {
  if (req.method == "OPTIONS") return true;
  if (req.method != "GET" && req.method != "HEAD") return false;
  const std::string_view p = req.path;
  return p == "/health" || p == "/" || p == "/index.html" || p.substr(0, 5) == "/app/";
}

bool has_body(const httplib::Request& req) {
  if (req.has_header("Transfer-Encoding")) return true;
  const std::string length = req.get_header_value("Content-Length");
  return !length.empty() && length.find_first_not_of('0') != std::string::npos;
}

}  // namespace

bool authorize(const std::string& token, const httplib::Request& req, httplib::Response& res) {
  if (token.empty() || exempt(req)) return true;
  constexpr std::string_view kScheme = "Bearer ";
  std::string message;
  bool invalid = false;
  const size_t headers = req.get_header_value_count("Authorization");
  if (headers == 0) {
    message = "this server needs an access token: send the header 'Authorization: Bearer <token>' with the token "
              "of its --auth-token-file";
  } else {
    const std::string header = req.get_header_value("Authorization");  // a copy: the view below needs it alive
    std::string_view value = header;
    const bool bearer = headers == 1 && value.size() > kScheme.size() &&
                        strncasecmp(value.data(), kScheme.data(), kScheme.size()) == 0;
    if (!bearer) {
      message = "the Authorization header must be exactly one 'Bearer <token>' (the token of the server's "
                "--auth-token-file)";
    } else {
      value.remove_prefix(kScheme.size());
      while (!value.empty() && value.front() == ' ') value.remove_prefix(1);
      while (!value.empty() && value.back() == ' ') value.remove_suffix(1);
      if (same_token(token, value)) return true;
      message = "the access token sent is not this server's (see its --auth-token-file)";
      invalid = true;
    }
  }
  res.status = 401;
  res.set_content(wire::encode_error_json("unauthenticated", message), std::string(wire::kJsonMediaType));
  res.set_header("WWW-Authenticate", invalid ? R"(Bearer realm="softshell", error="invalid_token")"
                                             : R"(Bearer realm="softshell")");
  // An unread body cannot be skipped: the connection ends after the answer. No limit is checked
  // or named before the token is.
  if (has_body(req)) {
    res.set_header("Connection", "close");
    if (Connection* c = current_connection()) c->close_after_answer();
  }
  return false;
}

}  // namespace internal
}  // namespace softshell::http
