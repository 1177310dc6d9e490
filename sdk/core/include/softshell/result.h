#pragma once
/// \file
/// \brief Error codes, `Error`, and `Result<T>`: how every fallible softshell call reports failure.
///
/// softshell has one error policy, in three tiers:
///  - bad input from outside (files, network, user data) -> a `Result<T>` holding an `Error`
///    whose message tells a person what was wrong and what to do. Inside the library the same
///    errors travel as `softshell::Exception`; `capture` (one place: `error_from`) turns them into
///    a `Result` at the public boundary, and the HTTP layer and the C ABI map that to a status;
///  - broken preconditions (a bug in the caller or in softshell) -> `SOFTSHELL_ASSERT`
///    (softshell/assert.h), routed to a replaceable handler;
///  - `Result<T>::value()` on an error throws that `Exception`, so code that prefers exceptions can
///    simply call `.value()`.

#include <cstdint>
#include <exception>
#include <new>
#include <type_traits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace softshell {

/// What kind of failure happened. The numeric values are stable: the C ABI returns them.
enum class ErrorCode : int32_t {
  kOk = 0,
  kInvalidArgument = 1,       ///< malformed input: bad syntax, index out of range, NaN (HTTP 400)
  kUnprocessable = 2,         ///< well-formed but unusable: undetermined system, E <= 0, non-manifold (HTTP 422)
  kNotFound = 3,              ///< unknown geometry or result (HTTP 404)
  kPayloadTooLarge = 4,       ///< body over the configured limit (HTTP 413)
  kUnsupportedMediaType = 5,  ///< POST body that is neither JSON nor octet-stream (HTTP 415)
  kNotAcceptable = 6,         ///< the requested response format cannot represent the data (HTTP 406)
  kResourceExhausted = 7,     ///< a memory cap would be exceeded (HTTP 507)
  kUnavailable = 8,           ///< server unreachable, timed out or shutting down
  kCancelled = 9,             ///< the operation was cancelled by its owner
  kIoError = 10,              ///< a file could not be read or written
  kInternal = 11,             ///< a bug in softshell; please report it
  kConflict = 12,             ///< contradicts the state others made: a hold against other holds (HTTP 409)
  kGone = 13,                 ///< existed once, no longer kept: a result dropped by retention, a deleted geometry (HTTP 410)
};

/// Short stable name of a code, e.g. "invalid_argument" (the `error` field of HTTP errors).
std::string_view to_string(ErrorCode code) noexcept;

/// An error: a code for programs and a message for people.
struct Error {
  ErrorCode code = ErrorCode::kInternal;
  std::string message;
};

/// The exception form of `Error` (thrown by `Result::value()` and used inside the library).
class Exception : public std::runtime_error {
 public:
  Exception(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  explicit Exception(const Error& error) : Exception(error.code, error.message) {}
  ErrorCode code() const noexcept { return code_; }
  Error error() const { return Error{code_, what()}; }

 private:
  ErrorCode code_;
};

/// Throws `Exception(code, message)`; a one-liner for validation code.
[[noreturn]] inline void fail(ErrorCode code, const std::string& message) { throw Exception(code, message); }

template <class T>
class Result;
template <class T>
inline constexpr bool is_result_v = false;
template <class T>
inline constexpr bool is_result_v<Result<T>> = true;

/// A value or an error. Cheap to move; check with `ok()` / `operator bool` before `value()`.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : data_(std::move(value)) {}          // NOLINT(google-explicit-constructor)
  Result(Error error) : data_(std::move(error)) {}      // NOLINT(google-explicit-constructor)

  bool ok() const noexcept { return data_.index() == 0; }
  explicit operator bool() const noexcept { return ok(); }

  /// The value; throws `Exception` if this holds an error.
  T& value() & { check(); return std::get<0>(data_); }
  const T& value() const& { check(); return std::get<0>(data_); }
  T&& value() && { check(); return std::move(std::get<0>(data_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  /// The error; only meaningful when `!ok()`.
  const Error& error() const { return std::get<1>(data_); }

 private:
  void check() const {
    if (!ok()) throw Exception(std::get<1>(data_));
  }
  std::variant<T, Error> data_;
};

/// `Result<void>`: success or an error.
template <>
class [[nodiscard]] Result<void> {
 public:
  Result() = default;
  Result(Error error) : error_(std::move(error)), ok_(false) {}  // NOLINT(google-explicit-constructor)
  bool ok() const noexcept { return ok_; }
  explicit operator bool() const noexcept { return ok_; }
  void value() const {
    if (!ok_) throw Exception(error_);
  }
  const Error& error() const { return error_; }

 private:
  Error error_{ErrorCode::kOk, {}};
  bool ok_ = true;
};

/// The error an exception stands for: a softshell::Exception its own error; std::bad_alloc
/// kResourceExhausted ("out of memory while <doing>"); anything else kInternal, which is a bug and
/// is also reported to the SDK log sink (softshell/log.h). `doing` (e.g. "decoding the body")
/// completes the messages; may be empty. The one translation of exceptions in softshell.
Error error_from(std::exception_ptr exception, std::string_view doing = {}) noexcept;

/// Runs `fn` and returns its value, or the error of what it threw (`error_from`). `fn` may
/// return a value, a `Result` or nothing. Used at public boundaries.
template <class Fn>
auto capture(Fn&& fn, std::string_view doing = {}) noexcept {
  using R = decltype(fn());
  using Out = std::conditional_t<is_result_v<R>, R, Result<R>>;
  try {
    if constexpr (std::is_void_v<R>) {
      fn();
      return Out{};
    } else {
      return Out(fn());
    }
  } catch (...) {
    return Out(error_from(std::current_exception(), doing));
  }
}

}  // namespace softshell
