#include "softshell/result.h"

#include "softshell/log.h"

namespace softshell {

std::string_view to_string(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::kOk: return "ok";
    case ErrorCode::kInvalidArgument: return "invalid_argument";
    case ErrorCode::kUnprocessable: return "unprocessable";
    case ErrorCode::kNotFound: return "not_found";
    case ErrorCode::kPayloadTooLarge: return "payload_too_large";
    case ErrorCode::kUnsupportedMediaType: return "unsupported_media_type";
    case ErrorCode::kNotAcceptable: return "not_acceptable";
    case ErrorCode::kResourceExhausted: return "resource_exhausted";
    case ErrorCode::kUnavailable: return "unavailable";
    case ErrorCode::kCancelled: return "cancelled";
    case ErrorCode::kIoError: return "io_error";
    case ErrorCode::kInternal: return "internal";
    case ErrorCode::kConflict: return "conflict";
    case ErrorCode::kGone: return "gone";
  }
  return "unknown";
}

Error error_from(std::exception_ptr exception, std::string_view doing) noexcept {
  const std::string while_doing = doing.empty() ? std::string() : " while " + std::string(doing);
  Error error;
  try {
    try {
      std::rethrow_exception(exception);
    } catch (const Exception& e) {
      error = e.error();
    } catch (const std::bad_alloc&) {
      return Error{ErrorCode::kResourceExhausted, "out of memory" + while_doing};
    } catch (const std::exception& e) {
      error = Error{ErrorCode::kInternal, "internal error" + while_doing + ": " + e.what()};
    } catch (...) {
      error = Error{ErrorCode::kInternal, "internal error" + while_doing + " (an unknown exception)"};
    }
    if (error.code == ErrorCode::kInternal) sdk_logger().error(error.message);
    return error;
  } catch (...) {
    // Even building the message failed: there is no memory left.
    return Error{ErrorCode::kResourceExhausted, {}};
  }
}

}  // namespace softshell
