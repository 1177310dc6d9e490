#include "softshell/engine/shell_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>

#include <Eigen/Dense>

#include "softshell/disjoint_sets.h"
#include "softshell/executor.h"

#include "kirchhoff_love.h"
#include "quadrature.h"
#include "zero_modes.h"
#include "request_check.h"

namespace softshell::engine {

namespace {

// The element stiffness of one (sub-)face and its load integrals, in the face's local indices.
struct Element {
  std::vector<int32_t> indices;              // control points (unique)
  Eigen::MatrixXd stiffness;                 // 3m x 3m
  Eigen::MatrixXd gram;                      // m x m: sum over points of w_q N_A N_B (parameter weights)
  Eigen::VectorXd area_weights;              // m: integral of N_A dA
  Eigen::Matrix3Xd normal_weights;           // 3 x m: integral of N_A n dA
  std::vector<QuadraturePoint> points;       // its quadrature points (parameter weights)
  double area = 0.0;
};

struct FaceWork {
  int32_t face;
  int32_t subface;
  uint8_t corner_mask;
};

void integrate_element(const LimitEvaluator& evaluator, const Material& material, const QuadratureOptions& quad,
                       const FaceWork& work, Element& out) {
  internal::FaceRule rule;
  internal::face_rule(evaluator, quad, work.face, work.subface, work.corner_mask, rule);
  const std::vector<internal::Cell>& accepted = rule.cells;
  const std::vector<std::array<double, 2>>& uvs = rule.uvs;
  const std::vector<double>& weights = rule.weights;
  const std::vector<size_t>& first_point = rule.first_point;
  const Eigen::MatrixXd& basis = rule.basis;
  out.indices = rule.indices;
  Eigen::MatrixX3d x(static_cast<Eigen::Index>(out.indices.size()), 3);
  for (Eigen::Index a = 0; a < x.rows(); ++a) {
    x.row(a) = evaluator.mesh().positions()[static_cast<size_t>(out.indices[static_cast<size_t>(a)])].transpose();
  }
  const auto m = x.rows();

  out.area_weights.setZero(m);
  out.points.clear();
  out.area = 0.0;
  const double t = material.thickness;
  const double membrane = t, bending = t * t * t / 12.0;
  std::vector<char> exact_load;  // cells at an extraordinary vertex: their pressure load exactly
  out.normal_weights = internal::exact_corner_normal_weights(evaluator, work.face, work.subface, accepted, out.indices,
                                                             exact_load);
  std::vector<char> point_exact_load(uvs.size(), 0);
  for (size_t c = 0; c < accepted.size(); ++c) {
    std::fill(point_exact_load.begin() + static_cast<std::ptrdiff_t>(first_point[c]),
              point_exact_load.begin() + static_cast<std::ptrdiff_t>(first_point[c + 1]), exact_load[c]);
  }
  internal::SurfaceFrame frame;
  // K_e = sum over points of dA (Bm^T t C Bm + Bb^T t^3/12 C Bb). With C = L L^T, every term is
  // G_q^T G_q for G_q = [sqrt(dA t) L^T Bm; sqrt(dA t^3/12) L^T Bb]: the rows of all points are
  // stacked into G and K_e = G^T G is one symmetric rank update (far faster than a rank-3 update
  // per point, and symmetric by construction).
  Eigen::MatrixXd g(static_cast<Eigen::Index>(6 * uvs.size()), 3 * m);
  for (size_t q = 0; q < uvs.size(); ++q) {
    const auto w = basis.middleRows(static_cast<Eigen::Index>(6 * q), 6);
    const bool regular = internal::compute_frame(w, x, material.youngs_modulus, material.poisson_ratio, frame);
    // The material matrix is positive definite on a regular surface; a failed Cholesky factor means
    // a metric so distorted that it is not (numerically) one.
    const Eigen::LLT<Eigen::Matrix3d> material_factor(regular ? frame.material : Eigen::Matrix3d::Zero());
    if (!regular || material_factor.info() != Eigen::Success) {
      std::ostringstream msg;
      msg << "the limit surface of face " << work.face << " is degenerate at (u, v) = (" << uvs[q][0] << ", "
          << uvs[q][1] << ")" << (work.subface ? " of sub-face " + std::to_string(work.subface) : std::string())
          << ": its tangents are parallel; check the control points around that face";
      fail(ErrorCode::kUnprocessable, msg.str());
    }
    const double dA = weights[q] * frame.j;
    const Eigen::Matrix3d lt = material_factor.matrixU();
    internal::weighted_strain_rows(w, frame, std::sqrt(dA * membrane) * lt, std::sqrt(dA * bending) * lt,
                                   g.middleRows(static_cast<Eigen::Index>(6 * q), 6));
    out.area_weights.noalias() += dA * w.row(0).transpose();
    if (!point_exact_load[q]) out.normal_weights.noalias() += frame.a3 * (dA * w.row(0));
    out.area += dA;
    out.points.push_back({SurfacePoint{work.face, work.subface, uvs[q][0], uvs[q][1]}, weights[q]});
  }
  out.stiffness.setZero(3 * m, 3 * m);
  out.stiffness.selfadjointView<Eigen::Lower>().rankUpdate(g.transpose());
  out.stiffness.triangularView<Eigen::StrictlyUpper>() = out.stiffness.transpose();
  // The Gram matrix of the basis at the points, with the parameter weights: independent of the
  // geometry, the material and the thickness (it finds the motions that leave the surface where it is).
  Eigen::MatrixXd values(static_cast<Eigen::Index>(uvs.size()), m);
  for (size_t q = 0; q < uvs.size(); ++q) {
    values.row(static_cast<Eigen::Index>(q)) = std::sqrt(weights[q]) * basis.row(static_cast<Eigen::Index>(6 * q));
  }
  out.gram.setZero(m, m);
  out.gram.selfadjointView<Eigen::Lower>().rankUpdate(values.transpose());
  out.gram.triangularView<Eigen::StrictlyUpper>() = out.gram.transpose();
}

// Connected components by shared control points (union-find), then 6 rigid modes each.
void compute_rigid_modes(const ControlMesh& mesh, std::vector<int32_t>& component_of, Eigen::MatrixXd& modes) {
  const auto n = static_cast<size_t>(mesh.num_vertices());
  DisjointSets parts(n);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 1; i < fv.size(); ++i) parts.unite(fv[0], fv[i]);
  }
  int32_t components = 0;
  component_of = parts.labels(components);
  // Centroid and size of every component.
  std::vector<Vec3> centre(static_cast<size_t>(components), Vec3::Zero());
  std::vector<int32_t> count(static_cast<size_t>(components), 0);
  for (size_t v = 0; v < n; ++v) {
    centre[static_cast<size_t>(component_of[v])] += mesh.positions()[v];
    ++count[static_cast<size_t>(component_of[v])];
  }
  for (size_t c = 0; c < centre.size(); ++c) centre[c] /= count[c];
  std::vector<double> size(static_cast<size_t>(components), 0.0);
  for (size_t v = 0; v < n; ++v) {
    const auto c = static_cast<size_t>(component_of[v]);
    size[c] = std::max(size[c], (mesh.positions()[v] - centre[c]).norm());
  }
  modes.setZero(static_cast<Eigen::Index>(3 * n), 6 * components);
  for (size_t v = 0; v < n; ++v) {
    const auto c = static_cast<size_t>(component_of[v]);
    const Vec3 r = (mesh.positions()[v] - centre[c]) / (size[c] > 0.0 ? size[c] : 1.0);
    const Eigen::Index row = static_cast<Eigen::Index>(3 * v), col = static_cast<Eigen::Index>(6 * c);
    for (int a = 0; a < 3; ++a) {
      modes(row + a, col + a) = 1.0;
      Vec3 axis = Vec3::Zero();
      axis[a] = 1.0;
      modes.block<3, 1>(row, col + 3 + a) = axis.cross(r);
    }
  }
}

}  // namespace

