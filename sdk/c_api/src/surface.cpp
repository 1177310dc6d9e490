// C ABI: the limit surface (evaluators), tessellations and picking.

#include <algorithm>
#include <string>
#include <vector>

#include "c_api_internal.h"
#include "softshell/softshell_c_bridge.h"

using namespace softshell;         // NOLINT(google-build-using-namespace): a .cpp of entry points
using namespace softshell::c_api;  // NOLINT(google-build-using-namespace)

extern "C" {

// ------------------------------------------------------------------------------------------------
// Limit surface

ss_status ss_evaluator_create(const ss_mesh* mesh, ss_evaluator** out_evaluator) {
  return guard("ss_evaluator_create", [&] {
    required(out_evaluator, "out_evaluator");
    *out_evaluator = nullptr;
    const auto m = live(mesh, "mesh");
    *out_evaluator = make_handle<ss_evaluator>(std::make_shared<LimitEvaluator>(LimitEvaluator::create(*m).value()));
  });
}

void ss_evaluator_destroy(ss_evaluator* evaluator) { destroy(evaluator, "ss_evaluator_destroy"); }

ss_status ss_evaluator_num_subfaces(const ss_evaluator* evaluator, int32_t face, int32_t* out_count) {
  return guard("ss_evaluator_num_subfaces", [&] {
    const auto ev = live(evaluator, "evaluator");
    required(out_count, "out_count");
    if (face < 0 || face >= ev->num_faces()) {
      fail(ErrorCode::kInvalidArgument,
           "face " + std::to_string(face) + " is out of range (" + std::to_string(ev->num_faces()) + " faces)");
    }
    *out_count = ev->num_subfaces(face);
  });
}

ss_status ss_evaluator_evaluate(const ss_evaluator* evaluator, const ss_surface_point* p, const double* positions_xyz,
                                int32_t count, ss_limit_sample* out_sample) {
  return guard("ss_evaluator_evaluate", [&] {
    const auto ev = live(evaluator, "evaluator");
    required(out_sample, "out_sample");
    const SurfacePoint sp = point(p, "point");
    ev->check(sp).value();
    const LimitSample s = (positions_xyz == nullptr && count == 0)
                              ? ev->evaluate(sp)
                              : ev->evaluate(sp, read_xyz(positions_xyz, count, "positions_xyz"));
    *out_sample = ss_limit_sample{to_c(s.position), to_c(s.du), to_c(s.dv), to_c(s.normal())};
  });
}

ss_status ss_evaluator_stencil(const ss_evaluator* evaluator, const ss_surface_point* p, int32_t* out_indices,
                               double* out_position, double* out_du, double* out_dv, int32_t capacity,
                               int32_t* out_count) {
  return guard("ss_evaluator_stencil", [&] {
    const auto ev = live(evaluator, "evaluator");
    const LimitStencil st = ev->stencil(point(p, "point"));
    write_items(out_indices, capacity, out_count, st.size(), "stencil", [&](int32_t* o) {
      std::copy(st.indices.begin(), st.indices.end(), o);
      if (out_position) std::copy(st.position.begin(), st.position.end(), out_position);
      if (out_du) std::copy(st.du.begin(), st.du.end(), out_du);
      if (out_dv) std::copy(st.dv.begin(), st.dv.end(), out_dv);
    });
  });
}

// ------------------------------------------------------------------------------------------------
// Tessellation

ss_status ss_tessellation_create(const ss_evaluator* evaluator, int32_t level, ss_tessellation** out) {
  return guard("ss_tessellation_create", [&] {
    required(out, "out");
    *out = nullptr;
    const auto ev = live(evaluator, "evaluator");
    *out = make_handle<ss_tessellation>(std::make_shared<Tessellation>(Tessellation::create(*ev, level).value()));
  });
}

void ss_tessellation_destroy(ss_tessellation* tessellation) { destroy(tessellation, "ss_tessellation_destroy"); }

ss_status ss_tessellation_counts(const ss_tessellation* tessellation, int32_t* out_num_vertices,
                                 int32_t* out_num_triangles) {
  return guard("ss_tessellation_counts", [&] {
    const auto t = live(tessellation, "tessellation");
    if (out_num_vertices) *out_num_vertices = static_cast<int32_t>(t->vertices().size());
    if (out_num_triangles) *out_num_triangles = static_cast<int32_t>(t->triangles().size());
  });
}

ss_status ss_tessellation_vertices(const ss_tessellation* tessellation, float* out_xyz, int32_t capacity,
                                   int32_t* out_count) {
  return guard("ss_tessellation_vertices", [&] {
    write_xyz_f(live(tessellation, "tessellation")->vertices(), out_xyz, capacity, out_count, "vertices");
  });
}

ss_status ss_tessellation_normals(const ss_tessellation* tessellation, float* out_xyz, int32_t capacity,
                                  int32_t* out_count) {
  return guard("ss_tessellation_normals", [&] {
    write_xyz_f(live(tessellation, "tessellation")->normals(), out_xyz, capacity, out_count, "normals");
  });
}

ss_status ss_tessellation_triangles(const ss_tessellation* tessellation, int32_t* out_indices, int32_t capacity,
                                    int32_t* out_count) {
  return guard("ss_tessellation_triangles", [&] {
    const auto t = live(tessellation, "tessellation");
    const auto& tris = t->triangles();
    write_items(out_indices, capacity, out_count, tris.size(), "triangles", [&](int32_t* o) {
      for (size_t i = 0; i < tris.size(); ++i) std::copy(tris[i].begin(), tris[i].end(), o + 3 * i);
    });
  });
}

ss_status ss_tessellation_update(ss_tessellation* tessellation, const double* positions_xyz, int32_t count) {
  return guard("ss_tessellation_update", [&] {
    const auto t = live(tessellation, "tessellation");
    t->update(read_xyz(positions_xyz, count, "positions_xyz"));
  });
}

// ------------------------------------------------------------------------------------------------
// Picking

ss_status ss_picker_create(ss_tessellation* tessellation, ss_picker** out_picker) {
  return guard("ss_picker_create", [&] {
    required(out_picker, "out_picker");
    *out_picker = nullptr;
    std::shared_ptr<Tessellation> t = live(tessellation, "tessellation");
    Picker picker = Picker::create(*t).value();
    *out_picker = make_handle<ss_picker>(std::make_shared<PickerObject>(PickerObject{std::move(t), std::move(picker)}));
  });
}

void ss_picker_destroy(ss_picker* picker) { destroy(picker, "ss_picker_destroy"); }

ss_status ss_picker_refit(ss_picker* picker) {
  return guard("ss_picker_refit", [&] { live(picker, "picker")->picker.refit().value(); });
}

ss_status ss_picker_pick(const ss_picker* picker, const ss_ray* ray, int32_t refine, ss_pick* out_pick,
                         int32_t* out_hit) {
  return guard("ss_picker_pick", [&] {
    const auto p = live(picker, "picker");
    required(ray, "ray");
    required(out_pick, "out_pick");
    required(out_hit, "out_hit");
    *out_hit = 0;
    Ray r;
    r.origin = Vec3(ray->origin.x, ray->origin.y, ray->origin.z);
    r.direction = Vec3(ray->direction.x, ray->direction.y, ray->direction.z);
    r.t_min = ray->t_min;
    r.t_max = ray->t_max;
    PickOptions options;
    options.refine = refine != 0;
    const auto pick = p->picker.pick(r, options).value();
    if (!pick) return;
    *out_hit = 1;
    ss_pick& o = *out_pick;
    o.triangle = pick->hit.triangle;
    o.status = static_cast<int32_t>(pick->status);
    o.estimate = to_c(pick->estimate);
    o.point = to_c(pick->point);
    o.position = to_c(pick->position);
    o.normal = to_c(pick->normal);
    o.du = to_c(pick->du);
    o.dv = to_c(pick->dv);
    o.t = pick->t;
    o.distance_to_ray = pick->distance_to_ray;
    o.triangle_t = pick->hit.t;
    o.iterations = pick->iterations;
    o.face_crossings = pick->face_crossings;
  });
}

}  // extern "C"
