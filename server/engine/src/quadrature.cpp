#include "quadrature.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace softshell::engine::internal {

IrregularCorners::IrregularCorners(const ControlMesh& mesh) : mesh_(mesh) {
  // Valence (faces around a vertex) and boundary status from the edges.
  const auto n = static_cast<size_t>(mesh.num_vertices());
  std::vector<int32_t> faces_around(n, 0);
  std::map<std::pair<int32_t, int32_t>, int> edge_faces;
  next_to_non_quad_.assign(n, 0);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      ++faces_around[static_cast<size_t>(fv[i])];
      if (fv.size() != 4) next_to_non_quad_[static_cast<size_t>(fv[i])] = 1;
      const int32_t a = fv[i], b = fv[(i + 1) % fv.size()];
      ++edge_faces[{std::min(a, b), std::max(a, b)}];
    }
  }
  std::vector<char> on_boundary(n, 0);
  for (const auto& [edge, count] : edge_faces) {
    if (count == 1) on_boundary[static_cast<size_t>(edge.first)] = on_boundary[static_cast<size_t>(edge.second)] = 1;
  }
  irregular_vertex_.assign(n, 0);
  for (size_t v = 0; v < n; ++v) {
    // Regular: interior with 4 faces, boundary with 2 faces (smooth boundary) or 1 face (corner).
    const bool regular = on_boundary[v] ? (faces_around[v] == 2 || faces_around[v] == 1) : faces_around[v] == 4;
    irregular_vertex_[v] = regular ? 0 : 1;
  }
  // Sharp features change the patch structure around them too.
  for (const Crease& c : mesh.creases()) {
    if (c.sharpness > 0.0f) irregular_vertex_[static_cast<size_t>(c.v0)] = irregular_vertex_[static_cast<size_t>(c.v1)] = 1;
  }
  for (const Corner& c : mesh.corners()) {
    if (c.sharpness > 0.0f) irregular_vertex_[static_cast<size_t>(c.vertex)] = 1;
  }
}

uint8_t IrregularCorners::corners(int32_t face, int32_t subface) const {
  auto fv = mesh_.face(face);
  if (fv.size() == 4) {
    uint8_t mask = 0;
    for (int c = 0; c < 4; ++c) {
      const auto v = static_cast<size_t>(fv[static_cast<size_t>(c)]);
      if (irregular_vertex_[v]) mask |= static_cast<uint8_t>(1u << c);
      if (next_to_non_quad_[v]) mask |= kSplitOnce;
    }
    return mask;
  }
  // Sub-face k of an n-gon: corner (0,0) is control point k, (1,1) the face centre, which is an
  // extraordinary vertex of valence n after the first refinement.
  uint8_t mask = 1u << 2;
  if (irregular_vertex_[static_cast<size_t>(fv[static_cast<size_t>(subface)])]) mask |= 1u;
  return mask;
}

namespace {

// Splits a cell while it touches an irregular corner of the unit square and levels remain. The
// small cells of the rings get the ring rule.
void refine(const Cell& cell, int levels, uint8_t mask, int ring_gauss_points, std::vector<Cell>& out) {
  const std::array<std::array<double, 2>, 4> corner = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
  bool touches = false;
  for (int c = 0; c < 4; ++c) {
    if (!(mask & (1u << c))) continue;
    const double cu = corner[static_cast<size_t>(c)][0], cv = corner[static_cast<size_t>(c)][1];
    touches |= (cu == cell.u0 || cu == cell.u0 + cell.size) && (cv == cell.v0 || cv == cell.v0 + cell.size);
  }
  if (!touches || levels == 0) {
    out.push_back(cell);
    if (!touches && cell.size <= kSmallRingCellSize) out.back().gauss_points = ring_gauss_points;
    return;
  }
  for (const Cell& child : split(cell)) refine(child, levels - 1, mask, ring_gauss_points, out);
}

}  // namespace