// Builds ShellModels; a friend of ShellModel so the result can stay immutable afterwards.
class ShellModelBuilder {
 public:
  static std::shared_ptr<const ShellModel> build(const ControlMesh& mesh, const Material& material,
                                                 const PrecomputeOptions& options);
};

namespace {
std::atomic<uint64_t> g_next_model_id{1};
}  // namespace

ShellModel::ShellModel(LimitEvaluator evaluator, Material material, PrecomputeOptions options)
    : id_(g_next_model_id++),
      evaluator_(std::move(evaluator)), material_(material), options_(std::move(options)) {}

std::shared_ptr<const ShellModel> ShellModelBuilder::build(const ControlMesh& mesh, const Material& material,
                                                           const PrecomputeOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  material.check().value();
  const QuadratureOptions& quad = options.quadrature;
  if (quad.gauss_points < 1 || quad.gauss_points > 10 || quad.ev_ring_gauss_points < 0 ||
      quad.ev_ring_gauss_points > 10 || quad.ev_refinement_levels < 0 ||
      quad.ev_refinement_levels > 8 || quad.max_distortion_splits < 0 || quad.max_distortion_splits > 6 ||
      !std::isfinite(quad.max_cell_distortion) || (quad.max_cell_distortion != 0.0 && quad.max_cell_distortion < 1.0)) {
    fail(ErrorCode::kInvalidArgument,
         "quadrature: gauss_points must be 1..10, ev_ring_gauss_points 0..10, ev_refinement_levels 0..8, max_distortion_splits 0..6 and "
         "max_cell_distortion 0 (off) or at least 1");
  }
  // Sharp creases and corners make the limit surface C0 (or nearly so) along them: a
  // Kirchhoff-Love shell needs C1, and across a kink it would act as a hinge (near-zero bending
  // stiffness, ill-conditioned K). The simulation therefore uses the smooth surface of the same
  // control mesh; see README "Limits of the model".
  ControlMesh smooth = mesh;
  smooth.creases().clear();
  smooth.corners().clear();
  LimitEvaluator evaluator = LimitEvaluator::create(smooth, options.evaluator).value();
  std::shared_ptr<ShellModel> model(new ShellModel(evaluator, material, options));
  model->options_.progress = nullptr;  // do not keep the caller's callback (and what it captures)
  model->options_.cancel = nullptr;

  // The (face, sub-face) domains to integrate; ghost faces have no surface.
  const internal::IrregularCorners irregular(smooth);
  std::vector<FaceWork> work;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (!evaluator.has_limit_surface(f)) continue;
    for (int32_t s = 0; s < evaluator.num_subfaces(f); ++s) work.push_back({f, s, irregular.corners(f, s)});
  }
  if (work.empty()) fail(ErrorCode::kUnprocessable, "the mesh has no face with a limit surface");

  // Sparsity pattern at control point level: A and B are coupled if some face's support has both.
  const auto n = static_cast<size_t>(mesh.num_vertices());
  std::vector<std::vector<int32_t>> neighbours(n);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (!evaluator.has_limit_surface(f)) continue;
    std::vector<int32_t> support = evaluator.support(f);
    std::sort(support.begin(), support.end());
    support.erase(std::unique(support.begin(), support.end()), support.end());
    for (int32_t b : support) {
      auto& list = neighbours[static_cast<size_t>(b)];
      list.insert(list.end(), support.begin(), support.end());
    }
  }
  std::vector<int64_t> column_start(3 * n + 1, 0);
  for (size_t b = 0; b < n; ++b) {
    auto& list = neighbours[b];
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    for (int i = 0; i < 3; ++i) column_start[3 * b + static_cast<size_t>(i) + 1] = static_cast<int64_t>(3 * list.size());
  }
  for (size_t c = 0; c < 3 * n; ++c) column_start[c + 1] += column_start[c];
  const int64_t nnz = column_start.back();
  if (nnz > std::numeric_limits<int32_t>::max()) {
    fail(ErrorCode::kResourceExhausted, "the stiffness matrix would have more than 2^31 entries");
  }
  Eigen::SparseMatrix<double>& k = model->stiffness_;
  k.resize(static_cast<Eigen::Index>(3 * n), static_cast<Eigen::Index>(3 * n));
  k.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  for (size_t c = 0; c <= 3 * n; ++c) k.outerIndexPtr()[c] = static_cast<int>(column_start[c]);
  for (size_t b = 0; b < n; ++b) {
    const auto& list = neighbours[b];
    for (int i = 0; i < 3; ++i) {
      int* rows = k.innerIndexPtr() + column_start[3 * b + static_cast<size_t>(i)];
      for (size_t r = 0; r < list.size(); ++r) {
        for (int a = 0; a < 3; ++a) rows[3 * r + static_cast<size_t>(a)] = 3 * list[r] + a;
      }
    }
  }
  std::fill(k.valuePtr(), k.valuePtr() + nnz, 0.0);
  // The scalar Gram matrix of the basis (zero-mode analysis), on the control-point pattern.
  Eigen::SparseMatrix<double> gram(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  {
    std::vector<int> starts(n + 1, 0);
    for (size_t b = 0; b < n; ++b) starts[b + 1] = starts[b] + static_cast<int>(neighbours[b].size());
    gram.resizeNonZeros(starts.back());
    std::copy(starts.begin(), starts.end(), gram.outerIndexPtr());
    for (size_t b = 0; b < n; ++b) std::copy(neighbours[b].begin(), neighbours[b].end(), gram.innerIndexPtr() + starts[b]);
    std::fill(gram.valuePtr(), gram.valuePtr() + starts.back(), 0.0);
  }

  // Elements in fixed-size batches: computed in parallel, accumulated in face order, so K is
  // bit-for-bit the same for any number of threads.
  Executor& executor = options.executor ? *options.executor : *default_executor();
  constexpr size_t kBatch = 128;
  std::vector<Element> batch(kBatch);
  Eigen::VectorXd area_weights = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(n));
  Eigen::VectorXd normal_weights = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * n));
  double area = 0.0;
  std::vector<int64_t> offset;  // position of each local block column in K's value array
  for (size_t begin = 0; begin < work.size(); begin += kBatch) {
    if (options.cancel && options.cancel->load()) fail(ErrorCode::kCancelled, "precomputation cancelled");
    const size_t count = std::min(kBatch, work.size() - begin);
    executor.parallel_for(0, static_cast<int64_t>(count), [&](int64_t i) {
      integrate_element(evaluator, material, quad, work[begin + static_cast<size_t>(i)], batch[static_cast<size_t>(i)]);
    }, options.threads);
    for (size_t i = 0; i < count; ++i) {
      const Element& e = batch[i];
      const auto m = e.indices.size();
      for (size_t bl = 0; bl < m; ++bl) {
        const int32_t b = e.indices[bl];
        const auto& list = neighbours[static_cast<size_t>(b)];
        for (size_t al = 0; al < m; ++al) {
          const int32_t a = e.indices[al];
          const auto rank = static_cast<int64_t>(std::lower_bound(list.begin(), list.end(), a) - list.begin());
          for (int j = 0; j < 3; ++j) {
            double* column = k.valuePtr() + column_start[3 * static_cast<size_t>(b) + static_cast<size_t>(j)] + 3 * rank;
            for (int ii = 0; ii < 3; ++ii) {
              column[ii] += e.stiffness(static_cast<Eigen::Index>(3 * al) + ii, static_cast<Eigen::Index>(3 * bl) + j);
            }
          }
          gram.valuePtr()[gram.outerIndexPtr()[b] + rank] += e.gram(static_cast<Eigen::Index>(al), static_cast<Eigen::Index>(bl));
        }
        area_weights[b] += e.area_weights[static_cast<Eigen::Index>(bl)];
        normal_weights.segment<3>(3 * b) += e.normal_weights.col(static_cast<Eigen::Index>(bl));
      }
      area += e.area;
      model->quadrature_.insert(model->quadrature_.end(), e.points.begin(), e.points.end());
    }
    if (options.progress) options.progress(static_cast<double>(begin + count) / static_cast<double>(work.size()));
  }
  for (Eigen::Index i = 0; i < nnz; ++i) {
    if (!std::isfinite(k.valuePtr()[i])) {
      fail(ErrorCode::kUnprocessable, "the stiffness matrix has non-finite entries: the geometry or material is degenerate");
    }
  }
  compute_rigid_modes(mesh, model->component_of_, model->rigid_modes_);
  internal::check_surface_connected(smooth, evaluator, model->component_of_);
  internal::find_extra_zero_modes(gram, model->component_of_, model->rigid_modes_, model->zero_modes_, model->invisible_);
  for (Eigen::Index mode = 0; mode < model->zero_modes_.cols(); ++mode) {
    Eigen::Index dof = 0;
    model->zero_modes_.col(mode).cwiseAbs().maxCoeff(&dof);
    model->mode_component_.push_back(model->component_of_[static_cast<size_t>(dof / 3)]);
  }
  model->area_weights_ = std::move(area_weights);
  model->normal_weights_ = std::move(normal_weights);
  model->area_ = area;
  model->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return model;
}

