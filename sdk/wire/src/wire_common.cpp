// Format-independent parts of the wire layer: media types, HTTP statuses, request validation.
#include <charconv>
#include <cmath>
#include <string>

#include "softshell/wire.h"
#include "wire_internal.h"

namespace softshell::wire {

namespace internal {

std::string describe_number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[32];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, ptr) : std::string("?");
}

}  // namespace internal

std::string_view media_type(Format format) {
  return format == Format::kBinary ? kBinaryMediaType : kJsonMediaType;
}

int http_status(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk: return 200;
    case ErrorCode::kInvalidArgument: return 400;
    case ErrorCode::kNotFound: return 404;
    case ErrorCode::kNotAcceptable: return 406;
    case ErrorCode::kPayloadTooLarge: return 413;
    case ErrorCode::kUnsupportedMediaType: return 415;
    case ErrorCode::kUnprocessable: return 422;
    case ErrorCode::kCancelled: return 499;  // the client went away (nginx's convention)
    case ErrorCode::kResourceExhausted: return 507;
    case ErrorCode::kUnavailable: return 503;
    case ErrorCode::kIoError:
    case ErrorCode::kInternal: return 500;
  }
  return 500;
}

ErrorCode error_code_for_status(int status) {
  switch (status) {
    case 400: return ErrorCode::kInvalidArgument;
    case 404: return ErrorCode::kNotFound;
    case 406: return ErrorCode::kNotAcceptable;
    case 413: return ErrorCode::kPayloadTooLarge;
    case 415: return ErrorCode::kUnsupportedMediaType;
    case 422: return ErrorCode::kUnprocessable;
    case 499: return ErrorCode::kCancelled;
    case 502:
    case 503:
    case 504: return ErrorCode::kUnavailable;
    case 507: return ErrorCode::kResourceExhausted;
    default: break;
  }
  if (status >= 200 && status < 300) return ErrorCode::kOk;
  if (status >= 400 && status < 500) return ErrorCode::kInvalidArgument;
  return ErrorCode::kInternal;
}

}  // namespace softshell::wire
