#include "context.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>

namespace softshell::demo {

void Context::say(const std::string& line) const {
  if (options.progress) options.progress(line);
}

Result<DeformationResult> Context::solve(const DeformationRequest& extra, DeformationModel with) {
  DeformationRequest request = extra;
  request.model = with;
  const DeformationRequest& s = stage.supports;
  request.vertex_constraints.insert(request.vertex_constraints.end(), s.vertex_constraints.begin(), s.vertex_constraints.end());
  request.lagrange_constraints.insert(request.lagrange_constraints.end(), s.lagrange_constraints.begin(),
                                      s.lagrange_constraints.end());
  request.limit_constraints.insert(request.limit_constraints.end(), s.limit_constraints.begin(), s.limit_constraints.end());
  auto result = session->deform(id, request);
  if (!result) return result.error();
  timeline.stored(result->res_id);
  report.last_res_id = std::max(report.last_res_id, result->res_id);
  ++report.deformations;
  shown = result->positions;
  view->show(result->positions);
  return result;
}

DeformationResult Context::deform(const DeformationRequest& extra, const std::string& phase) {
  const auto start = Clock::now();
  DeformationResult result = solve(extra, model).value();
  latencies.push_back(ms_between(start, Clock::now()));
  Response r = measure_shape(view->surface, view->rest_vertices, view->rest_normals);
  r.res_id = result.res_id;
  range.observe(phase, r);
  return result;
}

double Context::probe_length() const {
  // The model is linear, so a probe can be small enough to stay far inside the range anywhere.
  return 1e-3 * std::min(options.material.thickness, LinearRange::kAimDisplacementPerSize * stage.size);
}

double Context::probe_force() const {
  const double t = options.material.thickness;
  return options.material.youngs_modulus * t * t * t / (stage.size * stage.size) * probe_length();
}

namespace {

// The request with every load and prescribed displacement times k: the linear response is k times
// the request's.
DeformationRequest times(DeformationRequest r, double k) {
  for (VertexConstraint& c : r.vertex_constraints) c.displacement *= k;
  for (LagrangeConstraint& c : r.lagrange_constraints) c.values *= k;
  for (PointForce& f : r.forces) f.force *= k;
  for (LimitConstraint& c : r.limit_constraints) {
    c.displacement *= k;
    if (c.du_displacement) *c.du_displacement *= k;
    if (c.dv_displacement) *c.dv_displacement *= k;
  }
  for (SurfaceForce& f : r.surface_forces) f.force *= k;
  r.surface_load *= k;
  r.pressure *= k;
  return r;
}

// Whether positions came in single precision (every coordinate is a float): a remote server's
// binary results.
bool single_precision(const std::vector<Vec3>& positions) {
  for (const Vec3& p : positions) {
    for (int a = 0; a < 3; ++a) {
      if (static_cast<double>(static_cast<float>(p[a])) != p[a]) return false;
    }
  }
  return true;
}

}  // namespace

double Context::calibrate(const DeformationRequest& given, const std::string& phase) {
  // Results may come in f32 (the binary layout from a remote server): a probe whose shape change
  // is within a few rounding steps of the coordinates would calibrate against rounding noise, so
  // such a probe is sent again, scaled up (the model is linear: the scale is divided back). Results
  // in double precision (in-process, JSON) need no second probe.
  constexpr double kMeasurable = 1e-5;  // of the object's size: ~100 f32 steps
  DeformationRequest probe = given;
  double probe_scale = 1.0;
  model = DeformationModel::kLinear;  // the probe's response is scaled linearly
  DeformationResult result = deform(probe, phase + " (probe)");
  ++report.probes;
  Response r = measure_shape(view->surface, view->rest_vertices, view->rest_normals);
  const bool rounded = single_precision(result.positions);
  for (int again = 0; again < 3 && rounded && r.displacement < kMeasurable * stage.size; ++again) {
    const double k = std::clamp(10.0 * kMeasurable * stage.size / std::max(r.displacement, 1e-30), 10.0, 1e6);
    probe = times(probe, k);
    probe_scale *= k;
    result = deform(probe, phase + " (probe, scaled)");
    ++report.probes;
    r = measure_shape(view->surface, view->rest_vertices, view->rest_normals);
  }
  if (auto field = stresses(result.res_id, 1)) {
    add_stresses(r, *field, options.material);
    range.observe_stresses(phase + " (probe)", *field, options.material);
  }
  const double scale = scale_to_aims(r, stage.size, options.material, yield) * probe_scale;
  if (std::getenv("SOFTSHELL_DEMO_DEBUG")) {
    std::fprintf(stderr, "probe %s: |u| %.3g m, rotation %.3g rad, strain %.3g, nonlinearity %.3g -> scale %.3g\n",
                 phase.c_str(), r.displacement, r.rotation, r.strain.value_or(-1.0), r.nonlinearity().value_or(-1.0), scale);
  }
  return scale * options.load_scale;
}

void Context::choose_model(const std::string& phase) {
  // The linear range is left once the loads are kWarnOverAim times the aims: from there on (or
  // when asked) the phase is solved with the nonlinear model.
  const bool large = options.load_scale > LinearRange::kWarnOverAim;
  model = options.model.value_or(large ? DeformationModel::kNonlinear : DeformationModel::kLinear);
  if (model != DeformationModel::kNonlinear) return;
  range.mark_nonlinear(phase);
  report.nonlinear_phases.push_back(phase);
  if (!options.model) {
    char line[224];
    std::snprintf(line, sizeof line, "%s: loads %.3g times the linear range's aims leave it: solved with the nonlinear model "
                  "(slower; --model linear keeps the linear one)",
                  phase.c_str(), options.load_scale);
    say(line);
  }
}

void Context::check_stresses(const std::string& phase) {
  const Response worst = range.worst(phase);
  if (worst.res_id == 0) return;
  if (auto field = stresses(worst.res_id, 1)) range.observe_stresses(phase, *field, options.material);
}

std::optional<StressField> Context::stresses(uint32_t res_id, int level) {
  if (stresses_unavailable_) return std::nullopt;
  std::string why_not;
  auto field = stresses_of(*session, id, res_id, level, yield, why_not);
  if (!field) {
    stresses_unavailable_ = true;
    report.notes.push_back(why_not);
    say(why_not);
  }
  return field;
}

Snapshot& Context::snapshot(const std::string& file, const std::string& caption) {
  snapshots.push_back({file, caption, shown, {}, {}, {}});
  return snapshots.back();
}

}  // namespace softshell::demo
