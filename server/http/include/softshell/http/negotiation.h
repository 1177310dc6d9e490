#pragma once
/// \file
/// \brief Content negotiation and parameter parsing of the HTTP API (PROTOCOL.md, Conventions):
/// pure functions, shared by the server and its tests.

#include <cstdint>
#include <string_view>

#include "softshell/result.h"
#include "softshell/wire.h"

namespace softshell::http {

/// The format of a request body from its `Content-Type` (media type parameters such as
/// `; charset=utf-8` are ignored, case-insensitive). kUnsupportedMediaType for anything but
/// `application/octet-stream` and `application/json`, including a missing header.
Result<wire::Format> body_format(std::string_view content_type);

/// The response format for an `Accept` header: among `application/octet-stream` and
/// `application/json`, the one with the highest quality (`q`, default 1; q = 0 excludes it).
/// Equal qualities prefer `fallback`, then the one listed first. Wildcards (`*/*`,
/// `application/*`), other types and an empty header are not "usable": they give `fallback`
/// (a POST's own body format, JSON for a GET).
wire::Format response_format(std::string_view accept, wire::Format fallback);

/// A non-negative integer query parameter that fits u32 (decimal digits only).
/// kInvalidArgument naming the parameter otherwise.
Result<uint32_t> parse_u32(std::string_view text, std::string_view name);

/// A finite decimal number (query parameter). kInvalidArgument naming the parameter otherwise.
Result<double> parse_number(std::string_view text, std::string_view name);

}  // namespace softshell::http
