// FaceProgram: the exact evaluation of every face with one numbered 1-ring topology, split into
// regular bicubic pieces and EvConfig pieces (see exact_limit.h).
#include <algorithm>
#include <array>
#include <cmath>

#include <opensubdiv/far/topologyRefiner.h>

#include "exact_limit.h"
#include "softshell/result.h"

namespace softshell::internal {

using Index = Far::Index;

// ---------------------------------------------------------------------------------------------
// FaceProgram

struct ProgramBuilder {
  using Param = std::array<double, 2>;
  struct Quad {
    int level = 0;
    Index face = 0;
    int subface = 0;
    std::array<Param, 4> corner;  // sub-face coordinates of the face's vertices, in its order
  };

  const LocalRefinement& local;
  EvConfigStore& configs;
  FaceProgram& program;

  void add_piece(const Quad& q, int origin, const EvConfig* config, RowMatrix matrix) {
    FaceProgram::Piece piece;
    piece.subface = q.subface;
    piece.umin = piece.vmin = 1.0;
    piece.umax = piece.vmax = 0.0;
    for (const Param& p : q.corner) {
      piece.umin = std::min(piece.umin, p[0]);
      piece.umax = std::max(piece.umax, p[0]);
      piece.vmin = std::min(piece.vmin, p[1]);
      piece.vmax = std::max(piece.vmax, p[1]);
    }
    const Param o = q.corner[static_cast<size_t>(origin)];
    const Param e1 = {q.corner[static_cast<size_t>((origin + 1) % 4)][0] - o[0],
                      q.corner[static_cast<size_t>((origin + 1) % 4)][1] - o[1]};
    const Param e2 = {q.corner[static_cast<size_t>((origin + 3) % 4)][0] - o[0],
                      q.corner[static_cast<size_t>((origin + 3) % 4)][1] - o[1]};
    const double l1 = e1[0] * e1[0] + e1[1] * e1[1], l2 = e2[0] * e2[0] + e2[1] * e2[1];
    piece.ou = o[0];
    piece.ov = o[1];
    piece.su = e1[0] / l1;
    piece.sv = e1[1] / l1;
    piece.tu = e2[0] / l2;
    piece.tv = e2[1] / l2;
    piece.config = config;
    piece.matrix = std::move(matrix);
    program.pieces_.push_back(std::move(piece));
  }

  // Splits q until every piece is a regular patch or an EvConfig; false if `max_level` is reached.
  bool process(const Quad& q, int max_level) {
    const Far::TopologyLevel& level = local.refiner->GetLevel(q.level);
    const RowMatrix& w = local.weights[static_cast<size_t>(q.level)];
    PatchGrid grid;
    if (regular_grid(level, q.face, 0, grid)) {
      add_piece(q, 0, nullptr, grid_rows(grid, w));
      return true;
    }
    auto fv = level.GetFaceVertices(q.face);
    int irregular = -1, count = 0;
    for (int c = 0; c < 4; ++c) {
      if (!is_regular_vertex(level, fv[c])) {
        irregular = c;
        ++count;
      }
    }
    if (count == 1) {
      Neighbourhood hood;
      if (extract_neighbourhood(level, q.face, irregular, hood)) {
        if (const EvConfig* config = configs.get(hood.signature)) {
          RowMatrix m(config->size(), w.cols());
          for (int i = 0; i < config->size(); ++i) m.row(i) = w.row(hood.vertices[static_cast<size_t>(i)]);
          add_piece(q, irregular, config, std::move(m));
          return true;
        }
      }
    }
    if (q.level >= max_level) return false;
    const Far::TopologyLevel& next = local.refiner->GetLevel(q.level + 1);
    const Index centre = level.GetFaceChildVertex(q.face);
    const Param mid = {0.25 * (q.corner[0][0] + q.corner[1][0] + q.corner[2][0] + q.corner[3][0]),
                       0.25 * (q.corner[0][1] + q.corner[1][1] + q.corner[2][1] + q.corner[3][1])};
    for (int c = 0; c < 4; ++c) {
      Quad child;
      child.level = q.level + 1;
      child.subface = q.subface;
      child.face = child_face_with(level, next, q.face, level.GetVertexChildVertex(fv[c]));
      if (child.face < 0) return false;
      auto cv = next.GetFaceVertices(child.face);
      for (int i = 0; i < 4; ++i) {
        const Index v = cv[i];
        bool found = v == centre;
        Param p = mid;
        for (int j = 0; j < 4 && !found; ++j) {
          const Param& a = q.corner[static_cast<size_t>(j)];
          const Param& b = q.corner[static_cast<size_t>((j + 1) % 4)];
          if (v == level.GetVertexChildVertex(fv[j])) {
            p = a;
            found = true;
          } else if (v == level.GetEdgeChildVertex(level.FindEdge(fv[j], fv[(j + 1) % 4]))) {
            p = {0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])};
            found = true;
          }
        }
        if (!found) return false;
        child.corner[static_cast<size_t>(i)] = p;
      }
      if (!process(child, max_level)) return false;
    }
    return true;
  }
};

