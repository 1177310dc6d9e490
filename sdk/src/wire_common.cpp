// Format-independent parts of the wire layer: media types, HTTP statuses, request validation.
#include <algorithm>
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
    case ErrorCode::kConflict: return 409;
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

Result<void> validate_request(const DeformationRequest& request, int32_t num_control_points) {
  using internal::describe_number;
  auto bad = [](const std::string& message) -> Result<void> { return Error{ErrorCode::kInvalidArgument, message}; };
  auto index_ok = [&](int32_t i) { return i >= 0 && i < num_control_points; };
  auto range = [&](int32_t i) {
    return " refers to control point " + std::to_string(i) + ", but the geometry has " +
           std::to_string(num_control_points) + " (indices are 0-based)";
  };
  auto finite = [](const Vec3& v) { return v.allFinite(); };

  for (size_t k = 0; k < request.vertex_constraints.size(); ++k) {
    const auto& c = request.vertex_constraints[k];
    const std::string name = "vertex constraint " + std::to_string(k);
    if (c.mask == 0 || c.mask > 7) {
      return bad(name + " has mask " + std::to_string(c.mask) + "; a mask is 1..7 (bits 1 = x, 2 = y, 4 = z)");
    }
    if (!index_ok(c.index)) return bad(name + range(c.index));
    if (!finite(c.displacement)) return bad(name + " has a displacement that is not finite");
  }
  for (size_t k = 0; k < request.lagrange_constraints.size(); ++k) {
    const auto& c = request.lagrange_constraints[k];
    const std::string name = "Lagrange constraint " + std::to_string(k);
    if (c.indices.size() != c.coefficients.size()) {
      return bad(name + " has " + std::to_string(c.indices.size()) + " indices but " +
                 std::to_string(c.coefficients.size()) + " coefficient triples; they must match");
    }
    for (int32_t i : c.indices) {
      if (!index_ok(i)) return bad(name + range(i));
    }
    for (const Vec3& k3 : c.coefficients) {
      if (!finite(k3)) return bad(name + " has a coefficient that is not finite");
    }
    if (!finite(c.values)) return bad(name + " has a value that is not finite");
  }
  for (size_t k = 0; k < request.forces.size(); ++k) {
    const auto& f = request.forces[k];
    const std::string name = "force " + std::to_string(k);
    if (!index_ok(f.index)) return bad(name + range(f.index));
    if (!finite(f.force)) return bad(name + " is not finite");
  }
  auto check_point = [&](const SurfacePoint& p, const std::string& name) -> Result<void> {
    if (p.face < 0) return bad(name + " has a negative face index");
    if (p.subface < 0) return bad(name + " has a negative sub-face index");
    if (!(p.u >= 0.0 && p.u <= 1.0) || !(p.v >= 0.0 && p.v <= 1.0)) {
      return bad(name + " has (u, v) = (" + describe_number(p.u) + ", " + describe_number(p.v) +
                 "); both must lie in [0, 1]");
    }
    return {};
  };
  for (size_t k = 0; k < request.limit_constraints.size(); ++k) {
    const auto& c = request.limit_constraints[k];
    const std::string name = "limit constraint " + std::to_string(k);
    if (auto ok = check_point(c.point, name); !ok) return ok;
    if (!finite(c.displacement)) return bad(name + " has a displacement that is not finite");
    if ((c.du_displacement && !finite(*c.du_displacement)) || (c.dv_displacement && !finite(*c.dv_displacement))) {
      return bad(name + " has a tangent displacement that is not finite");
    }
  }
  for (size_t k = 0; k < request.surface_forces.size(); ++k) {
    const auto& f = request.surface_forces[k];
    const std::string name = "surface force " + std::to_string(k);
    if (auto ok = check_point(f.point, name); !ok) return ok;
    if (!finite(f.force)) return bad(name + " is not finite");
  }
  if (!finite(request.surface_load)) return bad("the surface load is not finite");
  if (!std::isfinite(request.pressure)) return bad("the pressure is " + describe_number(request.pressure));
  return {};
}

}  // namespace softshell::wire
