#include "softshell/interaction.h"

#include <cmath>
#include <map>
#include <string>

#include <Eigen/SVD>

#include "softshell/picking.h"

namespace softshell {

namespace {

bool finite(const Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

bool finite(const Pose& p) {
  const auto& q = p.orientation.coeffs();
  return finite(p.position) && std::isfinite(q.x()) && std::isfinite(q.y()) && std::isfinite(q.z()) &&
         std::isfinite(q.w()) && q.squaredNorm() > 0.0;
}

Eigen::Matrix3d skew(const Vec3& r) {
  Eigen::Matrix3d m;
  m << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
  return m;
}

}  // namespace

Result<std::vector<LagrangeConstraint>> to_lagrange(const LimitEvaluator& evaluator, const LimitConstraint& c,
                                                    uint32_t axes) {
  return capture([&]() -> std::vector<LagrangeConstraint> {
    if (axes == 0 || axes > kAxisAll) fail(ErrorCode::kInvalidArgument, "axis mask must be 1..7");
    if (!finite(c.displacement) || (c.du_displacement && !finite(*c.du_displacement)) ||
        (c.dv_displacement && !finite(*c.dv_displacement))) {
      fail(ErrorCode::kInvalidArgument, "limit constraint values must be finite");
    }
    const LimitStencil st = evaluator.stencil(c.point);
    const Vec3 mask((axes & kAxisX) ? 1.0 : 0.0, (axes & kAxisY) ? 1.0 : 0.0, (axes & kAxisZ) ? 1.0 : 0.0);
    auto make = [&](const std::vector<double>& weights, const Vec3& value, const Vec3& m) {
      LagrangeConstraint l;
      l.indices = st.indices;
      l.coefficients.reserve(weights.size());
      for (double w : weights) l.coefficients.push_back(w * m);
      l.values = value.cwiseProduct(m);
      return l;
    };
    std::vector<LagrangeConstraint> out{make(st.position, c.displacement, mask)};
    if (c.du_displacement) out.push_back(make(st.du, *c.du_displacement, Vec3::Ones()));
    if (c.dv_displacement) out.push_back(make(st.dv, *c.dv_displacement, Vec3::Ones()));
    return out;
  });
}

Result<std::vector<PointForce>> spread_force(const LimitEvaluator& evaluator, const SurfaceForce& force) {
  return capture([&]() -> std::vector<PointForce> {
    if (!finite(force.force)) fail(ErrorCode::kInvalidArgument, "force must be finite");
    const LimitStencil st = evaluator.stencil(force.point);
    std::vector<PointForce> out;
    out.reserve(st.size());
    for (size_t k = 0; k < st.size(); ++k) out.push_back(PointForce{st.indices[k], st.position[k] * force.force});
    return out;
  });
}

SurfaceForce push(const Pick& pick, const Vec3& direction, double magnitude) {
  const double n = direction.norm();
  const Vec3 unit = n > 0.0 && std::isfinite(n) ? Vec3(direction / n) : Vec3::Zero();
  return SurfaceForce{pick.point, std::isfinite(magnitude) ? Vec3(magnitude * unit) : Vec3::Zero()};
}

// ------------------------------------------------------------------------------------------------
// Grab

Result<Grab> Grab::begin(const LimitEvaluator& evaluator, const SurfacePoint& point,
                         const std::vector<Vec3>& current_positions, const Pose& hand, const GrabOptions& options) {
  return capture([&]() -> Grab {
    evaluator.check(point).value();
    if (current_positions.size() != static_cast<size_t>(evaluator.num_control_points())) {
      fail(ErrorCode::kInvalidArgument, "expected " + std::to_string(evaluator.num_control_points()) +
                                            " control positions, got " + std::to_string(current_positions.size()));
    }
    if (!finite(hand)) fail(ErrorCode::kInvalidArgument, "hand pose must be finite with a non-zero orientation");
    Grab g;
    g.point_ = point;
    const LimitSample rest = evaluator.evaluate(point);
    const LimitSample now = evaluator.evaluate(point, current_positions);
    if (!finite(now.position) || !finite(now.du) || !finite(now.dv)) {
      fail(ErrorCode::kInvalidArgument, "the current control positions are not finite");
    }
    g.rest_x_ = rest.position;
    g.rest_du_ = rest.du;
    g.rest_dv_ = rest.dv;
    g.grab_x_ = now.position;
    g.grab_du_ = now.du;
    g.grab_dv_ = now.dv;
    g.hand0_ = hand;
    g.hand0_.orientation.normalize();
    g.options_ = options;
    return g;
  });
}

Eigen::Matrix3d Grab::rotation_since_grab(const Pose& hand) const {
  Eigen::Quaterniond q = hand.orientation.normalized();
  return (q * hand0_.orientation.conjugate()).toRotationMatrix();
}

Vec3 Grab::target(const Pose& hand) const {
  if (!finite(hand)) return grab_x_;
  if (!options_.follow_rotation) return grab_x_ + (hand.position - hand0_.position);
  return hand.position + rotation_since_grab(hand) * (grab_x_ - hand0_.position);
}

LimitConstraint Grab::constraint(const Pose& hand) const {
  LimitConstraint c;
  c.point = point_;
  c.displacement = target(hand) - rest_x_;
  if (options_.constrain_tangents) {
    const Eigen::Matrix3d R = finite(hand) ? rotation_since_grab(hand) : Eigen::Matrix3d::Identity();
    c.du_displacement = R * grab_du_ - rest_du_;
    c.dv_displacement = R * grab_dv_ - rest_dv_;
  }
  return c;
}

// ------------------------------------------------------------------------------------------------
// Floor

void FloorContact::add_to(DeformationRequest& request) const {
  request.limit_constraints.insert(request.limit_constraints.end(), limit_constraints.begin(), limit_constraints.end());
  request.lagrange_constraints.insert(request.lagrange_constraints.end(), lagrange_constraints.begin(),
                                      lagrange_constraints.end());
}

Result<std::vector<int32_t>> floor_touching_samples(const Tessellation& tessellation, const Plane& floor,
                                                    double tolerance) {
  return capture([&]() -> std::vector<int32_t> {
    if (!finite(floor.point) || !finite(floor.normal) || !(floor.normal.norm() > 0.0)) {
      fail(ErrorCode::kInvalidArgument, "the floor plane needs a finite point and a finite, non-zero normal");
    }
    if (!std::isfinite(tolerance)) fail(ErrorCode::kInvalidArgument, "floor tolerance must be finite");
    if (tolerance < 0.0) tolerance = 1e-3 * tessellation.evaluator().mesh().bounding_diagonal();
    const Vec3 n = floor.normal.normalized();
    const auto& x = tessellation.vertices();
    std::vector<int32_t> touching;
    for (size_t i = 0; i < x.size(); ++i) {
      if (n.dot(x[i] - floor.point) <= tolerance) touching.push_back(static_cast<int32_t>(i));
    }
    return touching;
  });
}

int coordinate_axis(const Vec3& normal) {
  const double length = normal.norm();
  if (!(length > 0.0) || !std::isfinite(length)) return -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(std::abs(normal[a]) / length - 1.0) <= 1e-9) return a;
  }
  return -1;
}

