#pragma once
// The linear model's range. softshell's shell model is linear: it measures strain against the
// rest shape and leaves out what rotations do to it. The demo measures every result
// (displacement, rotation of the surface, strain), warns past the limits below, and scales its
// loads from a probe so that each phase stays at the aims, well inside them.
//
// Why these measures: a rotation by theta stretches a line by theta^2 / 2, which the linear
// strain omits; once that is not small against the strain the model does compute, the answer is
// off (for a bent thin plate or shell the ratio is about w / 2t: the linear model holds for
// deflections below the thickness, then the shell also stretches, stiffens or snaps through).
// Strains of a few per cent and stresses above yield leave the linear elastic material itself.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "softshell/material.h"
#include "softshell/session.h"
#include "softshell/tessellation.h"

namespace softshell::demo {

/// What one result did to the surface: maxima over the tessellation's vertices (displacement,
/// rotation) and over the stress quadrature points (stress, strain).
struct Response {
  uint32_t res_id = 0;
  double displacement = 0.0;         ///< m
  double rotation = 0.0;             ///< rad, between rest and deformed normals
  std::optional<double> von_mises;   ///< Pa (empty: no stresses)
  std::optional<double> strain;      ///< von Mises stress / E
  bool exceeds_yield = false;
  /// (rotation^2 / 2) / strain: the strain the linear model leaves out against the one it computes.
  std::optional<double> nonlinearity() const;
};

/// Where the demo warns, and what it aims for (two fifths of each limit).
struct LinearRange {
  static constexpr double kWarnDisplacementPerSize = 0.05;
  static constexpr double kWarnRotation = 0.25;          ///< rad, about 14 degrees
  static constexpr double kWarnNonlinearity = 0.5;
  static constexpr double kWarnStrain = 0.05;            ///< Hooke's law and the linear strain: a few per cent
  static constexpr double kAimDisplacementPerSize = 0.02;
  static constexpr double kAimRotation = 0.1;
  static constexpr double kAimNonlinearity = 0.2;
  static constexpr double kAimStrain = 0.02;
  static constexpr double kAimYieldFraction = 0.4;       ///< of the yield strength
  /// Without stresses, deflections are kept below this many thicknesses (nonlinearity ~ w / 2t).
  static constexpr double kAimDisplacementPerThickness = 0.4;
  /// Each warning limit is this many times its aim: loads scaled past it (--load-scale) leave the
  /// linear range.
  static constexpr double kWarnOverAim = 2.5;
};

/// Displacement and rotation of the shape `shown` against the rest shape (same tessellation).
Response measure_shape(const Tessellation& shown, const std::vector<Vec3>& rest_vertices,
                       const std::vector<Vec3>& rest_normals);

/// The area of a triangulated surface (e.g. a tessellation of the limit surface).
double surface_area(const std::vector<Vec3>& vertices, const std::vector<std::array<int32_t, 3>>& triangles);

/// The factor by which a probe's loads may be multiplied (the model is linear) to bring its
/// response to the aims. `yield` in Pa, 0 = unknown.
double scale_to_aims(const Response& probe, double size, const Material& material, double yield);

/// Stresses of a stored result at a tessellation level (1..4; the maximum is over the whole
/// surface in any case), or empty with `why_not` set if the server offers none (a server without
/// the stresses route answers 404). Other errors throw.
std::optional<StressField> stresses_of(Session& session, const GeomId& id, uint32_t res_id, int level, double yield,
                                       std::string& why_not);

/// Adds a stress field's maxima (over its quadrature points and its samples) to a response.
void add_stresses(Response& r, const StressField& field, const Material& material);

/// The worst response of each phase of the script, and the warnings they call for.
class RangeMonitor {
 public:
  /// Keeps the largest displacement and rotation seen in `phase` (and that result's id).
  void observe(const std::string& phase, const Response& r);
  /// Stresses of the phase's worst result (see `worst`).
  void observe_stresses(const std::string& phase, const StressField& field, const Material& material);
  /// The result with the largest displacement seen in a phase (res_id 0 if none).
  Response worst(const std::string& phase) const;
  /// The phase is solved with the nonlinear model: large displacements and rotations are in its
  /// range (only the material's limits, strain and yield, are checked).
  void mark_nonlinear(const std::string& phase);
  /// One warning per phase and measure past its limit, each saying what to do.
  std::vector<std::string> warnings(double size, const Material& material, double yield,
                                    const std::string& material_name) const;

 private:
  Response* find(const std::string& phase);
  std::vector<std::pair<std::string, Response>> phases_;  // in the order first seen
  std::vector<std::string> nonlinear_;
};

}  // namespace softshell::demo
