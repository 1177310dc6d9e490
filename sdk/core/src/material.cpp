#include "softshell/material.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>

namespace softshell {

double Material::membrane_stiffness() const {
  return youngs_modulus * thickness / (1.0 - poisson_ratio * poisson_ratio);
}

double Material::bending_stiffness() const {
  return youngs_modulus * thickness * thickness * thickness / (12.0 * (1.0 - poisson_ratio * poisson_ratio));
}

Result<void> Material::check() const {
  auto bad = [](const std::string& message) { return Error{ErrorCode::kUnprocessable, message}; };
  std::ostringstream value;
  if (!std::isfinite(youngs_modulus) || youngs_modulus <= 0.0) {
    value << youngs_modulus;
    return bad("Young's modulus must be a positive finite number (in Pa), got " + value.str());
  }
  if (!std::isfinite(poisson_ratio) || poisson_ratio <= -1.0 || poisson_ratio >= 0.5) {
    value << poisson_ratio;
    return bad("Poisson's ratio must lie strictly between -1 and 0.5, got " + value.str());
  }
  if (!std::isfinite(thickness) || thickness <= 0.0) {
    value << thickness;
    return bad("thickness must be a positive finite number (in the mesh's length unit), got " + value.str());
  }
  if (!std::isfinite(density) || density < 0.0) {
    value << density;
    return bad("density must be a non-negative finite number (kg/m^3), got " + value.str());
  }
  return {};
}

const std::vector<MaterialPreset>& material_presets() {
  // Typical room-temperature values (E in Pa, density in kg/m^3); thickness is set by the caller.
  static const std::vector<MaterialPreset> presets = {
      // name, {E, nu, t, rho}, description, yield (or tensile) strength
      {"aluminium", {6.9e10, 0.33, 0.001, 2700}, "aluminium alloy sheet (6061-T6)", 2.76e8},
      {"steel", {2.0e11, 0.30, 0.001, 7850}, "structural steel (S235)", 2.35e8},
      {"copper", {1.17e11, 0.34, 0.001, 8960}, "copper sheet (annealed)", 7.0e7},
      {"titanium", {1.1e11, 0.34, 0.001, 4500}, "titanium alloy (Ti-6Al-4V)", 8.8e8},
      {"glass", {7.0e10, 0.22, 0.001, 2500}, "soda-lime glass (brittle: the linear model ends at fracture)", 4.0e7},
      {"abs", {2.3e9, 0.35, 0.001, 1050}, "ABS plastic", 4.0e7},
      {"polycarbonate", {2.4e9, 0.37, 0.001, 1200}, "polycarbonate plastic", 6.0e7},
      {"wood", {1.1e10, 0.30, 0.001, 600}, "wood veneer (isotropic approximation)", 4.0e7},
      {"cardboard", {3.0e9, 0.30, 0.001, 700}, "paperboard (isotropic approximation)", 1.0e7},
      {"rubber", {5.0e6, 0.49, 0.001, 1100}, "natural rubber (small-strain modulus)", 1.5e7},
      {"silicone", {1.0e6, 0.49, 0.001, 1100}, "soft silicone (small-strain modulus)", 5.0e6},
  };
  return presets;
}

Result<Material> material_preset(std::string_view name, double thickness) {
  std::string lower(name);
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  if (lower == "aluminum") lower = "aluminium";
  for (const auto& preset : material_presets()) {
    if (preset.name == lower) {
      Material m = preset.material;
      m.thickness = thickness;
      if (auto ok = m.check(); !ok) return Error{ErrorCode::kInvalidArgument, ok.error().message};
      return m;
    }
  }
  std::string known;
  for (const auto& preset : material_presets()) known += (known.empty() ? "" : ", ") + preset.name;
  return Error{ErrorCode::kInvalidArgument, "unknown material '" + std::string(name) + "'; known: " + known};
}

}  // namespace softshell
