#include "request_check.h"

#include <cmath>
#include <string>

namespace softshell::engine::internal {
namespace {

[[noreturn]] void bad(const std::string& message) { fail(ErrorCode::kInvalidArgument, message); }

void check_index(const ShellModel& model, int32_t index, const std::string& what) {
  if (index < 0 || index >= model.num_control_points()) {
    bad(what + ": control point index " + std::to_string(index) + " is out of range (the geometry has " +
        std::to_string(model.num_control_points()) + " control points)");
  }
}

void check_finite(const Vec3& v, const std::string& what) {
  if (!v.allFinite()) bad(what + " has a component that is NaN or infinite");
}

void check_point(const ShellModel& model, const SurfacePoint& p, const std::string& what) {
  if (auto ok = model.evaluator().check(p); !ok) bad(what + ": " + ok.error().message);
}

}  // namespace

void check_loads(const ShellModel& model, const DeformationRequest& request) {
  for (size_t i = 0; i < request.forces.size(); ++i) {
    const std::string what = "force " + std::to_string(i);
    check_index(model, request.forces[i].index, what);
    check_finite(request.forces[i].force, what);
  }
  for (size_t i = 0; i < request.surface_forces.size(); ++i) {
    const std::string what = "surface force " + std::to_string(i);
    check_point(model, request.surface_forces[i].point, what);
    check_finite(request.surface_forces[i].force, what);
  }
  check_finite(request.surface_load, "the surface load");
  if (!std::isfinite(request.pressure)) bad("the pressure is NaN or infinite");
}

void check_request(const ShellModel& model, const DeformationRequest& request) {
  check_loads(model, request);
  for (size_t i = 0; i < request.vertex_constraints.size(); ++i) {
    const VertexConstraint& c = request.vertex_constraints[i];
    const std::string what = "vertex constraint " + std::to_string(i);
    check_index(model, c.index, what);
    if (c.mask == 0 || c.mask > 7) {
      bad(what + ": mask " + std::to_string(c.mask) + " is invalid; use bits 1 = x, 2 = y, 4 = z (1..7)");
    }
    check_finite(c.displacement, what);
  }
  for (size_t i = 0; i < request.lagrange_constraints.size(); ++i) {
    const LagrangeConstraint& c = request.lagrange_constraints[i];
    const std::string what = "Lagrange constraint " + std::to_string(i);
    if (c.indices.size() != c.coefficients.size()) {
      bad(what + ": " + std::to_string(c.indices.size()) + " indices but " + std::to_string(c.coefficients.size()) +
          " coefficient triples");
    }
    for (size_t k = 0; k < c.indices.size(); ++k) {
      check_index(model, c.indices[k], what);
      check_finite(c.coefficients[k], what);
    }
    check_finite(c.values, what);
  }
  for (size_t i = 0; i < request.limit_constraints.size(); ++i) {
    const LimitConstraint& c = request.limit_constraints[i];
    const std::string what = "limit constraint " + std::to_string(i);
    check_point(model, c.point, what);
    check_finite(c.displacement, what);
    if (c.du_displacement) check_finite(*c.du_displacement, what + " (du)");
    if (c.dv_displacement) check_finite(*c.dv_displacement, what + " (dv)");
  }
}

}  // namespace softshell::engine::internal
