#include "nonlinear_shell.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Dense>

#include "kirchhoff_love.h"
#include "parallel.h"

namespace softshell::engine::internal {
namespace {

using V3 = Eigen::Vector3d;

// Per quadrature point, reference data (kRef doubles):
//   0 A1, 3 A2, 6 A11, 9 A12, 12 A22 (tangents and second derivatives), 15 A1 x A2, 18 J = |A1 x A2|,
//   19 N (unit normal), 22 membrane matrix dA t C, 28 bending matrix dA t^3/12 C (symmetric, packed
//   00 11 22 01 02 12), 34 parameter weight (the Gauss weight times the cell area).
constexpr int kRef = 35;
// Per quadrature point, deformed state (kState doubles):
//   0 a1, 3 a2, 6 a11, 9 a12, 12 a22, 15 n, 18 j, 19 membrane forces N (n11 n22 n12),
//   22 bending moments M (m11 m22 m12), 25 H = sum m_ab a_ab, 28 g = (I - n n^T) H / j.
constexpr int kState = 31;
// Derivative rows of an element's basis: 0 N, 1 ,u, 2 ,v, 3 ,uu, 4 ,uv, 5 ,vv.
constexpr int kRows = 6;

V3 load3(const double* p) { return V3(p[0], p[1], p[2]); }
void store3(double* p, const V3& v) {
  p[0] = v[0];
  p[1] = v[1];
  p[2] = v[2];
}
V3 sym_mul(const double* s, const V3& x) {
  return V3(s[0] * x[0] + s[3] * x[1] + s[4] * x[2], s[3] * x[0] + s[1] * x[1] + s[5] * x[2],
            s[4] * x[0] + s[5] * x[1] + s[2] * x[2]);
}

// Internal force coefficients of one point: f_A = sum_d N_A,d c[d] (c[0]: the pressure force per
// unit pressure, w (a1 x a2), when asked for). d = displacement derivatives u,u u,v u,uu u,uv u,vv.
// Returns false for a degenerate point.
bool point_forces(const double* ref, const V3* d, bool pressure, double* state, V3* c, double& energy) {
  const V3 A1 = load3(ref), A2 = load3(ref + 3), A11 = load3(ref + 6), A12 = load3(ref + 9), A22 = load3(ref + 12);
  const V3 T3 = load3(ref + 15), N0 = load3(ref + 19);
  const double J = ref[18];
  const V3 &d1 = d[0], &d2 = d[1], &d11 = d[2], &d12 = d[3], &d22 = d[4];
  const V3 a1 = A1 + d1, a2 = A2 + d2, a11 = A11 + d11, a12 = A12 + d12, a22 = A22 + d22;
  // Green-Lagrange strains [E11, E22, 2 E12] without forming a.a - A.A.
  const V3 e(A1.dot(d1) + 0.5 * d1.squaredNorm(), A2.dot(d2) + 0.5 * d2.squaredNorm(),
             A1.dot(d2) + d1.dot(A2) + d1.dot(d2));
  const V3 dt3 = d1.cross(A2) + A1.cross(d2) + d1.cross(d2);
  const V3 t3 = T3 + dt3;
  const double j = t3.norm();
  if (!(j > 1e-12 * J) || !std::isfinite(j)) return false;
  const V3 n = t3 / j;
  // n - N = dt3 / j + N (J - j) / j, with J - j = (J^2 - j^2) / (J + j).
  const double j_drop = -(2.0 * T3.dot(dt3) + dt3.squaredNorm()) / (J + j);
  const V3 dn = dt3 / j + N0 * (j_drop / j);
  // Curvature change B_ab - b_ab = -(A_ab . (n - N) + u,ab . n).
  const V3 k(-(A11.dot(dn) + d11.dot(n)), -(A22.dot(dn) + d22.dot(n)), -2.0 * (A12.dot(dn) + d12.dot(n)));
  const V3 nm = sym_mul(ref + 22, e), mm = sym_mul(ref + 28, k);
  if (!nm.allFinite() || !mm.allFinite()) return false;
  energy += 0.5 * (e.dot(nm) + k.dot(mm));
  const V3 h = mm[0] * a11 + mm[1] * a22 + 2.0 * mm[2] * a12;
  const V3 g = (h - n * n.dot(h)) / j;
  c[0] = pressure ? V3(ref[34] * t3) : V3::Zero();
  c[1] = nm[0] * a1 + nm[2] * a2 - a2.cross(g);
  c[2] = nm[2] * a1 + nm[1] * a2 - g.cross(a1);
  c[3] = -mm[0] * n;
  c[4] = -2.0 * mm[2] * n;
  c[5] = -mm[1] * n;
  store3(state, a1);
  store3(state + 3, a2);
  store3(state + 6, a11);
  store3(state + 9, a12);
  store3(state + 12, a22);
  store3(state + 15, n);
  state[18] = j;
  store3(state + 19, nm);
  store3(state + 22, mm);
  store3(state + 25, h);
  store3(state + 28, g);
  return true;
}

// The directional derivative of the coefficients of point_forces (minus `pressure` times the
// pressure coefficient) for displacement derivatives v (v,u v,v v,uu v,uv v,vv).
void point_tangent(const double* ref, const double* state, double pressure, const V3* v, V3* c) {
  const V3 a1 = load3(state), a2 = load3(state + 3), a11 = load3(state + 6), a12 = load3(state + 9),
           a22 = load3(state + 12), n = load3(state + 15);
  const double j = state[18];
  const V3 nm = load3(state + 19), mm = load3(state + 22), h = load3(state + 25), g = load3(state + 28);
  const V3 &v1 = v[0], &v2 = v[1], &v11 = v[2], &v12 = v[3], &v22 = v[4];
  const V3 de(a1.dot(v1), a2.dot(v2), a1.dot(v2) + a2.dot(v1));
  const V3 dt3 = v1.cross(a2) + a1.cross(v2);
  const double dj = n.dot(dt3);
  const V3 dn = (dt3 - n * dj) / j;
  const V3 dk(-(v11.dot(n) + a11.dot(dn)), -(v22.dot(n) + a22.dot(dn)), -2.0 * (v12.dot(n) + a12.dot(dn)));
  const V3 dnm = sym_mul(ref + 22, de), dmm = sym_mul(ref + 28, dk);
  const V3 dh = dmm[0] * a11 + dmm[1] * a22 + 2.0 * dmm[2] * a12 + mm[0] * v11 + mm[1] * v22 + 2.0 * mm[2] * v12;
  const double hn = n.dot(h);
  const V3 dg = (dh - dn * hn - n * (dn.dot(h) + n.dot(dh))) / j - g * (dj / j);
  c[0] = -pressure * ref[34] * dt3;
  c[1] = dnm[0] * a1 + dnm[2] * a2 + nm[0] * v1 + nm[2] * v2 - v2.cross(g) - a2.cross(dg);
  c[2] = dnm[2] * a1 + dnm[1] * a2 + nm[2] * v1 + nm[1] * v2 - dg.cross(a1) - g.cross(v1);
  c[3] = -(dmm[0] * n + mm[0] * dn);
  c[4] = -2.0 * (dmm[2] * n + mm[2] * dn);
  c[5] = -(dmm[1] * n + mm[1] * dn);
}

}  // namespace

template <class Fn>
void NonlinearShell::for_each_element(Fn&& fn) const {
  // Chunks of about the same number of points, so both threads finish together.
  constexpr size_t kPointsPerChunk = 4096;
  const int threads = num_points_ < 2 * kPointsPerChunk ? 1 : resolve_threads(threads_);
  if (threads == 1) {
    for (size_t e = 0; e < elements_.size(); ++e) fn(e);
    return;
  }
  std::vector<size_t> starts{0};
  size_t points = 0;
  for (size_t e = 0; e < elements_.size(); ++e) {
    points += static_cast<size_t>(elements_[e].points);
    if (points >= kPointsPerChunk) {
      starts.push_back(e + 1);
      points = 0;
    }
  }
  if (starts.back() != elements_.size()) starts.push_back(elements_.size());
  parallel_for(0, static_cast<int64_t>(starts.size() - 1), threads, [&](int64_t c) {
    for (size_t e = starts[static_cast<size_t>(c)]; e < starts[static_cast<size_t>(c) + 1]; ++e) fn(e);
  });
}

std::shared_ptr<const NonlinearShell> NonlinearShell::build(std::shared_ptr<const ShellModel> model, int threads) {
  if (!model) fail(ErrorCode::kInvalidArgument, "NonlinearShell needs a model");
  std::shared_ptr<NonlinearShell> shell(new NonlinearShell());
  shell->model_ = model;
  shell->threads_ = threads;
  const ShellModel& m = *model;
  // Elements: the runs of quadrature points on one (face, sub-face), in the order K was built.
  const std::vector<QuadraturePoint>& quad = m.quadrature();
  for (size_t q = 0; q < quad.size();) {
    size_t end = q + 1;
    while (end < quad.size() && quad[end].point.face == quad[q].point.face &&
           quad[end].point.subface == quad[q].point.subface) {
      ++end;
    }
    Element e;
    e.first_point = q;
    e.points = static_cast<Eigen::Index>(end - q);
    shell->elements_.push_back(std::move(e));
    q = end;
  }
  shell->num_points_ = quad.size();
  shell->reference_.assign(kRef * quad.size(), 0.0);

  const Eigen::SparseMatrix<double>& k = m.stiffness();
  const Material& mat = m.material();
  const double t = mat.thickness;
  parallel_for(0, static_cast<int64_t>(shell->elements_.size()), resolve_threads(threads), [&](int64_t ei) {
    Element& e = shell->elements_[static_cast<size_t>(ei)];
    const auto p = e.points;
    std::vector<std::array<double, 2>> uvs(static_cast<size_t>(p));
    for (Eigen::Index q = 0; q < p; ++q) {
      const QuadraturePoint& qp = quad[e.first_point + static_cast<size_t>(q)];
      uvs[static_cast<size_t>(q)] = {qp.point.u, qp.point.v};
    }
    Eigen::MatrixXd bfr;  // 6P x m, rows 6q + d
    const SurfacePoint& first = quad[e.first_point].point;
    m.evaluator().face_stencils(first.face, first.subface, uvs, e.indices, bfr);
    const auto mm = static_cast<Eigen::Index>(e.indices.size());
    e.basis.resize(kRows * p, mm);
    for (Eigen::Index q = 0; q < p; ++q) {
      for (int d = 0; d < kRows; ++d) e.basis.row(d * p + q) = bfr.row(kRows * q + d);
    }
    Eigen::MatrixX3d x(mm, 3);
    for (Eigen::Index a = 0; a < mm; ++a) {
      x.row(a) = m.mesh().positions()[static_cast<size_t>(e.indices[static_cast<size_t>(a)])].transpose();
    }
    const Eigen::MatrixX3d deriv = e.basis * x;
    SurfaceFrame frame;
    for (Eigen::Index q = 0; q < p; ++q) {
      // The same frame and material matrix the linear model was integrated with.
      if (!compute_frame(bfr.middleRows(kRows * q, kRows), x, mat.youngs_modulus, mat.poisson_ratio, frame)) {
        fail(ErrorCode::kInternal, "nonlinear shell: a degenerate quadrature point in a model that was built");
      }
      const QuadraturePoint& qp = quad[e.first_point + static_cast<size_t>(q)];
      double* ref = shell->reference_.data() + kRef * (e.first_point + static_cast<size_t>(q));
      for (int d = 1; d < kRows; ++d) store3(ref + 3 * (d - 1), deriv.row(d * p + q).transpose());
      const V3 t3 = load3(ref).cross(load3(ref + 3));
      store3(ref + 15, t3);
      ref[18] = t3.norm();
      store3(ref + 19, t3 / t3.norm());
      const double da = qp.weight * frame.j;
      const Eigen::Matrix3d& c = frame.material;
      const double packed[6] = {c(0, 0), c(1, 1), c(2, 2), c(0, 1), c(0, 2), c(1, 2)};
      for (int i = 0; i < 6; ++i) {
        ref[22 + i] = da * t * packed[i];
        ref[28 + i] = da * t * t * t / 12.0 * packed[i];
      }
      ref[34] = qp.weight;
    }
    // Where each (a, b) block of the element lands in K's value array.
    e.offsets.resize(static_cast<size_t>(mm * mm));
    for (Eigen::Index bl = 0; bl < mm; ++bl) {
      const int col = 3 * e.indices[static_cast<size_t>(bl)];
      const int* begin = k.innerIndexPtr() + k.outerIndexPtr()[col];
      const int* end = k.innerIndexPtr() + k.outerIndexPtr()[col + 1];
      for (Eigen::Index al = 0; al < mm; ++al) {
        const int row = 3 * e.indices[static_cast<size_t>(al)];
        const int* it = std::lower_bound(begin, end, row);
        if (it == end || *it != row || end - it < 3 || it[2] != row + 2) {
          fail(ErrorCode::kInternal, "nonlinear shell: the stiffness pattern lacks an element's block");
        }
        e.offsets[static_cast<size_t>(al + mm * bl)] = static_cast<int32_t>(it - begin);
      }
    }
  });
  return shell;
}

size_t NonlinearShell::memory_bytes() const {
  size_t bytes = sizeof(*this) + reference_.size() * sizeof(double);
  for (const Element& e : elements_) {
    bytes += sizeof(Element) + static_cast<size_t>(e.basis.size()) * sizeof(double) +
             (e.indices.size() + e.offsets.size()) * sizeof(int32_t);
  }
  return bytes;
}

bool NonlinearShell::evaluate(const Eigen::VectorXd& u, ShellState& state, bool with_pressure) const {
  const int32_t ndof = num_dofs();
  if (u.size() != ndof) fail(ErrorCode::kInvalidArgument, "nonlinear shell: the displacement must have 3n entries");
  state.displacement = u;
  state.points.resize(kState * num_points_);
  std::vector<Eigen::MatrixX3d> element_force(elements_.size()), element_pressure(with_pressure ? elements_.size() : 0);
  std::vector<double> element_energy(elements_.size(), 0.0);
  std::vector<char> element_ok(elements_.size(), 1);
  for_each_element([&](size_t ei) {
    const Element& e = elements_[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    Eigen::MatrixX3d local(m, 3);
    for (Eigen::Index a = 0; a < m; ++a) local.row(a) = u.segment<3>(3 * e.indices[static_cast<size_t>(a)]).transpose();
    const Eigen::MatrixX3d deriv = e.basis.bottomRows((kRows - 1) * p) * local;
    Eigen::MatrixX3d coef(kRows * p, 3);
    V3 d[5], c[kRows];
    double energy = 0.0;
    for (Eigen::Index q = 0; q < p; ++q) {
      for (int r = 0; r < 5; ++r) d[r] = deriv.row(r * p + q).transpose();
      const size_t point = e.first_point + static_cast<size_t>(q);
      if (!point_forces(reference_.data() + kRef * point, d, with_pressure, state.points.data() + kState * point, c,
                        energy)) {
        element_ok[ei] = 0;
        return;
      }
      for (int r = 0; r < kRows; ++r) coef.row(r * p + q) = c[r].transpose();
    }
    element_energy[ei] = energy;
    element_force[ei].noalias() = e.basis.bottomRows((kRows - 1) * p).transpose() * coef.bottomRows((kRows - 1) * p);
    if (with_pressure) element_pressure[ei].noalias() = e.basis.topRows(p).transpose() * coef.topRows(p);
  });
  state.valid = std::all_of(element_ok.begin(), element_ok.end(), [](char ok) { return ok != 0; });
  state.energy = 0.0;
  state.internal_force.setZero(ndof);
  state.pressure_force.setZero(with_pressure ? ndof : 0);
  if (!state.valid) return false;
  for (size_t ei = 0; ei < elements_.size(); ++ei) {
    const Element& e = elements_[ei];
    state.energy += element_energy[ei];
    for (size_t a = 0; a < e.indices.size(); ++a) {
      state.internal_force.segment<3>(3 * e.indices[a]) += element_force[ei].row(static_cast<Eigen::Index>(a)).transpose();
      if (with_pressure) {
        state.pressure_force.segment<3>(3 * e.indices[a]) += element_pressure[ei].row(static_cast<Eigen::Index>(a)).transpose();
      }
    }
  }
  state.valid = std::isfinite(state.energy) && state.internal_force.allFinite() &&
                (!with_pressure || state.pressure_force.allFinite());
  return state.valid;
}

void NonlinearShell::tangent_product(const ShellState& state, double pressure, const Eigen::MatrixXd& v,
                                     Eigen::MatrixXd& out) const {
  const int32_t ndof = num_dofs();
  if (!state.valid || v.rows() != ndof) fail(ErrorCode::kInternal, "nonlinear shell: tangent product of a bad state");
  const Eigen::Index cols = v.cols();
  std::vector<Eigen::MatrixXd> element_out(elements_.size());
  for_each_element([&](size_t ei) {
    const Element& e = elements_[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    Eigen::MatrixXd local(m, 3 * cols);  // column 3 c + i: axis i of vector c
    for (Eigen::Index a = 0; a < m; ++a) {
      for (Eigen::Index c = 0; c < cols; ++c) {
        local.block<1, 3>(a, 3 * c) = v.block<3, 1>(3 * e.indices[static_cast<size_t>(a)], c).transpose();
      }
    }
    const Eigen::MatrixXd deriv = e.basis.bottomRows((kRows - 1) * p) * local;
    const Eigen::Index first = pressure != 0.0 ? 0 : p;  // the N rows only matter with a pressure
    Eigen::MatrixXd coef(kRows * p, 3 * cols);
    V3 d[5], c[kRows];
    for (Eigen::Index q = 0; q < p; ++q) {
      const size_t point = e.first_point + static_cast<size_t>(q);
      for (Eigen::Index col = 0; col < cols; ++col) {
        for (int r = 0; r < 5; ++r) d[r] = deriv.block<1, 3>(r * p + q, 3 * col).transpose();
        point_tangent(reference_.data() + kRef * point, state.points.data() + kState * point, pressure, d, c);
        for (int r = 0; r < kRows; ++r) coef.block<1, 3>(r * p + q, 3 * col) = c[r].transpose();
      }
    }
    element_out[ei].noalias() = e.basis.bottomRows(kRows * p - first).transpose() * coef.bottomRows(kRows * p - first);
  });
  out.setZero(ndof, cols);
  for (size_t ei = 0; ei < elements_.size(); ++ei) {
    const Element& e = elements_[ei];
    for (size_t a = 0; a < e.indices.size(); ++a) {
      for (Eigen::Index c = 0; c < cols; ++c) {
        out.block<3, 1>(3 * e.indices[a], c) += element_out[ei].block<1, 3>(static_cast<Eigen::Index>(a), 3 * c).transpose();
      }
    }
  }
}

void NonlinearShell::assemble_tangent(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const {
  if (!state.valid) fail(ErrorCode::kInternal, "nonlinear shell: tangent of a bad state");
  const Eigen::SparseMatrix<double>& k = model_->stiffness();
  out = k;  // the pattern; values overwritten below
  std::fill(out.valuePtr(), out.valuePtr() + out.nonZeros(), 0.0);
  std::vector<Eigen::MatrixXd> element_k(elements_.size());
  for_each_element([&](size_t ei) {
    const Element& e = elements_[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    // Q_q: the point's Hessian in the 18 generalized coordinates (derivative d, axis i) -> 3 d + i,
    // column by column from the tangent kernel (input d = 1..5; row d = 0 is the pressure force).
    constexpr int kQ = 3 * kRows;
    Eigen::MatrixXd qs(kQ * kQ, p);  // column q: Q_q column-major
    V3 d[5], c[kRows];
    for (Eigen::Index q = 0; q < p; ++q) {
      const size_t point = e.first_point + static_cast<size_t>(q);
      Eigen::Matrix<double, kQ, kQ> qm = Eigen::Matrix<double, kQ, kQ>::Zero();
      for (int r = 0; r < 5; ++r) {
        for (int axis = 0; axis < 3; ++axis) {
          for (V3& x : d) x.setZero();
          d[r][axis] = 1.0;
          point_tangent(reference_.data() + kRef * point, state.points.data() + kState * point, pressure, d, c);
          for (int row = 0; row < kRows; ++row) qm.block<3, 1>(3 * row, 3 * (r + 1) + axis) = c[row];
        }
      }
      const Eigen::Matrix<double, kQ, kQ> sym = 0.5 * (qm + qm.transpose());
      qs.col(q) = Eigen::Map<const Eigen::Matrix<double, kQ * kQ, 1>>(sym.data());
    }
    // K^{ij} = sum_q W_q^T Q_q^{ij} W_q per axis pair (i, j), as W^T T with T = blockdiag(Q^{ij}) W.
    const int first_row = pressure != 0.0 ? 0 : 1;
    Eigen::MatrixXd& ke = element_k[ei];
    ke.setZero(3 * m, 3 * m);
    Eigen::MatrixXd tm(kRows * p, m), kij(m, m);
    for (int i = 0; i < 3; ++i) {
      for (int j = i; j < 3; ++j) {
        tm.setZero();
        for (int dr = first_row; dr < kRows; ++dr) {
          for (int er = first_row; er < kRows; ++er) {
            const auto coef = qs.row((3 * er + j) * kQ + 3 * dr + i);  // Q(3 dr + i, 3 er + j) per point
            if (coef.isZero(0.0)) continue;
            tm.middleRows(dr * p, p).noalias() += coef.transpose().asDiagonal() * e.basis.middleRows(er * p, p);
          }
        }
        kij.noalias() = e.basis.bottomRows((kRows - first_row) * p).transpose() * tm.bottomRows((kRows - first_row) * p);
        for (Eigen::Index bl = 0; bl < m; ++bl) {
          for (Eigen::Index al = 0; al < m; ++al) {
            ke(3 * al + i, 3 * bl + j) = kij(al, bl);
            ke(3 * bl + j, 3 * al + i) = kij(al, bl);
          }
        }
      }
    }
  });
  for (size_t ei = 0; ei < elements_.size(); ++ei) {
    const Element& e = elements_[ei];
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    const Eigen::MatrixXd& ke = element_k[ei];
    for (Eigen::Index bl = 0; bl < m; ++bl) {
      for (int j = 0; j < 3; ++j) {
        double* column = out.valuePtr() + out.outerIndexPtr()[3 * e.indices[static_cast<size_t>(bl)] + j];
        for (Eigen::Index al = 0; al < m; ++al) {
          double* block = column + e.offsets[static_cast<size_t>(al + m * bl)];
          for (int i = 0; i < 3; ++i) block[i] += ke(3 * al + i, 3 * bl + j);
        }
      }
    }
  }
}

}  // namespace softshell::engine::internal
