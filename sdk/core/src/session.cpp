#include "softshell/session.h"

namespace softshell {

std::string GeomId::hex() const {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out(32, '0');
  for (size_t i = 0; i < bytes.size(); ++i) {
    out[2 * i] = kDigits[bytes[i] >> 4];
    out[2 * i + 1] = kDigits[bytes[i] & 0xf];
  }
  return out;
}

Result<GeomId> GeomId::from_hex(std::string_view hex) {
  auto nibble = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  auto shown = [&] {
    std::string s(hex.substr(0, 40));
    for (char& c : s) {
      if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = '?';
    }
    return "'" + s + (hex.size() > 40 ? "...'" : "'");
  };
  if (hex.size() != 32) {
    return Error{ErrorCode::kInvalidArgument, "a geometry id is 32 hex characters, got " +
                                                  std::to_string(hex.size()) + " characters: " + shown()};
  }
  GeomId id;
  for (size_t i = 0; i < 16; ++i) {
    const int hi = nibble(hex[2 * i]), lo = nibble(hex[2 * i + 1]);
    if (hi < 0 || lo < 0) {
      return Error{ErrorCode::kInvalidArgument, "a geometry id is 32 hex characters (0-9, a-f), got " + shown()};
    }
    id.bytes[i] = static_cast<uint8_t>(hi << 4 | lo);
  }
  return id;
}

std::string_view to_string(GeometryStatus status) {
  switch (status) {
    case GeometryStatus::kPrecomputing: return "precomputing";
    case GeometryStatus::kReady: return "ready";
    case GeometryStatus::kFailed: return "failed";
  }
  return "unknown";
}

}  // namespace softshell

namespace softshell {
namespace {
Error no_holds() {
  return Error{ErrorCode::kUnavailable, "this session does not support holds and events (PROTOCOL.md version 2)"};
}
}  // namespace

Result<void> Session::remove_geometry(const GeomId&) {
  return Error{ErrorCode::kUnavailable, "this session does not support deleting geometries"};
}

Result<HeldResult> Session::put_hold(const GeomId&, const std::string&, const DeformationRequest&,
                                     std::chrono::milliseconds) {
  return no_holds();
}

std::future<Result<HeldResult>> Session::put_hold_async(const GeomId& id, const std::string& hold_id,
                                                        const DeformationRequest& request,
                                                        std::chrono::milliseconds ttl) {
  std::promise<Result<HeldResult>> promise;
  promise.set_value(put_hold(id, hold_id, request, ttl));
  return promise.get_future();
}

Result<HeldResult> Session::release_hold(const GeomId&, const std::string&) { return no_holds(); }
Result<HoldList> Session::holds(const GeomId&) { return no_holds(); }
Result<HoldDetail> Session::hold(const GeomId&, const std::string&) { return no_holds(); }
Result<std::unique_ptr<EventSubscription>> Session::subscribe(const GeomId&, uint32_t) { return no_holds(); }

}  // namespace softshell
