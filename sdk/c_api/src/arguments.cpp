// Arguments in, buffers out: the conversions every entry point shares (c_api_internal.h).

#include <algorithm>
#include <cstring>
#include <string>

#include "c_api_internal.h"

namespace softshell::c_api {

int32_t count_arg(int32_t n, const char* argument) {
  if (n < 0) fail(ErrorCode::kInvalidArgument, std::string(argument) + " must not be negative");
  return n;
}

Vec3 vec(const ss_vec3* v, const char* argument) {
  required(v, argument);
  const Vec3 out(v->x, v->y, v->z);
  if (!out.allFinite()) fail(ErrorCode::kInvalidArgument, std::string(argument) + " is not finite");
  return out;
}

SurfacePoint point(const ss_surface_point* p, const char* argument) {
  required(p, argument);
  return SurfacePoint{p->face, p->subface, p->u, p->v};
}

Pose pose(const ss_pose* p, const char* argument) {
  required(p, argument);
  Pose out;
  out.position = Vec3(p->position.x, p->position.y, p->position.z);
  out.orientation = Eigen::Quaterniond(p->orientation.w, p->orientation.x, p->orientation.y, p->orientation.z);
  if (!out.position.allFinite() || !out.orientation.coeffs().allFinite() || out.orientation.coeffs().isZero(0.0)) {
    fail(ErrorCode::kInvalidArgument, std::string(argument) + " must be finite with a non-zero orientation");
  }
  return out;
}

std::vector<Vec3> read_xyz(const double* xyz, int32_t count, const char* argument) {
  count_arg(count, "count");
  if (count > 0) required(xyz, argument);
  std::vector<Vec3> out(static_cast<size_t>(count));
  for (size_t i = 0; i < out.size(); ++i) {
    out[i] = Vec3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (!out[i].allFinite()) {
      fail(ErrorCode::kInvalidArgument, std::string(argument) + ": point " + std::to_string(i) + " is not finite");
    }
  }
  return out;
}

GeomId geom_id(const ss_geom_id* id) {
  required(id, "id");
  GeomId out;
  std::memcpy(out.bytes.data(), id->bytes, 16);
  return out;
}

Material material(const ss_material* m, const char* argument) {
  required(m, argument);
  Material out;
  out.youngs_modulus = m->youngs_modulus;
  out.poisson_ratio = m->poisson_ratio;
  out.thickness = m->thickness;
  out.density = m->density;
  return out;
}

ss_material to_c(const Material& m) {
  return ss_material{m.youngs_modulus, m.poisson_ratio, m.thickness, m.density};
}

void write_xyz(const std::vector<Vec3>& points, double* out, int32_t capacity, int32_t* out_count, const char* what) {
  write_items(out, capacity, out_count, points.size(), what, [&](double* o) {
    for (size_t i = 0; i < points.size(); ++i) {
      o[3 * i] = points[i].x();
      o[3 * i + 1] = points[i].y();
      o[3 * i + 2] = points[i].z();
    }
  });
}

void write_model(const DeformationResult& r, int32_t* out_model, int32_t* out_iterations, double* out_residual) {
  const bool nonlinear = r.model == DeformationModel::kNonlinear;
  if (out_model) *out_model = nonlinear ? SS_MODEL_NONLINEAR : SS_MODEL_LINEAR;
  if (out_iterations) *out_iterations = nonlinear ? r.iterations : 0;
  if (out_residual) *out_residual = nonlinear ? r.residual : 0.0;
}

void write_xyz_f(const std::vector<Vec3>& points, float* out, int32_t capacity, int32_t* out_count, const char* what) {
  write_items(out, capacity, out_count, points.size(), what, [&](float* o) {
    for (size_t i = 0; i < points.size(); ++i) {
      o[3 * i] = static_cast<float>(points[i].x());
      o[3 * i + 1] = static_cast<float>(points[i].y());
      o[3 * i + 2] = static_cast<float>(points[i].z());
    }
  });
}

void write_string(std::string_view text, char* out, int32_t capacity) {
  if (out == nullptr || capacity <= 0) return;
  const size_t n = std::min(text.size(), static_cast<size_t>(capacity) - 1);
  std::memcpy(out, text.data(), n);
  out[n] = '\0';
}

}  // namespace softshell::c_api