std::unique_ptr<FaceProgram> FaceProgram::build(const std::vector<int32_t>& signature, EvConfigStore& configs) {
  const int n = signature[1];
  for (int max_level = 2; max_level <= 4; ++max_level) {
    LocalRefinement local = refine_local(signature, max_level);
    auto program = std::unique_ptr<FaceProgram>(new FaceProgram);
    program->size_ = local.base_size;
    ProgramBuilder builder{local, configs, *program};
    bool ok = true;
    if (n == 4) {
      ok = builder.process({0, 0, 0, {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}}}, max_level);
    } else {
      // Sub-face k is the child at corner k: (0,0) there, (1,0) at the midpoint of edge k -> k+1,
      // (1,1) at the centre, (0,1) at the midpoint of edge k-1 -> k.
      const Far::TopologyLevel& l0 = local.refiner->GetLevel(0);
      const Far::TopologyLevel& l1 = local.refiner->GetLevel(1);
      auto fv = l0.GetFaceVertices(0);
      for (int k = 0; k < n && ok; ++k) {
        ProgramBuilder::Quad q;
        q.level = 1;
        q.subface = k;
        q.face = child_face_with(l0, l1, 0, l0.GetVertexChildVertex(fv[k]));
        if (q.face < 0) {
          ok = false;
          break;
        }
        const Index next_mid = l0.GetEdgeChildVertex(l0.FindEdge(fv[k], fv[(k + 1) % n]));
        const Index prev_mid = l0.GetEdgeChildVertex(l0.FindEdge(fv[(k + n - 1) % n], fv[k]));
        auto cv = l1.GetFaceVertices(q.face);
        for (int i = 0; i < 4; ++i) {
          const Index v = cv[i];
          q.corner[static_cast<size_t>(i)] = v == next_mid ? ProgramBuilder::Param{1, 0}
                                            : v == prev_mid ? ProgramBuilder::Param{0, 1}
                                            : v == l0.GetFaceChildVertex(0) ? ProgramBuilder::Param{1, 1}
                                                                             : ProgramBuilder::Param{0, 0};
        }
        ok = builder.process(q, max_level);
      }
    }
    if (ok) return program;
  }
  return nullptr;  // e.g. a valence-2 vertex: not split into exact pieces within 4 levels
}

const FaceProgram::Piece& FaceProgram::piece_at(int subface, double u, double v) const {
  for (const Piece& p : pieces_) {
    if (p.subface == subface && u >= p.umin && u <= p.umax && v >= p.vmin && v <= p.vmax) return p;
  }
  fail(ErrorCode::kInternal, "no piece of the face contains the point");
}

void FaceProgram::to_subface(const Piece& piece, Eigen::Ref<RowMatrix> rows) {
  const double su = piece.su, sv = piece.sv, tu = piece.tu, tv = piece.tv;
  if (su == 1.0 && sv == 0.0 && tu == 0.0 && tv == 1.0) return;
  for (Eigen::Index i = 0; i + 5 < rows.rows(); i += 6) {
    for (Eigen::Index j = 0; j < rows.cols(); ++j) {
      const double fs = rows(i + 1, j), ft = rows(i + 2, j);
      const double fss = rows(i + 3, j), fst = rows(i + 4, j), ftt = rows(i + 5, j);
      rows(i + 1, j) = fs * su + ft * tu;
      rows(i + 2, j) = fs * sv + ft * tv;
      rows(i + 3, j) = fss * su * su + 2.0 * fst * su * tu + ftt * tu * tu;
      rows(i + 4, j) = fss * su * sv + fst * (su * tv + sv * tu) + ftt * tu * tv;
      rows(i + 5, j) = fss * sv * sv + 2.0 * fst * sv * tv + ftt * tv * tv;
    }
  }
}

