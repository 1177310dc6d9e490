#include "softshell/bullet/force_accumulator.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace softshell::bullet {

ForceAccumulator::ForceAccumulator(LimitEvaluator evaluator)
    : evaluator_(std::move(evaluator)),
      forces_(static_cast<size_t>(evaluator_.num_control_points()), Vec3::Zero()),
      is_touched_(forces_.size(), 0) {}

void ForceAccumulator::clear() {
  for (int32_t i : touched_) {
    forces_[static_cast<size_t>(i)].setZero();
    is_touched_[static_cast<size_t>(i)] = 0;
  }
  touched_.clear();
  total_.setZero();
}

void ForceAccumulator::add(int32_t index, const Vec3& force) {
  if (index < 0 || index >= num_control_points()) {
    fail(ErrorCode::kInvalidArgument, "control point " + std::to_string(index) + " is out of range");
  }
  const auto i = static_cast<size_t>(index);
  if (!is_touched_[i]) {
    is_touched_[i] = 1;
    touched_.push_back(index);
  }
  forces_[i] += force;
  total_ += force;
}

void ForceAccumulator::add(const SurfacePoint& point, const Vec3& force) {
  evaluator_.stencil(point, stencil_);  // throws kInvalidArgument for a bad point
  for (size_t k = 0; k < stencil_.size(); ++k) {
    if (stencil_.position[k] == 0.0) continue;
    add(stencil_.indices[k], stencil_.position[k] * force);
  }
}

void ForceAccumulator::blend_toward(const ForceAccumulator& target, double alpha, double drop_below) {
  if (target.num_control_points() != num_control_points()) {
    fail(ErrorCode::kInvalidArgument, "ForceAccumulator::blend_toward: meshes of different sizes");
  }
  // Blend on the union of both touched sets, then keep only the forces that remain.
  for (int32_t i : target.touched_) {
    if (!is_touched_[static_cast<size_t>(i)]) {
      is_touched_[static_cast<size_t>(i)] = 1;
      touched_.push_back(i);
    }
  }
  total_.setZero();
  size_t kept = 0;
  const double drop_squared = drop_below * drop_below;
  for (int32_t i : touched_) {
    const auto k = static_cast<size_t>(i);
    forces_[k] += alpha * (target.forces_[k] - forces_[k]);
    if (forces_[k].squaredNorm() < drop_squared || forces_[k].isZero(0.0)) {
      forces_[k].setZero();
      is_touched_[k] = 0;
    } else {
      total_ += forces_[k];
      touched_[kept++] = i;
    }
  }
  touched_.resize(kept);
}

void ForceAccumulator::assign(const ForceAccumulator& other) {
  if (other.num_control_points() != num_control_points()) {
    fail(ErrorCode::kInvalidArgument, "ForceAccumulator::assign: meshes of different sizes");
  }
  clear();
  for (int32_t i : other.touched_) add(i, other.forces_[static_cast<size_t>(i)]);
}

void ForceAccumulator::append_to(std::vector<PointForce>& out) const {
  const size_t first = out.size();
  for (int32_t i : touched_) out.push_back(PointForce{i, forces_[static_cast<size_t>(i)]});
  std::sort(out.begin() + static_cast<std::ptrdiff_t>(first), out.end(),
            [](const PointForce& a, const PointForce& b) { return a.index < b.index; });
}

double ForceAccumulator::relative_difference(const ForceAccumulator& other) const {
  if (empty() && other.empty()) return 0.0;
  if (empty() || other.empty()) return 1.0;
  double diff = 0.0, norm_a = 0.0, norm_b = 0.0;
  // Control points touched by either: this's touched list covers the points where this is
  // non-zero; the other's points missing here contribute their full size.
  for (int32_t i : touched_) {
    const auto k = static_cast<size_t>(i);
    diff += (forces_[k] - other.forces_[k]).squaredNorm();
    norm_a += forces_[k].squaredNorm();
  }
  for (int32_t i : other.touched_) {
    const auto k = static_cast<size_t>(i);
    norm_b += other.forces_[k].squaredNorm();
    if (!is_touched_[k]) diff += other.forces_[k].squaredNorm();
  }
  const double scale = std::max(norm_a, norm_b);
  return scale > 0.0 ? std::sqrt(diff / scale) : 0.0;
}

}  // namespace softshell::bullet
