// C ABI: deformation requests and the interaction helpers that fill them (floor contact, grabs).
// Each element is checked when it is added by the SDK's one request validator
// (request_validation.h: the same rules and messages as the service); what needs the geometry
// (indices in range, points on the surface) is checked when the request is solved.

#include <string>
#include <vector>

#include "c_api_internal.h"
#include "softshell/request_validation.h"
#include "softshell/softshell_c_bridge.h"

using namespace softshell;         // NOLINT(google-build-using-namespace): a .cpp of entry points
using namespace softshell::c_api;  // NOLINT(google-build-using-namespace)

namespace {

// A vector that becomes part of a request: only converted here; `add_valid` checks the element.
Vec3 request_vec(const ss_vec3* v, const char* argument) {
  required(v, argument);
  return Vec3(v->x, v->y, v->z);
}

// Appends an element to a request after the SDK's request validator has accepted it (the
// geometry is not known yet: indices are checked against it when the request is solved).
template <class Element>
void add_valid(std::vector<Element>& elements, Element element) {
  validate(element, elements.size(), RequestContext{}).value();
  elements.push_back(std::move(element));
}

}  // namespace

extern "C" {

// ------------------------------------------------------------------------------------------------
// Requests

ss_status ss_request_create(ss_request** out_request) {
  return guard("ss_request_create", [&] {
    required(out_request, "out_request");
    *out_request = nullptr;
    *out_request = make_handle<ss_request>(std::make_shared<DeformationRequest>());
  });
}

void ss_request_destroy(ss_request* request) { destroy(request, "ss_request_destroy"); }

ss_status ss_request_clear(ss_request* request) {
  return guard("ss_request_clear", [&] { *live(request, "request") = {}; });
}

ss_status ss_request_add_vertex_constraint(ss_request* request, int32_t index, uint32_t mask,
                                           const ss_vec3* displacement) {
  return guard("ss_request_add_vertex_constraint", [&] {
    const auto r = live(request, "request");
    add_valid(r->vertex_constraints, {index, mask, request_vec(displacement, "displacement")});
  });
}

ss_status ss_request_add_force(ss_request* request, int32_t index, const ss_vec3* force) {
  return guard("ss_request_add_force", [&] {
    const auto r = live(request, "request");
    add_valid(r->forces, {index, request_vec(force, "force")});
  });
}

ss_status ss_request_add_surface_force(ss_request* request, const ss_surface_point* p, const ss_vec3* force) {
  return guard("ss_request_add_surface_force", [&] {
    const auto r = live(request, "request");
    add_valid(r->surface_forces, {point(p, "point"), request_vec(force, "force")});
  });
}

ss_status ss_request_add_limit_constraint(ss_request* request, const ss_surface_point* p, const ss_vec3* displacement,
                                          const ss_vec3* du_displacement, const ss_vec3* dv_displacement) {
  return guard("ss_request_add_limit_constraint", [&] {
    const auto r = live(request, "request");
    LimitConstraint c;
    c.point = point(p, "point");
    c.displacement = request_vec(displacement, "displacement");
    if (du_displacement) c.du_displacement = request_vec(du_displacement, "du_displacement");
    if (dv_displacement) c.dv_displacement = request_vec(dv_displacement, "dv_displacement");
    add_valid(r->limit_constraints, std::move(c));
  });
}

ss_status ss_request_add_lagrange_constraint(ss_request* request, const int32_t* indices, const ss_vec3* coefficients,
                                             int32_t count, const ss_vec3* values) {
  return guard("ss_request_add_lagrange_constraint", [&] {
    const auto r = live(request, "request");
    if (count_arg(count, "count") == 0) fail(ErrorCode::kInvalidArgument, "a Lagrange constraint needs control points");
    required(indices, "indices");
    required(coefficients, "coefficients");
    LagrangeConstraint c;
    for (int32_t k = 0; k < count; ++k) {
      c.indices.push_back(indices[k]);
      c.coefficients.push_back(request_vec(&coefficients[k], "coefficients"));
    }
    c.values = request_vec(values, "values");
    add_valid(r->lagrange_constraints, std::move(c));
  });
}

ss_status ss_request_set_surface_load(ss_request* request, const ss_vec3* load_per_area) {
  return guard("ss_request_set_surface_load", [&] {
    const auto r = live(request, "request");
    const Vec3 load = request_vec(load_per_area, "load_per_area");
    validate_loads(load, r->pressure).value();
    r->surface_load = load;
  });
}

ss_status ss_request_set_pressure(ss_request* request, double pressure) {
  return guard("ss_request_set_pressure", [&] {
    const auto r = live(request, "request");
    validate_loads(r->surface_load, pressure).value();
    r->pressure = pressure;
  });
}

ss_status ss_request_set_model(ss_request* request, int32_t model) {
  return guard("ss_request_set_model", [&] {
    const auto r = live(request, "request");
    if (model != SS_MODEL_LINEAR && model != SS_MODEL_NONLINEAR) {
      throw CStatus{SS_INVALID_ARGUMENT,
                    "model is SS_MODEL_LINEAR (0) or SS_MODEL_NONLINEAR (1), got " + std::to_string(model)};
    }
    r->model = model == SS_MODEL_NONLINEAR ? DeformationModel::kNonlinear : DeformationModel::kLinear;
  });
}

ss_status ss_request_model(const ss_request* request, int32_t* out_model) {
  return guard("ss_request_model", [&] {
    const auto r = live(request, "request");
    required(out_model, "out_model");
    *out_model = r->model == DeformationModel::kNonlinear ? SS_MODEL_NONLINEAR : SS_MODEL_LINEAR;
  });
}

ss_status ss_request_counts(const ss_request* request, int32_t* out_vertex_constraints,
                            int32_t* out_lagrange_constraints, int32_t* out_forces, int32_t* out_limit_constraints,
                            int32_t* out_surface_forces) {
  return guard("ss_request_counts", [&] {
    const auto r = live(request, "request");
    if (out_vertex_constraints) *out_vertex_constraints = static_cast<int32_t>(r->vertex_constraints.size());
    if (out_lagrange_constraints) *out_lagrange_constraints = static_cast<int32_t>(r->lagrange_constraints.size());
    if (out_forces) *out_forces = static_cast<int32_t>(r->forces.size());
    if (out_limit_constraints) *out_limit_constraints = static_cast<int32_t>(r->limit_constraints.size());
    if (out_surface_forces) *out_surface_forces = static_cast<int32_t>(r->surface_forces.size());
  });
}

// ------------------------------------------------------------------------------------------------
// Floor contact

void ss_floor_options_default(ss_floor_options* out) {
  if (out) *out = ss_floor_options{-1.0, 0, 0};
}

ss_status ss_request_add_floor(ss_request* request, const ss_tessellation* tessellation, const ss_vec3* plane_point,
                               const ss_vec3* plane_normal, const ss_floor_options* options, int32_t* out_points,
                               int32_t* out_fixes_rigid_motion) {
  return guard("ss_request_add_floor", [&] {
    const auto r = live(request, "request");
    const auto t = live(tessellation, "tessellation");
    FloorOptions o;
    if (options) {
      o.tolerance = options->tolerance;
      o.axes = options->normal_only ? FloorAxes::kNormal : FloorAxes::kAll;
      o.snap = options->snap != 0;
    }
    const FloorContact contact =
        floor_contact(*t, Plane{vec(plane_point, "plane_point"), vec(plane_normal, "plane_normal")}, o).value();
    contact.add_to(*r);
    if (out_points) *out_points = static_cast<int32_t>(contact.points.size());
    if (out_fixes_rigid_motion) *out_fixes_rigid_motion = contact.fixes_rigid_motion ? 1 : 0;
  });
}

// ------------------------------------------------------------------------------------------------
// Grabs

void ss_grab_options_default(ss_grab_options* out) {
  if (out) *out = ss_grab_options{1, 0};
}

ss_status ss_grab_begin(const ss_evaluator* evaluator, const ss_surface_point* p, const double* current_xyz,
                        int32_t count, const ss_pose* hand, const ss_grab_options* options, ss_grab** out_grab) {
  return guard("ss_grab_begin", [&] {
    required(out_grab, "out_grab");
    *out_grab = nullptr;
    const auto ev = live(evaluator, "evaluator");
    GrabOptions o;
    if (options) {
      o.follow_rotation = options->follow_rotation != 0;
      o.constrain_tangents = options->constrain_tangents != 0;
    }
    const std::vector<Vec3> current = (current_xyz == nullptr && count == 0)
                                          ? ev->mesh().positions()
                                          : read_xyz(current_xyz, count, "current_xyz");
    *out_grab = make_handle<ss_grab>(
        std::make_shared<Grab>(Grab::begin(*ev, point(p, "point"), current, pose(hand, "hand"), o).value()));
  });
}

void ss_grab_destroy(ss_grab* grab) { destroy(grab, "ss_grab_destroy"); }

ss_status ss_grab_target(const ss_grab* grab, const ss_pose* hand, ss_vec3* out_target) {
  return guard("ss_grab_target", [&] {
    const auto g = live(grab, "grab");
    required(out_target, "out_target");
    *out_target = to_c(g->target(pose(hand, "hand")));
  });
}

ss_status ss_request_add_grab(ss_request* request, const ss_grab* grab, const ss_pose* hand) {
  return guard("ss_request_add_grab", [&] {
    const auto r = live(request, "request");
    const auto g = live(grab, "grab");
    r->limit_constraints.push_back(g->constraint(pose(hand, "hand")));
  });
}

}  // extern "C"
