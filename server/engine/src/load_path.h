#pragma once
// How the prescribed displacements of a nonlinear solve are approached through its load steps
// (private). Control points prescribed on all three axes that move together as a rigid body (up
// to a residual deformation) follow the rotation, not the straight line between start and end: a
// part turned by 180 degrees would otherwise pass through a state where it is squashed flat onto
// its axis. Everything else moves along straight lines.

#include <vector>

#include <Eigen/Core>

#include "problem.h"
#include "softshell/control_mesh.h"

namespace softshell::engine::internal {

class PrescribedPath {
 public:
  /// From displacement `u0` to the problem's prescribed values.
  PrescribedPath(const ControlMesh& mesh, const Problem& p, const Eigen::VectorXd& u0);

  /// Writes the prescribed DOFs of `u` at path parameter `lambda` in [0, 1] (exact at 1).
  void apply(double lambda, Eigen::VectorXd& u) const;

  /// The largest turn (radians) of a rigidly moving group.
  double largest_turn() const;

 private:
  struct Group {
    std::vector<int32_t> points;
    Vec3 from_centre = Vec3::Zero(), to_centre = Vec3::Zero();
    Vec3 axis = Vec3::UnitZ();
    double angle = 0.0;
    std::vector<Vec3> offsets;   // start position minus start centre, per point
    std::vector<Vec3> residual;  // end position minus the rigid motion of the start, per point
  };
  const ControlMesh& mesh_;
  const Problem& p_;
  Eigen::VectorXd start_;  // per prescribed DOF (in p.fixed order), its value at u0
  std::vector<Group> groups_;
};

/// The largest change of `du` along a mesh edge over the edge's length: the rotation (radians)
/// a displacement increment implies, to first order.
double largest_edge_rotation(const ControlMesh& mesh, const Eigen::VectorXd& du);

}  // namespace softshell::engine::internal