std::array<Cell, 4> split(const Cell& cell) {
  const double h = 0.5 * cell.size;
  std::array<Cell, 4> out;
  out[0].u0 = cell.u0, out[0].v0 = cell.v0;
  out[1].u0 = cell.u0 + h, out[1].v0 = cell.v0;
  out[2].u0 = cell.u0 + h, out[2].v0 = cell.v0 + h;
  out[3].u0 = cell.u0, out[3].v0 = cell.v0 + h;
  for (Cell& c : out) c.size = h, c.gauss_points = cell.gauss_points;
  if (cell.ev_corner >= 0) {  // the quarter at the corner (quarter k sits at corner k)
    Cell& at_corner = out[static_cast<size_t>(cell.ev_corner)];
    at_corner.ev_corner = cell.ev_corner;
    at_corner.weight_factors = cell.weight_factors;
  }
  return out;
}

void face_cells(const LimitEvaluator& evaluator, int32_t face, int32_t subface, int gauss_points,
                int ring_gauss_points, int levels, uint8_t corner_mask, std::vector<Cell>& out) {
  out.clear();
  const auto corners = static_cast<uint8_t>(corner_mask & 0xfu);
  if ((corner_mask & kSplitOnce) && !(corners && levels > 0)) {
    for (const Cell& quarter : split(Cell{})) out.push_back(quarter);
  } else {
    refine(Cell{}, corners ? levels : 0, corners, ring_gauss_points == gauss_points ? 0 : ring_gauss_points, out);
  }
  // The face's rule first: the nonlinear model reads runs of gauss_points^2 points as cells.
  std::stable_partition(out.begin(), out.end(), [](const Cell& cell) { return cell.gauss_points == 0; });
  // The cells at an extraordinary corner.
  for (Cell& cell : out) {
    for (int c = 0; c < 4; ++c) {
      if (!(corners & (1u << c))) continue;
      const double cu = (c == 1 || c == 2) ? 1.0 : 0.0, cv = (c >= 2) ? 1.0 : 0.0;
      const bool at = (cell.u0 == cu || cell.u0 + cell.size == cu) && (cell.v0 == cv || cell.v0 + cell.size == cv);
      if (at && evaluator.ev_corner_weights(face, subface, c, cell.size, gauss_points, cell.weight_factors)) {
        cell.ev_corner = c;
        break;
      }
    }
  }
}

void cell_points(const std::vector<Cell>& cells, int gauss_points, std::vector<std::array<double, 2>>& out_uv,
                 std::vector<double>& out_weight, std::vector<size_t>& first_point) {
  out_uv.clear();
  out_weight.clear();
  first_point.assign(1, 0);
  for (const Cell& cell : cells) {
    const GaussRule& rule = gauss_legendre(cell.gauss_points > 0 ? cell.gauss_points : gauss_points);
    const size_t g = rule.points.size();
    const bool factors = cell.weight_factors.size() == g * g;
    for (size_t j = 0; j < g; ++j) {
      for (size_t i = 0; i < g; ++i) {
        out_uv.push_back({cell.u0 + cell.size * rule.points[i], cell.v0 + cell.size * rule.points[j]});
        out_weight.push_back(cell.size * cell.size * rule.weights[i] * rule.weights[j] *
                             (factors ? cell.weight_factors[i + g * j] : 1.0));
      }
    }
    first_point.push_back(out_uv.size());
  }
}

namespace {

// max/min over the points of one cell of the area element and of both tangents' lengths (1 for
// a uniform parametrization).
double cell_distortion(const Eigen::MatrixXd& basis, const Eigen::MatrixX3d& x, Eigen::Index first_point,
                       Eigen::Index points) {
  Eigen::Vector3d low = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d high = Eigen::Vector3d::Zero();
  for (Eigen::Index q = first_point; q < first_point + points; ++q) {
    const Eigen::RowVector3d a1 = basis.row(6 * q + 1) * x, a2 = basis.row(6 * q + 2) * x;
    const Eigen::Vector3d size(a1.cross(a2).norm(), a1.norm(), a2.norm());
    low = low.cwiseMin(size);
    high = high.cwiseMax(size);
  }
  if (!(low.minCoeff() > 0.0)) return std::numeric_limits<double>::infinity();
  return high.cwiseQuotient(low).maxCoeff();
}

}  // namespace

