#include "linear_range.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace softshell::demo {
namespace {

std::string number(double v, const char* format = "%.3g") {
  char buf[48];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string length(double metres) {
  return std::abs(metres) < 0.1 ? number(metres * 1000.0) + " mm" : number(metres) + " m";
}

constexpr const char* kRemedy =
    "use smaller loads (--load-scale), a thicker or stiffer material, or the nonlinear model "
    "(--model nonlinear)";

}  // namespace

std::optional<double> Response::nonlinearity() const {
  if (!strain || !(*strain > 0.0)) return std::nullopt;
  return 0.5 * rotation * rotation / *strain;
}

Response measure_shape(const Tessellation& shown, const std::vector<Vec3>& rest_vertices,
                       const std::vector<Vec3>& rest_normals) {
  Response r;
  const auto& v = shown.vertices();
  const auto& n = shown.normals();
  for (size_t i = 0; i < v.size() && i < rest_vertices.size(); ++i) {
    r.displacement = std::max(r.displacement, (v[i] - rest_vertices[i]).norm());
    const double angle = std::atan2(n[i].cross(rest_normals[i]).norm(), n[i].dot(rest_normals[i]));
    if (std::isfinite(angle)) r.rotation = std::max(r.rotation, angle);
  }
  return r;
}

double surface_area(const std::vector<Vec3>& vertices, const std::vector<std::array<int32_t, 3>>& triangles) {
  double area = 0.0;
  for (const auto& t : triangles) {
    const Vec3& a = vertices[static_cast<size_t>(t[0])];
    area += 0.5 * (vertices[static_cast<size_t>(t[1])] - a).cross(vertices[static_cast<size_t>(t[2])] - a).norm();
  }
  return area;
}

double scale_to_aims(const Response& probe, double size, const Material& material, double yield) {
  using L = LinearRange;
  double scale = std::numeric_limits<double>::infinity();
  const auto limit = [&](double allowed, double per_probe) {
    if (per_probe > 0.0 && std::isfinite(per_probe)) scale = std::min(scale, allowed / per_probe);
  };
  limit(L::kAimDisplacementPerSize * size, probe.displacement);
  limit(L::kAimRotation, probe.rotation);
  if (probe.strain) {
    // Strain scales with the load, nonlinearity (rotation^2 / strain) too.
    limit(L::kAimStrain, *probe.strain);
    if (yield > 0.0) limit(L::kAimYieldFraction * yield, probe.von_mises.value_or(0.0));
    if (auto eta = probe.nonlinearity()) limit(L::kAimNonlinearity, *eta);
  } else {
    limit(L::kAimDisplacementPerThickness * material.thickness, probe.displacement);
  }
  return std::isfinite(scale) ? scale : 1.0;
}

std::optional<StressField> stresses_of(Session& session, const GeomId& id, uint32_t res_id, int level, double yield,
                                       std::string& why_not) {
  StressQuery query;
  query.level = std::clamp(level, 1, StressQuery::kMaxLevel);
  query.yield_strength = yield;
  auto field = session.stresses(id, res_id, query);
  if (field) return std::move(*field);
  // The geometry and the result exist (we just made them): a 404 means the route does not.
  const ErrorCode code = field.error().code;
  if (code == ErrorCode::kNotFound || code == ErrorCode::kNotAcceptable || code == ErrorCode::kUnsupportedMediaType) {
    why_not = "stresses are unavailable: the server does not offer them (" + field.error().message +
              "); the loads are kept below " + number(LinearRange::kAimDisplacementPerThickness) +
              " thicknesses of deflection instead, and no strain or yield check is made";
    return std::nullopt;
  }
  throw Exception(field.error());
}

void add_stresses(Response& r, const StressField& field, const Material& material) {
  // The field's maximum is over the quadrature points; the queried points (tessellation
  // vertices, one of them at a grabbed point) can lie higher.
  double max = field.max.von_mises();
  for (const StressSample& s : field.samples) max = std::max(max, s.von_mises());
  r.von_mises = max;
  r.strain = *r.von_mises / material.youngs_modulus;
  r.exceeds_yield = field.exceeds_yield;
}

Response* RangeMonitor::find(const std::string& phase) {
  for (auto& [name, r] : phases_) {
    if (name == phase) return &r;
  }
  return nullptr;
}

void RangeMonitor::observe(const std::string& phase, const Response& r) {
  Response* worst = find(phase);
  if (!worst) {
    phases_.emplace_back(phase, r);
    return;
  }
  if (r.displacement > worst->displacement) {
    worst->displacement = r.displacement;
    worst->res_id = r.res_id;
  }
  worst->rotation = std::max(worst->rotation, r.rotation);
}

void RangeMonitor::observe_stresses(const std::string& phase, const StressField& field, const Material& material) {
  if (Response* worst = find(phase)) add_stresses(*worst, field, material);
}

Response RangeMonitor::worst(const std::string& phase) const {
  for (const auto& [name, r] : phases_) {
    if (name == phase) return r;
  }
  return {};
}

void RangeMonitor::mark_nonlinear(const std::string& phase) {
  if (std::find(nonlinear_.begin(), nonlinear_.end(), phase) == nonlinear_.end()) nonlinear_.push_back(phase);
}

std::vector<std::string> RangeMonitor::warnings(double size, const Material& material, double yield,
                                                const std::string& material_name) const {
  using L = LinearRange;
  std::vector<std::string> out;
  for (const auto& [phase, r] : phases_) {
    const std::string who = phase + ": ";
    const bool nonlinear = std::find(nonlinear_.begin(), nonlinear_.end(), phase) != nonlinear_.end();
    // Large displacements and rotations are the nonlinear model's range; the material's limits
    // (strain, yield) hold for both models.
    if (!nonlinear && r.displacement > L::kWarnDisplacementPerSize * size) {
      out.push_back(who + "the largest displacement, " + length(r.displacement) + ", is " +
                    number(100.0 * r.displacement / size, "%.1f") + "% of the object's size (" + length(size) +
                    "); the linear model assumes small displacements: " + kRemedy);
    }
    if (!nonlinear && r.rotation > L::kWarnRotation) {
      out.push_back(who + "the surface turns by up to " + number(r.rotation * 180.0 / 3.14159265358979, "%.0f") +
                    " degrees; the linear model assumes small rotations: " + kRemedy);
    }
    const auto eta = r.nonlinearity();
    if (!nonlinear && eta && *eta > L::kWarnNonlinearity) {
      out.push_back(who + "the stretching that rotations of " + number(r.rotation) +
                    " rad cause (which the linear model leaves out) is " + number(*eta, "%.2g") +
                    " times the strain it computes; a thin shell bent this far (" + length(r.displacement) + ", " +
                    number(r.displacement / material.thickness, "%.2g") + " thicknesses) also stretches: " + kRemedy);
    } else if (!nonlinear && !r.strain && r.displacement > 2.0 * L::kWarnNonlinearity * material.thickness) {  // w / 2t
      out.push_back(who + "the largest displacement, " + length(r.displacement) + ", is " +
                    number(r.displacement / material.thickness, "%.2g") +
                    " thicknesses; a thin shell bent further than its thickness also stretches, which the linear "
                    "model leaves out: " + kRemedy);
    }
    if (r.strain && *r.strain > L::kWarnStrain) {
      out.push_back(who + "strains reach " + number(100.0 * *r.strain, "%.2g") +
                    "%; the linear elastic material holds to about " + number(100.0 * L::kWarnStrain, "%.0f") + "%: " +
                    (nonlinear ? std::string("use smaller loads (--load-scale) or a thicker or stiffer material")
                               : std::string(kRemedy)));
    }
    if (r.exceeds_yield) {
      out.push_back(who + "the von Mises stress, " + number(r.von_mises.value_or(0.0) / 1e6) +
                    " MPa, is above the yield strength of " + material_name + " (" + number(yield / 1e6) +
                    " MPa): the material would deform permanently; use smaller loads (--load-scale) or a thicker "
                    "or stronger material");
    }
  }
  return out;
}

}  // namespace softshell::demo
