#include "softshell/request_validation.h"

#include <charconv>
#include <cmath>
#include <string>

namespace softshell {
std::string describe_number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[32];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, ptr) : std::string("?");
}

namespace {

Result<void> bad(std::string message) { return Error{ErrorCode::kInvalidArgument, std::move(message)}; }

bool finite(const Vec3& v) { return v.allFinite(); }

Result<void> check_index(int32_t index, const std::string& name, const RequestContext& context) {
  if (index < 0) return bad(name + " refers to control point " + std::to_string(index) + "; indices are 0-based");
  if (context.num_control_points != RequestContext::kUnknown && index >= context.num_control_points) {
    return bad(name + " refers to control point " + std::to_string(index) + ", but the geometry has " +
               std::to_string(context.num_control_points) + " (indices are 0-based)");
  }
  return {};
}

Result<void> check_point(const SurfacePoint& p, const std::string& name, const RequestContext& context) {
  if (!(p.u >= 0.0 && p.u <= 1.0) || !(p.v >= 0.0 && p.v <= 1.0)) {
    return bad(name + " has (u, v) = (" + describe_number(p.u) + ", " + describe_number(p.v) +
               "); both must lie in [0, 1]");
  }
  if (p.face < 0) return bad(name + " has a negative face index");
  if (p.subface < 0) return bad(name + " has a negative sub-face index");
  if (context.evaluator) {
    if (auto ok = context.evaluator->check(p); !ok) return bad(name + ": " + ok.error().message);
  }
  return {};
}

}  // namespace

Result<void> validate(const VertexConstraint& c, size_t position, const RequestContext& context) {
  const std::string name = "vertex constraint " + std::to_string(position);
  if (c.mask == 0 || c.mask > 7) {
    return bad(name + " has mask " + std::to_string(c.mask) + "; a mask is 1..7 (bits 1 = x, 2 = y, 4 = z)");
  }
  if (auto ok = check_index(c.index, name, context); !ok) return ok;
  if (!finite(c.displacement)) return bad(name + " has a displacement that is not finite");
  return {};
}

Result<void> validate(const LagrangeConstraint& c, size_t position, const RequestContext& context) {
  const std::string name = "Lagrange constraint " + std::to_string(position);
  if (c.indices.size() != c.coefficients.size()) {
    return bad(name + " has " + std::to_string(c.indices.size()) + " indices but " +
               std::to_string(c.coefficients.size()) + " coefficient triples; they must match");
  }
  for (int32_t i : c.indices) {
    if (auto ok = check_index(i, name, context); !ok) return ok;
  }
  for (const Vec3& k : c.coefficients) {
    if (!finite(k)) return bad(name + " has a coefficient that is not finite");
  }
  if (!finite(c.values)) return bad(name + " has a value that is not finite");
  return {};
}

Result<void> validate(const PointForce& f, size_t position, const RequestContext& context) {
  const std::string name = "force " + std::to_string(position);
  if (auto ok = check_index(f.index, name, context); !ok) return ok;
  if (!finite(f.force)) return bad(name + " is not finite");
  return {};
}

Result<void> validate(const LimitConstraint& c, size_t position, const RequestContext& context) {
  const std::string name = "limit constraint " + std::to_string(position);
  if (auto ok = check_point(c.point, name, context); !ok) return ok;
  if (!finite(c.displacement)) return bad(name + " has a displacement that is not finite");
  if ((c.du_displacement && !finite(*c.du_displacement)) || (c.dv_displacement && !finite(*c.dv_displacement))) {
    return bad(name + " has a tangent displacement that is not finite");
  }
  return {};
}

Result<void> validate(const SurfaceForce& f, size_t position, const RequestContext& context) {
  const std::string name = "surface force " + std::to_string(position);
  if (auto ok = check_point(f.point, name, context); !ok) return ok;
  if (!finite(f.force)) return bad(name + " is not finite");
  return {};
}

Result<void> validate_loads(const Vec3& surface_load, double pressure) {
  if (!finite(surface_load)) return bad("the surface load is not finite");
  if (!std::isfinite(pressure)) return bad("the pressure is " + describe_number(pressure));
  return {};
}

Result<void> validate_request(const DeformationRequest& request, const RequestContext& context) {
  auto each = [&](const auto& elements) -> Result<void> {
    for (size_t k = 0; k < elements.size(); ++k) {
      if (auto ok = validate(elements[k], k, context); !ok) return ok;
    }
    return {};
  };
  if (auto ok = each(request.vertex_constraints); !ok) return ok;
  if (auto ok = each(request.lagrange_constraints); !ok) return ok;
  if (auto ok = each(request.forces); !ok) return ok;
  if (auto ok = each(request.limit_constraints); !ok) return ok;
  if (auto ok = each(request.surface_forces); !ok) return ok;
  return validate_loads(request.surface_load, request.pressure);
}

}  // namespace softshell