void face_rule(const LimitEvaluator& evaluator, const QuadratureOptions& quad, int32_t face, int32_t subface,
               uint8_t corner_mask, FaceRule& out) {
  // The cells: dyadic toward extraordinary corners, then split where the parametrization is far
  // from uniform, one round of stencil evaluations per split level.
  std::vector<Cell> cells, next;
  out.cells.clear();
  face_cells(evaluator, face, subface, quad.gauss_points, quad.ev_ring_gauss_points, quad.ev_refinement_levels,
             corner_mask, cells);
  Eigen::MatrixX3d x;
  bool split_any = false;
  for (int round = 0;; ++round) {
    cell_points(cells, quad.gauss_points, out.uvs, out.weights, out.first_point);
    evaluator.face_stencils(face, subface, out.uvs, out.indices, out.basis);
    if (round == 0) {
      x.resize(static_cast<Eigen::Index>(out.indices.size()), 3);
      for (Eigen::Index a = 0; a < x.rows(); ++a) {
        x.row(a) = evaluator.mesh().positions()[static_cast<size_t>(out.indices[static_cast<size_t>(a)])].transpose();
      }
    }
    if (quad.max_cell_distortion <= 0.0 || round == quad.max_distortion_splits) {
      out.cells.insert(out.cells.end(), cells.begin(), cells.end());
      break;
    }
    next.clear();
    for (size_t c = 0; c < cells.size(); ++c) {
      // Cells at an extraordinary vertex are never uniform; their rule is made for them.
      if (cells[c].ev_corner < 0 &&
          cell_distortion(out.basis, x, static_cast<Eigen::Index>(out.first_point[c]),
                          static_cast<Eigen::Index>(out.first_point[c + 1] - out.first_point[c])) >
              quad.max_cell_distortion) {
        const auto quarters = split(cells[c]);
        next.insert(next.end(), quarters.begin(), quarters.end());
      } else {
        out.cells.push_back(cells[c]);
      }
    }
    if (next.empty()) break;
    split_any = true;
    cells.swap(next);
  }
  if (split_any) {  // the stencils of the final cells, in one evaluation
    cell_points(out.cells, quad.gauss_points, out.uvs, out.weights, out.first_point);
    evaluator.face_stencils(face, subface, out.uvs, out.indices, out.basis);
  }
}

Eigen::Matrix3Xd exact_corner_normal_weights(const LimitEvaluator& evaluator, int32_t face, int32_t subface,
                                             const std::vector<Cell>& cells, const std::vector<int32_t>& indices,
                                             std::vector<char>& exact) {
  Eigen::Matrix3Xd sum = Eigen::Matrix3Xd::Zero(3, static_cast<Eigen::Index>(indices.size()));
  exact.assign(cells.size(), 0);
  std::vector<int32_t> support;
  Eigen::Matrix3Xd cell_weights;
  for (size_t c = 0; c < cells.size(); ++c) {
    const Cell& cell = cells[c];
    if (cell.ev_corner < 0 || !evaluator.ev_corner_normal_weights(face, subface, cell.ev_corner, cell.size,
                                                                  evaluator.mesh().positions(), cell_weights)) {
      continue;
    }
    if (support.empty()) support = evaluator.support(face);
    for (size_t k = 0; k < support.size(); ++k) {
      const auto column = std::find(indices.begin(), indices.end(), support[k]) - indices.begin();
      sum.col(column) += cell_weights.col(static_cast<Eigen::Index>(k));
    }
    exact[c] = 1;
  }
  return sum;
}

}  // namespace softshell::engine::internal