Result<std::shared_ptr<const ShellModel>> ShellModel::build(const ControlMesh& mesh, const Material& material,
                                                            const PrecomputeOptions& options) {
  return capture([&] { return ShellModelBuilder::build(mesh, material, options); });
}

double ShellModel::strain_energy(const Eigen::VectorXd& displacement) const {
  if (displacement.size() != stiffness_.rows()) {
    fail(ErrorCode::kInvalidArgument, "strain_energy: the displacement vector must have 3n entries");
  }
  return 0.5 * displacement.dot(stiffness_ * displacement);
}

Eigen::VectorXd ShellModel::load_vector(const DeformationRequest& request) const {
  internal::check_loads(*this, request);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(num_dofs());
  for (const PointForce& pf : request.forces) f.segment<3>(3 * pf.index) += pf.force;
  LimitStencil st;
  for (const SurfaceForce& sf : request.surface_forces) {
    evaluator_.stencil(sf.point, st);
    for (size_t k = 0; k < st.size(); ++k) f.segment<3>(3 * st.indices[k]) += st.position[k] * sf.force;
  }
  if (!request.surface_load.isZero(0.0)) {
    for (Eigen::Index a = 0; a < area_weights_.size(); ++a) f.segment<3>(3 * a) += area_weights_[a] * request.surface_load;
  }
  if (request.pressure != 0.0) f += request.pressure * normal_weights_;
  return f;
}

