#include "load_path.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace softshell::engine::internal {

PrescribedPath::PrescribedPath(const ControlMesh& mesh, const Problem& p, const Eigen::VectorXd& u0)
    : mesh_(mesh), p_(p) {
  start_.resize(static_cast<Eigen::Index>(p.fixed.size()));
  for (size_t k = 0; k < p.fixed.size(); ++k) start_[static_cast<Eigen::Index>(k)] = u0[p.fixed[k]];
  const auto n = static_cast<size_t>(mesh.num_vertices());
  std::vector<char> full(n, 0);
  for (size_t v = 0; v < n; ++v) full[v] = p.is_fixed[3 * v] && p.is_fixed[3 * v + 1] && p.is_fixed[3 * v + 2];
  // Connected sets of fully prescribed control points (mesh edges between them).
  std::vector<int32_t> parent(n);
  for (size_t v = 0; v < n; ++v) parent[v] = static_cast<int32_t>(v);
  auto find = [&](int32_t v) {
    while (parent[static_cast<size_t>(v)] != v) {
      parent[static_cast<size_t>(v)] = parent[static_cast<size_t>(parent[static_cast<size_t>(v)])];
      v = parent[static_cast<size_t>(v)];
    }
    return v;
  };
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      const int32_t a = fv[i], b = fv[(i + 1) % fv.size()];
      if (full[static_cast<size_t>(a)] && full[static_cast<size_t>(b)]) parent[static_cast<size_t>(find(a))] = find(b);
    }
  }
  std::vector<std::vector<int32_t>> sets(n);
  for (size_t v = 0; v < n; ++v) {
    if (full[v]) sets[static_cast<size_t>(find(static_cast<int32_t>(v)))].push_back(static_cast<int32_t>(v));
  }
  for (auto& points : sets) {
    if (points.size() < 3) continue;
    Group g;
    g.points = std::move(points);
    std::vector<Vec3> from, to;
    for (int32_t v : g.points) {
      const Vec3 x = mesh.positions()[static_cast<size_t>(v)];
      from.push_back(x + u0.segment<3>(3 * v));
      to.push_back(x + p.fixed_value.segment<3>(3 * v));
    }
    for (size_t i = 0; i < from.size(); ++i) {
      g.from_centre += from[i] / static_cast<double>(from.size());
      g.to_centre += to[i] / static_cast<double>(to.size());
    }
    // The best rotation from start to end (Kabsch).
    Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < from.size(); ++i) h += (from[i] - g.from_centre) * (to[i] - g.to_centre).transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
    d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
    const Eigen::Matrix3d r = svd.matrixV() * d * svd.matrixU().transpose();
    if (!r.allFinite()) continue;
    const Eigen::AngleAxisd turn(r);
    if (!(turn.angle() > 1e-3)) continue;  // (nearly) a translation: straight lines are fine
    g.axis = turn.axis();
    g.angle = turn.angle();
    for (size_t i = 0; i < from.size(); ++i) {
      g.offsets.push_back(from[i] - g.from_centre);
      g.residual.push_back(to[i] - (r * (from[i] - g.from_centre) + g.to_centre));
    }
    groups_.push_back(std::move(g));
  }
}

void PrescribedPath::apply(double lambda, Eigen::VectorXd& u) const {
  for (size_t k = 0; k < p_.fixed.size(); ++k) {
    const int32_t dof = p_.fixed[k];
    const double from = start_[static_cast<Eigen::Index>(k)];
    u[dof] = lambda == 1.0 ? p_.fixed_value[dof] : from + lambda * (p_.fixed_value[dof] - from);
  }
  if (lambda == 1.0) return;
  for (const Group& g : groups_) {
    const Eigen::Matrix3d r = Eigen::AngleAxisd(lambda * g.angle, g.axis).toRotationMatrix();
    const Vec3 centre = g.from_centre + lambda * (g.to_centre - g.from_centre);
    for (size_t i = 0; i < g.points.size(); ++i) {
      const int32_t v = g.points[i];
      u.segment<3>(3 * v) = r * g.offsets[i] + centre + lambda * g.residual[i] - mesh_.positions()[static_cast<size_t>(v)];
    }
  }
}

double PrescribedPath::largest_turn() const {
  double turn = 0.0;
  for (const Group& g : groups_) turn = std::max(turn, g.angle);
  return turn;
}

double largest_edge_rotation(const ControlMesh& mesh, const Eigen::VectorXd& du) {
  double rotation = 0.0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      const int32_t a = fv[i], b = fv[(i + 1) % fv.size()];
      const double length = (mesh.positions()[static_cast<size_t>(a)] - mesh.positions()[static_cast<size_t>(b)]).norm();
      if (length > 0.0) rotation = std::max(rotation, (du.segment<3>(3 * a) - du.segment<3>(3 * b)).norm() / length);
    }
  }
  return rotation;
}

}  // namespace softshell::engine::internal
