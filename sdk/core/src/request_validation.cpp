#include "softshell/request_validation.h"

#include <algorithm>
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

RequestLimits RequestLimits::for_control_points(int32_t num_control_points) {
  const auto n = static_cast<size_t>(std::max(num_control_points, 1));
  return RequestLimits{std::min(kMaxSurfaceConstraints, n), std::max(kMinElementLimit, 3 * n),
                       std::max(kMinElementLimit, 4 * n), n};
}

namespace {

Result<void> check_counts(const DeformationRequest& request, int32_t num_control_points) {
  const RequestLimits limits = RequestLimits::for_control_points(num_control_points);
  const std::string points = std::to_string(num_control_points) + " control points";
  auto over = [](std::string message) -> Result<void> { return Error{ErrorCode::kUnprocessable, std::move(message)}; };
  const size_t surface = request.lagrange_constraints.size() + request.limit_constraints.size();
  if (surface > limits.surface_constraints) {
    return over("the request has " + std::to_string(surface) +
                " Lagrange and limit constraints; one request may have at most " +
                std::to_string(limits.surface_constraints) + " on this geometry (" +
                std::to_string(RequestLimits::kMaxSurfaceConstraints) + ", and no more than its " + points +
                "). Pin control points with vertex constraints instead (they cost nothing), or constrain fewer "
                "surface points: a few well-spread points hold a surface as firmly as many");
  }
  if (request.vertex_constraints.size() > limits.vertex_constraints) {
    return over("the request has " + std::to_string(request.vertex_constraints.size()) +
                " vertex constraints; the geometry's " + points + " take at most " +
                std::to_string(limits.vertex_constraints) + " (one per axis each); merge repeated ones");
  }
  if (request.forces.size() > limits.forces) {
    return over("the request has " + std::to_string(request.forces.size()) + " forces; the geometry's " + points +
                " take at most " + std::to_string(limits.forces) +
                " (forces on one control point add up: send their sum once)");
  }
  if (request.surface_forces.size() > RequestLimits::kMaxSurfaceForces) {
    return over("the request has " + std::to_string(request.surface_forces.size()) +
                " surface forces; at most " + std::to_string(RequestLimits::kMaxSurfaceForces) +
                " are taken per request (add up nearby ones, or use surface_load for a spread load)");
  }
  for (size_t k = 0; k < request.lagrange_constraints.size(); ++k) {
    if (request.lagrange_constraints[k].indices.size() > limits.lagrange_terms) {
      return over("Lagrange constraint " + std::to_string(k) + " has " +
                  std::to_string(request.lagrange_constraints[k].indices.size()) +
                  " terms, more than the geometry's " + points + "; combine the terms of repeated indices");
    }
  }
  return {};
}

}  // namespace

Result<void> validate_request(const DeformationRequest& request, const RequestContext& context) {
  if (context.num_control_points != RequestContext::kUnknown) {
    if (auto ok = check_counts(request, context.num_control_points); !ok) return ok;
  }
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