size_t ShellModel::memory_bytes() const {
  const auto nnz = static_cast<size_t>(stiffness_.nonZeros());
  return sizeof(ShellModel) + nnz * (sizeof(double) + sizeof(int)) +
         static_cast<size_t>(stiffness_.cols() + 1) * sizeof(int) + quadrature_.size() * sizeof(QuadraturePoint) +
         static_cast<size_t>(area_weights_.size() + normal_weights_.size()) * sizeof(double) +
         static_cast<size_t>(rigid_modes_.size() + zero_modes_.size()) * sizeof(double) +
         (invisible_.size() + 7) / 8 + (mode_component_.size() + component_of_.size()) * sizeof(int32_t) +
         // the evaluator's mesh copy and Bfr surfaces (estimate)
         static_cast<size_t>(mesh().num_vertices()) * 24 + mesh().face_indices().size() * 4 +
         static_cast<size_t>(mesh().num_faces()) * 512;
}

size_t ShellModel::estimate_memory_bytes(const ControlMesh& mesh, const PrecomputeOptions& options) {
  const auto n = static_cast<size_t>(mesh.num_vertices());
  const int32_t faces = mesh.num_faces();
  // Faces around each control point (CSR).
  std::vector<int32_t> start(n + 1, 0), around;
  for (int32_t f = 0; f < faces; ++f) {
    for (int32_t v : mesh.face(f)) ++start[static_cast<size_t>(v) + 1];
  }
  for (size_t v = 0; v < n; ++v) start[v + 1] += start[v];
  around.resize(static_cast<size_t>(start[n]));
  {
    std::vector<int32_t> fill(start.begin(), start.end() - 1);
    for (int32_t f = 0; f < faces; ++f) {
      for (int32_t v : mesh.face(f)) around[static_cast<size_t>(fill[static_cast<size_t>(v)]++)] = f;
    }
  }
  // A face's support (its limit patch's control points) is its one-ring: the corners of every
  // face that shares a corner with it. The builder's pattern couples A and B if one support has
  // both, so B's column has the union of the supports that contain B: those of the faces
  // sharing a corner with a face around B.
  std::vector<int32_t> ring_start(static_cast<size_t>(faces) + 1, 0), rings;
  std::vector<int32_t> mark(n, -1);
  for (int32_t f = 0; f < faces; ++f) {
    for (int32_t c : mesh.face(f)) {
      for (int32_t k = start[static_cast<size_t>(c)]; k < start[static_cast<size_t>(c) + 1]; ++k) {
        for (int32_t v : mesh.face(around[static_cast<size_t>(k)])) {
          if (mark[static_cast<size_t>(v)] != f) {
            mark[static_cast<size_t>(v)] = f;
            rings.push_back(v);
          }
        }
      }
    }
    ring_start[static_cast<size_t>(f) + 1] = static_cast<int32_t>(rings.size());
  }
  std::fill(mark.begin(), mark.end(), -1);
  std::vector<int32_t> face_mark(static_cast<size_t>(faces), -1);
  size_t pairs = 0;  // nonzero 3x3 blocks of K
  for (size_t b = 0; b < n; ++b) {
    const auto self = static_cast<int32_t>(b);
    for (int32_t k = start[b]; k < start[b + 1]; ++k) {
      for (int32_t c : mesh.face(around[static_cast<size_t>(k)])) {
        for (int32_t j = start[static_cast<size_t>(c)]; j < start[static_cast<size_t>(c) + 1]; ++j) {
          const int32_t f = around[static_cast<size_t>(j)];
          if (face_mark[static_cast<size_t>(f)] == self) continue;
          face_mark[static_cast<size_t>(f)] = self;
          for (int32_t r = ring_start[static_cast<size_t>(f)]; r < ring_start[static_cast<size_t>(f) + 1]; ++r) {
            const int32_t a = rings[static_cast<size_t>(r)];
            if (mark[static_cast<size_t>(a)] != self) {
              mark[static_cast<size_t>(a)] = self;
              ++pairs;
            }
          }
        }
      }
    }
  }
  // Quadrature points: a Gauss rule per (sub-)face, plus the refinement rings at extraordinary
  // corners (3 cells per level each) and room for cells split for distortion (a third more).
  const QuadratureOptions& q = options.quadrature;
  const size_t gauss = static_cast<size_t>(q.gauss_points) * static_cast<size_t>(q.gauss_points);
  const size_t ring = q.ev_ring_gauss_points > 0
                          ? static_cast<size_t>(q.ev_ring_gauss_points) * static_cast<size_t>(q.ev_ring_gauss_points)
                          : gauss;
  size_t points = 0;
  for (int32_t f = 0; f < faces; ++f) {
    const auto corners = mesh.face(f);
    const size_t sub = corners.size() == 4 ? 1 : corners.size();
    size_t irregular = corners.size() == 4 ? 0 : 1;  // the sub-faces of an n-gon meet at its centre
    for (int32_t c : corners) {
      const int32_t valence = start[static_cast<size_t>(c) + 1] - start[static_cast<size_t>(c)];
      if (valence != 4) ++irregular;  // boundary corners too: conservative
    }
    points += sub * (gauss + std::min<size_t>(irregular, 4) * static_cast<size_t>(q.ev_refinement_levels) * 3 * ring);
  }
  points += points / 3;
  const size_t components = 1;  // rigid modes: 6 per connected component; one assumed, more are rare
  return sizeof(ShellModel) + pairs * 9 * (sizeof(double) + sizeof(int)) + (3 * n + 1) * sizeof(int) +
         points * sizeof(QuadraturePoint) + 4 * n * sizeof(double) + 3 * n * 6 * components * sizeof(double) +
         n * (2 * sizeof(int32_t)) + n * 24 + mesh.face_indices().size() * 4 + static_cast<size_t>(faces) * 512;
}

}  // namespace softshell::engine
