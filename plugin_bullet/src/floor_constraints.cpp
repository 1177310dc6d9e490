#include "softshell/bullet/floor_constraints.h"

#include "softshell/interaction.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace softshell::bullet {

Result<std::vector<VertexConstraint>> floor_constraints(const Tessellation& tessellation,
                                                        const Eigen::Isometry3d& shell_to_world,
                                                        const FloorSettings& settings) {
  return capture([&]() -> std::vector<VertexConstraint> {
    if (!settings.point.allFinite() || !settings.normal.allFinite() || !(settings.normal.norm() > 0.0)) {
      fail(ErrorCode::kInvalidArgument, "the floor plane needs a finite point and a finite, non-zero normal");
    }
    if (!std::isfinite(settings.tolerance)) fail(ErrorCode::kInvalidArgument, "floor tolerance must be finite");
    if (settings.mask == 0 || settings.mask > kAxisAll) {
      fail(ErrorCode::kInvalidArgument, "floor constraint mask must be in 1..7 (bits 1 = x, 2 = y, 4 = z)");
    }
    if (!shell_to_world.matrix().allFinite()) fail(ErrorCode::kInvalidArgument, "non-finite shell transform");

    // Which samples touch: the SDK's one floor rule (interaction.h), on the plane taken into the
    // shell's frame, where the tessellation lives.
    const Eigen::Isometry3d world_to_shell = shell_to_world.inverse();
    const Plane plane{world_to_shell * settings.point, world_to_shell.linear() * settings.normal.normalized()};
    const std::vector<int32_t> touching = floor_touching_samples(tessellation, plane, settings.tolerance).value();

    // The control point that dominates the surface at each touching sample.
    const auto& limit = tessellation.limit_matrix();  // rows: samples, columns: control points
    std::vector<uint8_t> held(static_cast<size_t>(limit.cols()), 0);
    for (int32_t i : touching) {
      Eigen::Index best = -1;
      double best_weight = -std::numeric_limits<double>::infinity();
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(limit, static_cast<Eigen::Index>(i)); it;
           ++it) {
        if (it.value() > best_weight) {
          best_weight = it.value();
          best = it.col();
        }
      }
      if (best >= 0) held[static_cast<size_t>(best)] = 1;
    }

    std::vector<VertexConstraint> out;
    for (size_t k = 0; k < held.size(); ++k) {
      if (held[k]) out.push_back(VertexConstraint{static_cast<int32_t>(k), settings.mask, Vec3::Zero()});
    }
    return out;
  });
}

Result<DeformationRequest> floor_request(const Tessellation& tessellation, const Eigen::Isometry3d& shell_to_world,
                                         const FloorSettings& settings) {
  if (settings.hold == FloorHold::kControlPoints) {
    auto held = floor_constraints(tessellation, shell_to_world, settings);
    if (!held) return held.error();
    DeformationRequest out;
    out.vertex_constraints = std::move(*held);
    return out;
  }
  return capture([&]() -> DeformationRequest {
    if (!settings.point.allFinite() || !settings.normal.allFinite() || !(settings.normal.norm() > 0.0)) {
      fail(ErrorCode::kInvalidArgument, "the floor plane needs a finite point and a finite, non-zero normal");
    }
    if (!shell_to_world.matrix().allFinite()) fail(ErrorCode::kInvalidArgument, "non-finite shell transform");
    // The plane in the shell's frame, where the tessellation and the constraints live.
    const Eigen::Isometry3d world_to_shell = shell_to_world.inverse();
    Plane plane;
    plane.point = world_to_shell * settings.point;
    plane.normal = world_to_shell.linear() * settings.normal.normalized();
    FloorOptions options;
    options.tolerance = settings.tolerance;
    if (settings.mask == kAxisAll) {
      options.axes = FloorAxes::kAll;
    } else {
      const int axis = coordinate_axis(plane.normal);
      if (axis < 0 || settings.mask != (1u << axis)) {
        fail(ErrorCode::kInvalidArgument,
             "floor hold kLimitPoints takes a mask of all axes or of the floor normal's axis in the shell's frame");
      }
      options.axes = FloorAxes::kNormal;
    }
    auto contact = floor_contact(tessellation, plane, options);
    if (!contact) throw Exception(contact.error());
    DeformationRequest out;
    contact->add_to(out);
    return out;
  });
}

}  // namespace softshell::bullet
