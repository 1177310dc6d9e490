// Format-independent parts of the wire layer: media types, HTTP statuses, request validation.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <string>

#include "softshell/wire.h"
#include "wire_internal.h"

namespace softshell::wire {

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
    case ErrorCode::kConflict: return 409;
    case ErrorCode::kGone: return 410;
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
    case 409: return ErrorCode::kConflict;
    case 410: return ErrorCode::kGone;
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

Result<void> check_hold_id(std::string_view hold_id) {
  auto allowed = [](char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
           c == '-';
  };
  if (hold_id.empty() || hold_id.size() > kMaxHoldIdLength ||
      !std::all_of(hold_id.begin(), hold_id.end(), allowed)) {
    std::string shown(hold_id.substr(0, 70));
    for (char& c : shown) c = allowed(c) ? c : '?';
    return Error{ErrorCode::kInvalidArgument, "a hold id is 1 to " + std::to_string(kMaxHoldIdLength) +
                                                  " characters of A-Z, a-z, 0-9, '.', '_' and '-'; got '" + shown +
                                                  (hold_id.size() > 70 ? "...'" : "'") + " (" +
                                                  std::to_string(hold_id.size()) + " characters)"};
  }
  return {};
}

std::string_view to_string(HoldStateStatus state) {
  switch (state) {
    case HoldStateStatus::kSolved: return "solved";
    case HoldStateStatus::kSolving: return "solving";
    case HoldStateStatus::kUnsolvable: return "unsolvable";
  }
  return "solved";
}

Result<HoldStateStatus> parse_hold_state(std::string_view name) {
  if (name == "solved") return HoldStateStatus::kSolved;
  if (name == "solving") return HoldStateStatus::kSolving;
  if (name == "unsolvable") return HoldStateStatus::kUnsolvable;
  return Error{ErrorCode::kInvalidArgument,
               "unknown hold state '" + std::string(name.substr(0, 40)) + "' (solved, solving, unsolvable)"};
}

}  // namespace softshell::wire
