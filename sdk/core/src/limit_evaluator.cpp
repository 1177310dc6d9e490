#include "softshell/limit_evaluator.h"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>

#include <opensubdiv/bfr/refinerSurfaceFactory.h>
#include <opensubdiv/far/error.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include "exact_limit.h"
#include "limit_evaluator_impl.h"
#include "softshell/mesh_validation.h"

namespace softshell {
namespace internal {
namespace {

// OpenSubdiv reports topology errors through a global callback; the default prints to stdout.
// We report through our own errors instead, so the callback only keeps the last message.
thread_local std::string g_last_osd_error;  // NOLINT(cppcoreguidelines-avoid-non-const-global-variables)

void install_osd_error_callback() {
  static std::once_flag once;
  std::call_once(once, [] {
    Far::SetErrorCallback([](Far::ErrorType, const char* message) { g_last_osd_error = message ? message : ""; });
    Far::SetWarningCallback([](const char*) {});
  });
}

}  // namespace

std::unique_ptr<Far::TopologyRefiner> make_refiner(const ControlMesh& mesh) {
  install_osd_error_callback();
  using Descriptor = Far::TopologyDescriptor;
  const std::vector<int32_t> sizes = mesh.face_sizes();
  std::vector<int32_t> crease_pairs;
  std::vector<float> crease_weights;
  for (const Crease& c : mesh.creases()) {
    crease_pairs.push_back(c.v0);
    crease_pairs.push_back(c.v1);
    crease_weights.push_back(c.sharpness);
  }
  std::vector<int32_t> corner_vertices;
  std::vector<float> corner_weights;
  for (const Corner& c : mesh.corners()) {
    corner_vertices.push_back(c.vertex);
    corner_weights.push_back(c.sharpness);
  }

  Descriptor desc;
  desc.numVertices = mesh.num_vertices();
  desc.numFaces = mesh.num_faces();
  desc.numVertsPerFace = sizes.data();
  desc.vertIndicesPerFace = mesh.face_indices().data();
  desc.numCreases = static_cast<int>(mesh.creases().size());
  desc.creaseVertexIndexPairs = crease_pairs.data();
  desc.creaseWeights = crease_weights.data();
  desc.numCorners = static_cast<int>(mesh.corners().size());
  desc.cornerVertexIndices = corner_vertices.data();
  desc.cornerWeights = corner_weights.data();

  OpenSubdiv::Sdc::Options sdc;
  sdc.SetVtxBoundaryInterpolation(mesh.boundary() == BoundaryMode::kNone
                                      ? OpenSubdiv::Sdc::Options::VTX_BOUNDARY_NONE
                                      : OpenSubdiv::Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
  sdc.SetFVarLinearInterpolation(OpenSubdiv::Sdc::Options::FVAR_LINEAR_ALL);

  Far::TopologyRefinerFactory<Descriptor>::Options options(OpenSubdiv::Sdc::SCHEME_CATMARK, sdc);
  g_last_osd_error.clear();
  std::unique_ptr<Far::TopologyRefiner> refiner(Far::TopologyRefinerFactory<Descriptor>::Create(desc, options));
  if (!refiner) {
    fail(ErrorCode::kUnprocessable,
         "OpenSubdiv cannot build this mesh's topology" +
             (g_last_osd_error.empty() ? std::string() : ": " + g_last_osd_error));
  }
  return refiner;
}

}  // namespace internal

namespace Bfr = internal::Bfr;
namespace Far = internal::Far;

Vec3 LimitSample::normal() const {
  Vec3 n = du.cross(dv);
  const double len = n.norm();
  return len > 0.0 ? Vec3(n / len) : Vec3::Zero();
}

Vec3 apply_weights(const std::vector<int32_t>& indices, const std::vector<double>& weights,
                   const std::vector<Vec3>& values) {
  Vec3 sum = Vec3::Zero();
  for (size_t k = 0; k < indices.size(); ++k) sum += weights[k] * values[static_cast<size_t>(indices[k])];
  return sum;
}

LimitEvaluator::LimitEvaluator(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
LimitEvaluator::~LimitEvaluator() = default;

Result<LimitEvaluator> LimitEvaluator::create(const ControlMesh& mesh, const Options& options) {
  return capture([&]() -> LimitEvaluator {
    if (options.approx_level_smooth < 1 || options.approx_level_smooth > 10 || options.approx_level_sharp < 1 ||
        options.approx_level_sharp > 10) {
      fail(ErrorCode::kInvalidArgument, "LimitEvaluator approximation levels must be between 1 and 10");
    }
    validate_mesh(mesh).value();

    auto impl = std::make_shared<Impl>();
    impl->mesh = mesh;
    if (!options.sharp_features) {
      impl->mesh.creases().clear();
      impl->mesh.corners().clear();
    }
    impl->options = options;
    impl->refiner = internal::make_refiner(impl->mesh);

    Bfr::SurfaceFactory::Options factory_options;
    factory_options.SetApproxLevelSmooth(options.approx_level_smooth);
    factory_options.SetApproxLevelSharp(options.approx_level_sharp);
    Bfr::RefinerSurfaceFactory<> factory(*impl->refiner, factory_options);
    impl->programs = std::make_shared<internal::FaceProgramStore>();
    const Far::TopologyLevel& base = impl->refiner->GetLevel(0);

    // With sharp features the whole surface is Bfr's (creases change the rules level by level;
    // mixing approximate and exact faces around one vertex would open cracks).
    const bool bfr_only = impl->mesh.has_sharpness();

    impl->faces.resize(static_cast<size_t>(mesh.num_faces()));
    std::vector<int32_t> sorted;
    internal::Neighbourhood hood;
    internal::PatchGrid grid;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      internal::FaceSurface& fs = impl->faces[static_cast<size_t>(f)];
      if (!factory.FaceHasLimitSurface(f)) continue;  // ghost face (BoundaryMode::kNone)
      fs.has_surface = true;
      // Exact unless regular (Bfr is exact there) or at a non-manifold or valence-2 vertex
      // (OpenSubdiv's own rules, Bfr's approximation).
      if (!bfr_only && !internal::regular_grid(base, f, 0, grid) && internal::extract_neighbourhood(base, f, 0, hood)) {
        fs.program = impl->programs->get(hood.signature);
        if (fs.program) {
          fs.support.assign(hood.vertices.begin(), hood.vertices.end());
          impl->max_support = std::max(impl->max_support, static_cast<int32_t>(fs.support.size()));
          continue;
        }
      }
      if (!factory.InitVertexSurface(f, &fs.surface)) {
        fail(ErrorCode::kUnprocessable, "OpenSubdiv could not set up the limit surface of face " + std::to_string(f));
      }
      fs.support.resize(static_cast<size_t>(fs.surface.GetNumControlPoints()));
      fs.surface.GetControlPointIndices(fs.support.data());
      sorted = fs.support;
      std::sort(sorted.begin(), sorted.end());
      fs.has_duplicates = std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end();
      impl->max_support = std::max(impl->max_support, static_cast<int32_t>(fs.support.size()));
      const Bfr::Parameterization param = fs.surface.GetParameterization();
      if (param.HasSubFaces()) {
        double a[2] = {0.0, 0.0}, b[2] = {1.0, 0.0}, ua[2], ub[2];
        param.ConvertNormalizedSubFaceToCoord(0, a, ua);
        param.ConvertNormalizedSubFaceToCoord(0, b, ub);
        fs.subface_scale = ub[0] - ua[0];
      }
    }
    return LimitEvaluator(std::move(impl));
  });
}

const ControlMesh& LimitEvaluator::mesh() const { return impl_->mesh; }
const LimitEvaluator::Options& LimitEvaluator::options() const { return impl_->options; }
int32_t LimitEvaluator::num_faces() const { return impl_->mesh.num_faces(); }
int32_t LimitEvaluator::num_control_points() const { return impl_->mesh.num_vertices(); }
int32_t LimitEvaluator::max_stencil_size() const { return impl_->max_support; }

int32_t LimitEvaluator::num_subfaces(int32_t face) const {
  const int32_t n = impl_->mesh.face_size(face);
  return n == 4 ? 1 : n;
}

bool LimitEvaluator::has_limit_surface(int32_t face) const {
  return face >= 0 && face < num_faces() && impl_->faces[static_cast<size_t>(face)].has_surface;
}

bool LimitEvaluator::is_regular(int32_t face) const {
  if (!has_limit_surface(face)) return false;
  const internal::FaceSurface& fs = impl_->faces[static_cast<size_t>(face)];
  return !fs.program && fs.surface.IsRegular();
}

bool LimitEvaluator::ev_corner_weights(int32_t face, int32_t subface, int corner, double cell_size, int gauss_points,
                                       std::vector<double>& weight_factors) const {
  if (!has_limit_surface(face) || subface < 0 || subface >= num_subfaces(face) || corner < 0 || corner > 3 ||
      !(cell_size > 0.0 && cell_size <= 1.0) || gauss_points < 1 || gauss_points > 16) {
    return false;
  }
  const internal::FaceSurface& fs = impl_->faces[static_cast<size_t>(face)];
  return fs.program && fs.program->corner_rule(subface, corner, cell_size, gauss_points, weight_factors);
}

bool LimitEvaluator::ev_corner_normal_weights(int32_t face, int32_t subface, int corner, double cell_size,
                                              const std::vector<Vec3>& positions, Eigen::Matrix3Xd& out) const {
  if (!has_limit_surface(face) || subface < 0 || subface >= num_subfaces(face) || corner < 0 || corner > 3 ||
      !(cell_size > 0.0 && cell_size <= 1.0) || positions.size() != static_cast<size_t>(num_control_points())) {
    return false;
  }
  const internal::FaceSurface& fs = impl_->faces[static_cast<size_t>(face)];
  if (!fs.program) return false;
  internal::RowMatrix x(static_cast<Eigen::Index>(fs.support.size()), 3), local;
  for (size_t k = 0; k < fs.support.size(); ++k) x.row(static_cast<Eigen::Index>(k)) = positions[static_cast<size_t>(fs.support[k])].transpose();
  if (!fs.program->corner_normal_integral(subface, corner, cell_size, x, local)) return false;
  out = local.transpose();
  return true;
}

std::vector<int32_t> LimitEvaluator::support(int32_t face) const {
  if (!has_limit_surface(face)) {
    fail(ErrorCode::kInvalidArgument, "face " + std::to_string(face) + " has no limit surface");
  }
  return impl_->faces[static_cast<size_t>(face)].support;
}

Result<void> LimitEvaluator::check(const SurfacePoint& p) const {
  auto bad = [](std::string message) { return Error{ErrorCode::kInvalidArgument, std::move(message)}; };
  if (p.face < 0 || p.face >= num_faces()) {
    return bad("face index " + std::to_string(p.face) + " is out of range (the mesh has " +
               std::to_string(num_faces()) + " faces)");
  }
  const int32_t subfaces = num_subfaces(p.face);
  if (p.subface < 0 || p.subface >= subfaces) {
    return bad("face " + std::to_string(p.face) + " has " + std::to_string(subfaces) + " sub-face" +
               (subfaces == 1 ? " (0)" : "s (0.." + std::to_string(subfaces - 1) + ")") + ", not " +
               std::to_string(p.subface));
  }
  if (!std::isfinite(p.u) || !std::isfinite(p.v) || p.u < 0.0 || p.u > 1.0 || p.v < 0.0 || p.v > 1.0) {
    return bad("(u, v) must lie in [0, 1] x [0, 1], got (" + std::to_string(p.u) + ", " + std::to_string(p.v) + ")");
  }
  if (!has_limit_surface(p.face)) {
    return bad("face " + std::to_string(p.face) +
               " touches the boundary of a mesh with boundary \"none\": it is a ghost face without limit surface");
  }
  return {};
}

void LimitEvaluator::Impl::bfr_coord(const SurfacePoint& p, double out_uv[2]) const {
  const Bfr::Surface<double>& surface = faces[static_cast<size_t>(p.face)].surface;
  const double uv[2] = {p.u, p.v};
  const Bfr::Parameterization param = surface.GetParameterization();
  if (param.HasSubFaces()) {
    param.ConvertNormalizedSubFaceToCoord(p.subface, uv, out_uv);
  } else {
    out_uv[0] = uv[0];
    out_uv[1] = uv[1];
  }
}

void LimitEvaluator::Impl::weights(const SurfacePoint& p, double* out, std::vector<double>& scratch) const {
  const internal::FaceSurface& fs = faces[static_cast<size_t>(p.face)];
  if (fs.program) {
    fs.program->evaluate(p.subface, p.u, p.v, out, scratch);
    return;
  }
  const size_t n = fs.support.size();
  double uv[2];
  bfr_coord(p, uv);
  fs.surface.EvaluateStencil(uv, out, out + n, out + 2 * n, out + 3 * n, out + 4 * n, out + 5 * n);
  // Derivatives with respect to the normalized sub-face coordinates (chain rule).
  const double s = fs.subface_scale;
  if (s != 1.0) {
    for (size_t k = n; k < 3 * n; ++k) out[k] *= s;
    for (size_t k = 3 * n; k < 6 * n; ++k) out[k] *= s * s;
  }
}

void LimitEvaluator::stencil(const SurfacePoint& p, LimitStencil& out) const {
  check(p).value();
  const internal::FaceSurface& fs = impl_->faces[static_cast<size_t>(p.face)];
  const size_t n = fs.support.size();
  out.indices = fs.support;
  thread_local std::vector<double> buffer, scratch;
  buffer.resize(6 * n);
  impl_->weights(p, buffer.data(), scratch);
  std::vector<double>* rows[6] = {&out.position, &out.du, &out.dv, &out.duu, &out.duv, &out.dvv};
  for (size_t d = 0; d < 6; ++d) rows[d]->assign(&buffer[d * n], &buffer[d * n] + n);
  if (fs.has_duplicates) {
    // Merge repeated control points so that every index appears once.
    LimitStencil merged;
    for (size_t k = 0; k < n; ++k) {
      auto it = std::find(merged.indices.begin(), merged.indices.end(), out.indices[k]);
      size_t j = static_cast<size_t>(it - merged.indices.begin());
      if (it == merged.indices.end()) {
        merged.indices.push_back(out.indices[k]);
        for (auto* w : {&merged.position, &merged.du, &merged.dv, &merged.duu, &merged.duv, &merged.dvv}) {
          w->push_back(0.0);
        }
      }
      merged.position[j] += out.position[k];
      merged.du[j] += out.du[k];
      merged.dv[j] += out.dv[k];
      merged.duu[j] += out.duu[k];
      merged.duv[j] += out.duv[k];
      merged.dvv[j] += out.dvv[k];
    }
    out = std::move(merged);
  }
}

LimitStencil LimitEvaluator::stencil(const SurfacePoint& p) const {
  LimitStencil out;
  stencil(p, out);
  return out;
}

void LimitEvaluator::face_stencils(int32_t face, int32_t subface, const std::vector<std::array<double, 2>>& uvs,
                                   std::vector<int32_t>& out_indices, Eigen::MatrixXd& out_weights) const {
  for (const auto& uv : uvs) check(SurfacePoint{face, subface, uv[0], uv[1]}).value();
  if (uvs.empty()) check(SurfacePoint{face, subface, 0.0, 0.0}).value();
  const internal::FaceSurface& fs = impl_->faces[static_cast<size_t>(face)];
  const size_t n = fs.support.size();
  // Unique control points (Bfr may list one twice on tiny closed meshes) and where each goes.
  std::vector<int32_t> column(n);
  out_indices.clear();
  for (size_t k = 0; k < n; ++k) {
    auto it = std::find(out_indices.begin(), out_indices.end(), fs.support[k]);
    column[k] = static_cast<int32_t>(it - out_indices.begin());
    if (it == out_indices.end()) out_indices.push_back(fs.support[k]);
  }
  if (fs.program) {  // every point of the face at once, no repeated control points
    thread_local internal::RowMatrix rows;
    fs.program->evaluate_many(subface, uvs.data(), uvs.size(), rows);
    out_weights = rows;
    return;
  }
  out_weights.setZero(static_cast<Eigen::Index>(6 * uvs.size()), static_cast<Eigen::Index>(out_indices.size()));
  std::vector<double> w(6 * n), scratch;
  for (size_t i = 0; i < uvs.size(); ++i) {
    impl_->weights(SurfacePoint{face, subface, uvs[i][0], uvs[i][1]}, w.data(), scratch);
    for (int d = 0; d < 6; ++d) {
      const auto row = static_cast<Eigen::Index>(6 * i + static_cast<size_t>(d));
      const double* src = &w[static_cast<size_t>(d) * n];
      for (size_t k = 0; k < n; ++k) out_weights(row, column[k]) += src[k];
    }
  }
}

void LimitEvaluator::Impl::evaluate_many(int32_t face, int32_t subface, const std::array<double, 2>* uvs,
                                         size_t count, const std::vector<Vec3>& positions, Vec3* out_position,
                                         Vec3* out_du, Vec3* out_dv, std::vector<double>& scratch) const {
  const internal::FaceSurface& fs = faces[static_cast<size_t>(face)];
  if (fs.program) {
    internal::RowMatrix rows;
    fs.program->evaluate_many(subface, uvs, count, rows);
    Eigen::MatrixX3d x(static_cast<Eigen::Index>(fs.support.size()), 3);
    for (size_t k = 0; k < fs.support.size(); ++k) {
      x.row(static_cast<Eigen::Index>(k)) = positions[static_cast<size_t>(fs.support[k])].transpose();
    }
    for (size_t i = 0; i < count; ++i) {
      const auto r = static_cast<Eigen::Index>(6 * i);
      out_position[i] = (rows.row(r) * x).transpose();
      if (out_du) out_du[i] = (rows.row(r + 1) * x).transpose();
      if (out_dv) out_dv[i] = (rows.row(r + 2) * x).transpose();
    }
    return;
  }
  const Bfr::Surface<double>& surface = fs.surface;
  const Bfr::Surface<double>::PointDescriptor desc(3);
  scratch.resize(3 * static_cast<size_t>(surface.GetNumPatchPoints()));
  surface.PreparePatchPoints(positions.front().data(), desc, scratch.data(), desc);
  const double s = fs.subface_scale;
  for (size_t i = 0; i < count; ++i) {
    double uv[2];
    bfr_coord(SurfacePoint{face, subface, uvs[i][0], uvs[i][1]}, uv);
    double p[3], du[3], dv[3];
    surface.Evaluate(uv, scratch.data(), desc, p, du, dv);
    out_position[i] = Vec3(p[0], p[1], p[2]);
    if (out_du) out_du[i] = s * Vec3(du[0], du[1], du[2]);
    if (out_dv) out_dv[i] = s * Vec3(dv[0], dv[1], dv[2]);
  }
}

LimitSample LimitEvaluator::evaluate(const SurfacePoint& p) const { return evaluate(p, impl_->mesh.positions()); }

LimitSample LimitEvaluator::evaluate(const SurfacePoint& p, const std::vector<Vec3>& positions) const {
  if (positions.size() != static_cast<size_t>(num_control_points())) {
    fail(ErrorCode::kInvalidArgument, "expected " + std::to_string(num_control_points()) + " control positions, got " +
                                          std::to_string(positions.size()));
  }
  LimitStencil st = stencil(p);
  LimitSample s;
  s.position = apply_weights(st.indices, st.position, positions);
  s.du = apply_weights(st.indices, st.du, positions);
  s.dv = apply_weights(st.indices, st.dv, positions);
  s.duu = apply_weights(st.indices, st.duu, positions);
  s.duv = apply_weights(st.indices, st.duv, positions);
  s.dvv = apply_weights(st.indices, st.dvv, positions);
  return s;
}

}  // namespace softshell
