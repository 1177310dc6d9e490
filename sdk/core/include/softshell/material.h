#pragma once
/// \file
/// \brief `Material`: isotropic linear-elastic shell material (E, nu, t).

#include <string>
#include <string_view>
#include <vector>

#include "softshell/result.h"

namespace softshell {

/// Isotropic, linear-elastic thin-shell material.
///
/// Units: any consistent set. In SI (positions in metres) E is in Pa = N/m², t in metres, forces
/// in N, and a surface load in N/m². The presets are SI.
struct Material {
  double youngs_modulus = 6.9e10;  ///< E (Pa = N/m²), must be > 0 and finite
  double poisson_ratio = 0.33;     ///< nu (dimensionless), must be in (-1, 0.5)
  double thickness = 0.001;        ///< t (m, the mesh's length unit), must be > 0 and finite
  double density = 2700.0;         ///< rho (kg/m³), for self-weight helpers; not part of the wire format

  /// Membrane stiffness E t / (1 - nu²).
  double membrane_stiffness() const;
  /// Bending stiffness D = E t³ / (12 (1 - nu²)).
  double bending_stiffness() const;

  /// Ok, or kUnprocessable with a message naming the bad field and the allowed range.
  Result<void> check() const;

  bool operator==(const Material&) const = default;
};

/// A named material preset (SI units), e.g. `"aluminium"`, `"steel"`, `"rubber"`.
struct MaterialPreset {
  std::string name;
  Material material;
  std::string description;
  double yield_strength = 0.0;  ///< Pa: above it the linear elastic model no longer holds
};

/// All presets: aluminium, steel, copper, titanium, glass, abs, polycarbonate, wood, cardboard,
/// rubber, silicone.
const std::vector<MaterialPreset>& material_presets();

/// Preset by name (case-insensitive), with the given thickness in metres. Unknown names give
/// kInvalidArgument listing the known ones.
Result<Material> material_preset(std::string_view name, double thickness = 0.001);

}  // namespace softshell