void FaceProgram::evaluate(int subface, double u, double v, double* out, std::vector<double>& scratch) const {
  // One point: the group of evaluate_many without its bookkeeping (no allocation once the
  // scratch has grown).
  const Piece& p = piece_at(subface, u, v);
  const double du = u - p.ou, dv = v - p.ov;
  const double s = std::clamp(p.su * du + p.sv * dv, 0.0, 1.0), t = std::clamp(p.tu * du + p.tv * dv, 0.0, 1.0);
  const auto m = static_cast<Eigen::Index>(size_);
  Eigen::Map<RowMatrix> result(out, 6, m);
  Eigen::Matrix<double, 6, 16, Eigen::RowMajor> basis;
  if (p.config) {
    const EvConfig::Location at = EvConfig::locate(s, t);
    const auto k = static_cast<Eigen::Index>(p.config->size());
    scratch.resize(static_cast<size_t>(6 * k));
    Eigen::Map<RowMatrix> local(scratch.data(), 6, k);
    if (at.ring == 0) {
      p.config->evaluate(0.0, 0.0, local.data());
    } else {
      EvConfig::basis_rows(at, basis.data());
      thread_local RowMatrix deep;
      local.noalias() = basis.lazyProduct(p.config->ring_points(at.ring, at.patch, deep));
      local.row(0) += p.config->limit_mask();
    }
    result.noalias() = local.lazyProduct(p.matrix);
  } else {
    double b[6][16];
    bspline_basis(s, t, b);
    std::copy(&b[0][0], &b[0][0] + 96, basis.data());
    result.noalias() = basis.lazyProduct(p.matrix);
  }
  to_subface(p, result);
}

void FaceProgram::evaluate_many(int subface, const std::array<double, 2>* uvs, size_t count, RowMatrix& out) const {
  const int m = size_;
  out.resize(static_cast<Eigen::Index>(6 * count), m);
  // Each point's piece and, on an extraordinary piece, its ring and sub-patch.
  struct Point {
    const Piece* piece;
    EvConfig::Location at;
    size_t index;
  };
  std::vector<Point> points(count);
  for (size_t i = 0; i < count; ++i) {
    const Piece& p = piece_at(subface, uvs[i][0], uvs[i][1]);
    const double du = uvs[i][0] - p.ou, dv = uvs[i][1] - p.ov;
    const double s = std::clamp(p.su * du + p.sv * dv, 0.0, 1.0), t = std::clamp(p.tu * du + p.tv * dv, 0.0, 1.0);
    EvConfig::Location at;
    if (p.config) {
      at = EvConfig::locate(s, t);
    } else {
      at.a = s, at.b = t;
    }
    points[i] = {&p, at, i};
  }
  std::stable_sort(points.begin(), points.end(), [](const Point& x, const Point& y) {
    return x.piece != y.piece ? x.piece < y.piece
                              : (x.at.ring != y.at.ring ? x.at.ring < y.at.ring : x.at.patch < y.at.patch);
  });
  // One group: the points of one polynomial piece: (6 P x 16) basis rows times its 16 control
  // points (over the neighbourhood of an extraordinary piece, then over the local points).
  RowMatrix basis, local, result, deep;
  for (size_t first = 0; first < count;) {
    size_t last = first + 1;
    while (last < count && points[last].piece == points[first].piece && points[last].at.ring == points[first].at.ring &&
           points[last].at.patch == points[first].at.patch) {
      ++last;
    }
    const Piece& piece = *points[first].piece;
    const auto group = static_cast<Eigen::Index>(last - first);
    if (piece.config && points[first].at.ring == 0) {  // the extraordinary vertex itself
      local.resize(6, piece.config->size());
      piece.config->evaluate(0.0, 0.0, local.data());
      result.noalias() = local * piece.matrix;
      for (size_t i = first; i < last; ++i) out.middleRows(static_cast<Eigen::Index>(6 * points[i].index), 6) = result;
    } else {
      basis.resize(6 * group, 16);
      for (size_t i = first; i < last; ++i) {
        double* rows = basis.row(static_cast<Eigen::Index>(6 * (i - first))).data();
        if (piece.config) {
          EvConfig::basis_rows(points[i].at, rows);
        } else {
          double b[6][16];
          bspline_basis(points[i].at.a, points[i].at.b, b);
          std::copy(&b[0][0], &b[0][0] + 96, rows);
        }
      }
      if (piece.config) {
        local.noalias() = basis * piece.config->ring_points(points[first].at.ring, points[first].at.patch, deep);
        for (Eigen::Index r = 0; r < group; ++r) local.row(6 * r) += piece.config->limit_mask();
        result.noalias() = local * piece.matrix;
      } else {
        result.noalias() = basis * piece.matrix;
      }
      for (size_t i = first; i < last; ++i) {
        out.middleRows(static_cast<Eigen::Index>(6 * points[i].index), 6) =
            result.middleRows(static_cast<Eigen::Index>(6 * (i - first)), 6);
      }
    }
    for (size_t i = first; i < last; ++i) {
      to_subface(piece, out.middleRows(static_cast<Eigen::Index>(6 * points[i].index), 6));
    }
    first = last;
  }
}

