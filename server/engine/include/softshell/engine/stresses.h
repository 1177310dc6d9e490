#pragma once
/// \file
/// \brief Stresses of a solved deformation: membrane forces, bending moments and von Mises stress
/// at the top and bottom surfaces (linear Kirchhoff-Love shell).

#include <vector>

#include <Eigen/Core>

#include "softshell/engine/shell_model.h"
#include "softshell/stresses.h"

namespace softshell::engine {

using softshell::StressSample;

/// Stresses at a point for a displacement vector (3n). At an extraordinary vertex itself, where
/// the curvature of a Catmull-Clark surface vanishes or diverges, they are taken 2^-10 inside
/// the face (in its (u, v)); the position is the vertex's. Throws Exception(kInvalidArgument) for a
/// bad point or vector size.
StressSample evaluate_stress(const ShellModel& model, const Eigen::VectorXd& displacement, const SurfacePoint& point);

/// Stresses at many points (each face's basis set up once), in the order given. Throws
/// Exception(kInvalidArgument) for a bad point or vector size.
std::vector<StressSample> evaluate_stresses(const ShellModel& model, const Eigen::VectorXd& displacement,
                                            const std::vector<SurfacePoint>& points);

/// The largest von Mises stress over the quadrature points of the whole surface and where it is.
struct StressSummary {
  StressSample max;          ///< the sample with the largest von Mises stress
  bool exceeds_yield = false; ///< max.von_mises() > yield_strength (the linear model is not valid there)
};
StressSummary max_stress(const ShellModel& model, const Eigen::VectorXd& displacement, double yield_strength);

}  // namespace softshell::engine