Result<FloorContact> floor_contact(const Tessellation& tessellation, const Plane& floor, const FloorOptions& options) {
  return capture([&]() -> FloorContact {
    const std::vector<int32_t> touching = floor_touching_samples(tessellation, floor, options.tolerance).value();
    const Vec3 n = floor.normal.normalized();
    const int axis = options.axes == FloorAxes::kNormal ? coordinate_axis(n) : -1;
    if (options.axes == FloorAxes::kNormal && axis < 0) {
      fail(ErrorCode::kInvalidArgument,
           "normal-only floor contacts need a floor normal along x, y or z: Lagrange constraints act on each "
           "axis separately (PROTOCOL.md), so a tilted normal cannot be expressed; use FloorAxes::kAll");
    }
    const LimitEvaluator& ev = tessellation.evaluator();
    const double size = ev.mesh().bounding_diagonal();

    // Touching samples, grouped by control face (ordered, so the result is deterministic).
    const auto& x = tessellation.vertices();
    const auto& points = tessellation.vertex_points();
    std::map<int32_t, std::vector<size_t>> by_face;
    FloorContact out;
    for (int32_t i : touching) by_face[points[static_cast<size_t>(i)].face].push_back(static_cast<size_t>(i));
    out.touching_samples = static_cast<int32_t>(touching.size());

    Eigen::MatrixXd rigid(0, 6);  // the rigid modes' values in the constrained directions
    Vec3 centre = Vec3::Zero();
    {
      Vec3 lo, hi;
      ev.mesh().bounding_box(lo, hi);
      centre = 0.5 * (lo + hi);
    }
    const double scale = std::max(size, std::numeric_limits<double>::min());
    for (const auto& [face, samples] : by_face) {
      Vec3 mean = Vec3::Zero();
      for (size_t i : samples) mean += x[i];
      mean /= static_cast<double>(samples.size());
      size_t best = samples.front();
      for (size_t i : samples) {
        if ((x[i] - mean).squaredNorm() < (x[best] - mean).squaredNorm()) best = i;
      }
      const SurfacePoint p = points[best];
      const Vec3 rest = ev.evaluate(p).position;
      Vec3 held = x[best];
      if (options.snap) held -= n * n.dot(x[best] - floor.point);
      const Vec3 displacement = held - rest;
      out.points.push_back(p);

      // u(r) = a + w x r = [I, -skew(r)] (a, w), with r relative to the centre and scaled.
      Eigen::Matrix<double, 3, 6> modes;
      modes.leftCols<3>().setIdentity();
      modes.rightCols<3>() = -skew((rest - centre) / scale);
      if (options.axes == FloorAxes::kAll) {
        out.limit_constraints.push_back(LimitConstraint{p, displacement, std::nullopt, std::nullopt});
        rigid.conservativeResize(rigid.rows() + 3, 6);
        rigid.bottomRows<3>() = modes;
      } else {
        const uint32_t mask = 1u << axis;
        LimitConstraint c{p, displacement, std::nullopt, std::nullopt};
        out.lagrange_constraints.push_back(to_lagrange(ev, c, mask).value().front());
        rigid.conservativeResize(rigid.rows() + 1, 6);
        rigid.bottomRows<1>() = modes.row(axis);
      }
    }
    if (rigid.rows() >= 6) {
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(rigid);
      const auto& s = svd.singularValues();
      out.fixes_rigid_motion = s(5) > 1e-6 * s(0);
    }
    return out;
  });
}

}  // namespace softshell