const FaceProgram::Piece* FaceProgram::corner_piece(int subface, int corner, double size) const {
  static constexpr std::array<std::array<double, 2>, 4> kCorners = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
  const auto& c = kCorners[static_cast<size_t>(corner & 3)];
  for (const Piece& p : pieces_) {
    if (!p.config || p.subface != subface || p.ou != c[0] || p.ov != c[1]) continue;
    // A dyadic square inside the piece.
    const double h = size / (p.umax - p.umin);
    int e = 0;
    const double f = std::frexp(h, &e);
    return (h <= 1.0 && f == 0.5) ? &p : nullptr;
  }
  return nullptr;
}

bool FaceProgram::corner_rule(int subface, int corner, double size, int g, std::vector<double>& out) const {
  const Piece* p = corner_piece(subface, corner, size);
  if (!p) return false;
  const std::vector<double>& rule = p->config->corner_rule(g);
  std::vector<double> gx, gw;
  gauss_legendre_01(g, gx, gw);
  const double u0 = p->ou == 0.0 ? 0.0 : 1.0 - size, v0 = p->ov == 0.0 ? 0.0 : 1.0 - size;
  const double h = size / (p->umax - p->umin);
  auto nearest = [&](double x) {
    size_t best = 0;
    for (size_t i = 1; i < gx.size(); ++i) {
      if (std::abs(gx[i] - x) < std::abs(gx[best] - x)) best = i;
    }
    return best;
  };
  // The cell's Gauss points are the piece's, rotated.
  out.resize(static_cast<size_t>(g) * static_cast<size_t>(g));
  for (int j = 0; j < g; ++j) {
    for (int i = 0; i < g; ++i) {
      const double du = u0 + size * gx[static_cast<size_t>(i)] - p->ou, dv = v0 + size * gx[static_cast<size_t>(j)] - p->ov;
      const size_t si = nearest((p->su * du + p->sv * dv) / h), ti = nearest((p->tu * du + p->tv * dv) / h);
      out[static_cast<size_t>(i + g * j)] = rule[si + static_cast<size_t>(g) * ti];
    }
  }
  return true;
}

bool FaceProgram::corner_normal_integral(int subface, int corner, double size, const RowMatrix& x,
                                         RowMatrix& out) const {
  const Piece* p = corner_piece(subface, corner, size);
  if (!p) return false;
  int e = 0;
  (void)std::frexp(size / (p->umax - p->umin), &e);  // h = 2^(e-1)
  RowMatrix local;
  p->config->normal_integral(1 - e, p->matrix * x, local);
  // du dv = ds dt / |det|, x_u x x_v = det x_s x x_t: only the orientation of (s, t) remains.
  const double orientation = (p->su * p->tv - p->sv * p->tu) > 0.0 ? 1.0 : -1.0;
  out = orientation * (p->matrix.transpose() * local);
  return true;
}

const FaceProgram* FaceProgramStore::get(const std::vector<int32_t>& signature) {
  auto it = programs_.find(signature);
  if (it == programs_.end()) it = programs_.emplace(signature, FaceProgram::build(signature, configs_)).first;
  return it->second.get();  // null: not evaluable exactly (remembered)
}

}  // namespace softshell::internal
