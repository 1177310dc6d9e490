// The demo's summary (stdout) and its one-line JSON object (--json).
#include <cmath>
#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

#include "demo.h"

namespace softshell::demo {
namespace {

std::string format(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string length(double m) { return m < 0.1 ? format("%.3g mm", m * 1000.0) : format("%.3g m", m); }

std::string masses(const std::vector<double>& kg) {
  std::string out;
  for (double m : kg) out += (out.empty() ? "" : ", ") + (m < 1.0 ? format("%.3g g", m * 1000.0) : format("%.3g kg", m));
  return out;
}

// A number, or null where there is none (JSON has no NaN).
nlohmann::json optional_number(const std::optional<double>& v) {
  return v && std::isfinite(*v) ? nlohmann::json(*v) : nlohmann::json(nullptr);
}

nlohmann::json holds_json(const HoldVersions& holds) {
  nlohmann::json out = nlohmann::json::object();
  for (const auto& [id, version] : holds) out[id] = version;
  return out;
}

}  // namespace

std::string format_summary(const DemoReport& r) {
  std::ostringstream s;
  const auto& st = r.setup;
  s << "softshell-demo: " << r.mesh << " (" << r.control_points << " control points, " << r.faces << " faces), "
    << r.material << ", " << r.server << " server\n";
  s << "  object               " << length(st.height) << " tall, " << st.up << " up" << (st.up_detected ? " (detected)" : "")
    << ", size " << length(st.size) << "; " << st.supports << "\n";
  if (r.precomputed_now) {
    s << "  precompute           " << format("%.0f", r.precompute_ms)
      << " ms   (paper Table 1: 7-82 s for 210-472 control points)\n";
  } else {
    s << "  precompute           none: the server already held this geometry (uploaded before)\n";
  }
  s << "  loads                grab " << length(r.loads.grab) << ", push " << format("%.3g N", r.loads.push);
  if (!r.loads.box_masses.empty()) s << ", boxes of " << masses(r.loads.box_masses);
  s << " (scaled to stay inside the linear model's range)\n";
  s << "  deformations         " << r.deformations << " (" << r.probes
    << " calibration probes; grab, push, tangent grab, " << (r.large_pull.ran ? "large pull, " : "")
    << "two hands; supports held)\n"
    << "  latency per request  p50 " << format("%.2f", r.latency_p50_ms) << " ms, p95 " << format("%.2f", r.latency_p95_ms)
    << " ms, max " << format("%.2f", r.latency_max_ms) << " ms   (paper: 2-75 ms solve, 1-5 frames = up to 83 ms end to end)\n"
    << "  follower             ";
  if (r.follower.ran) {
    s << "received " << r.follower.received << ", final result " << r.follower.final_res_id
      << (r.follower.matches_master ? " = master's last" : " (DIFFERS from the master's last)") << ", max lag "
      << format("%.2f", r.follower.max_lag_ms) << " ms\n";
  } else {
    s << "not run\n";
  }
  s << "  Bullet               ";
  if (r.bullet.ran) {
    s << r.bullet.bodies << (r.bullet.bodies == 1 ? " box, " : " boxes, ") << r.bullet.on_shell << " resting on the shell, "
      << r.bullet.contacts << " contact points, " << r.bullet.requests << " requests, max dent "
      << length(r.bullet.max_deflection) << "\n";
  } else {
    s << "no boxes\n";
  }
  if (r.multi_user.ran) {
    const auto& m = r.multi_user;
    s << "  shared (2 users)     ";
    if (!m.error.empty()) s << "FAILED: " << m.error << "\n                       ";
    s << "hold updates " << (m.updates.size() == 2 ? std::to_string(m.updates[0]) + " + " + std::to_string(m.updates[1]) : "0")
      << ", answered p50 " << format("%.2f", m.update_p50_ms) << " ms, p95 " << format("%.2f", m.update_p95_ms) << " ms; "
      << m.bodies << (m.bodies == 1 ? " box" : " boxes") << " (" << m.on_shell << " on the shell) and the floor as holds\n"
      << "                       " << m.solves << " solves, " << format("%.2f", m.merged_mean) << " new hold versions per solve (max "
      << m.merged_max << ", over " << m.solves_measured << " seen in sequence)\n"
      << "                       follower (events) took " << m.follower_received << ", lag p50 " << format("%.2f", m.follower_lag_p50_ms)
      << " ms, max " << format("%.2f", m.follower_lag_max_ms) << " ms; final result " << m.final_res_id
      << (m.follower_matches ? " = follower's" : " (the follower DIFFERS)") << ", holds";
    for (const auto& [id, v] : m.final_holds) s << " " << id << "@" << v;
    s << (m.includes_every_user ? " (both users' last versions)" : " (MISSING a user's last version)") << "\n";
  }
  s << "  final state          max |u| " << length(r.final.max_displacement) << ", max rotation "
    << format("%.2g deg", r.final.max_rotation * 180.0 / 3.14159265358979) << ", max von Mises ";
  if (r.final.max_von_mises) {
    s << format("%.3g MPa", *r.final.max_von_mises / 1e6) << " (strain " << format("%.2g%%", 100.0 * r.final.max_strain.value_or(0))
      << (r.final.exceeds_yield ? ", above yield!)" : ")") << "\n";
  } else {
    s << "unavailable\n";
  }
  if (r.large_pull.ran) {
    const auto& p = r.large_pull;
    s << "  large pull           " << length(p.distance) << " (" << format("%.0f%%", 100.0 * p.per_size)
      << " of the size), surface area over rest: linear " << format("%.3g", p.linear_area_ratio) << ", nonlinear ";
    if (p.nonlinear_area_ratio) {
      s << format("%.3g", *p.nonlinear_area_ratio) << " (" << p.nonlinear_iterations << " Newton iterations, "
        << format("%.0f ms", p.nonlinear_ms) << ")\n";
    } else {
      s << "refused by the server: " << p.nonlinear_refused << "\n";
    }
  }
  if (!r.nonlinear_phases.empty()) {
    s << "  nonlinear model      ";
    for (size_t i = 0; i < r.nonlinear_phases.size(); ++i) s << (i ? ", " : "") << r.nonlinear_phases[i];
    s << "\n";
  }
  s << "  linear range         " << (r.warnings.empty() ? "every result inside" : std::to_string(r.warnings.size()) + " warning(s):")
    << "\n";
  for (const auto& w : r.warnings) s << "    - " << w << "\n";
  for (const auto& n : r.notes) s << "  note                 " << n << "\n";
  s << "  outputs             ";
  for (const auto& o : r.outputs) s << " " << o;
  s << "\n";
  return s.str();
}

std::string format_json(const DemoReport& r) {
  const auto& st = r.setup;
  nlohmann::json j = {
      {"mesh", r.mesh},
      {"mesh_path", r.mesh_path},
      {"material", r.material},
      {"server", r.server},
      {"setup",
       {{"up", std::string(1, st.up)}, {"up_detected", st.up_detected}, {"size", st.size}, {"height", st.height},
        {"parts", st.parts}, {"resting_parts", st.resting_parts}, {"floor_points", st.floor_points}, {"pins", st.pins},
        {"supports", st.supports}}},
      {"precomputed_now", r.precomputed_now},
      {"precompute_ms", r.precomputed_now ? nlohmann::json(r.precompute_ms) : nlohmann::json(nullptr)},
      {"loads", {{"grab", r.loads.grab}, {"push", r.loads.push}, {"box_masses", r.loads.box_masses}}},
      {"deformations", r.deformations},
      {"probes", r.probes},
      {"latency_ms", {{"p50", r.latency_p50_ms}, {"p95", r.latency_p95_ms}, {"max", r.latency_max_ms}}},
      {"follower",
       {{"ran", r.follower.ran}, {"received", r.follower.received}, {"final_res_id", r.follower.final_res_id}, {"max_lag_ms", r.follower.max_lag_ms},
        {"matches_master", r.follower.matches_master}}},
      {"bullet",
       {{"ran", r.bullet.ran}, {"bodies", r.bullet.bodies}, {"on_shell", r.bullet.on_shell}, {"contacts", r.bullet.contacts},
        {"requests", r.bullet.requests}, {"max_deflection", r.bullet.max_deflection}}},
      {"multi_user",
       {{"ran", r.multi_user.ran}, {"users", r.multi_user.users}, {"updates", r.multi_user.updates},
        {"update_latency_ms", {{"p50", r.multi_user.update_p50_ms}, {"p95", r.multi_user.update_p95_ms}}},
        {"solves", r.multi_user.solves}, {"solves_measured", r.multi_user.solves_measured},
        {"merged_per_solve", {{"mean", r.multi_user.merged_mean}, {"max", r.multi_user.merged_max}}},
        {"bodies", r.multi_user.bodies}, {"on_shell", r.multi_user.on_shell},
        {"follower", {{"received", r.multi_user.follower_received}, {"lag_ms", {{"p50", r.multi_user.follower_lag_p50_ms}, {"max", r.multi_user.follower_lag_max_ms}}}}},
        {"final_res_id", r.multi_user.final_res_id}, {"final_holds", holds_json(r.multi_user.final_holds)},
        {"includes_every_user", r.multi_user.includes_every_user}, {"follower_matches", r.multi_user.follower_matches},
        {"error", r.multi_user.error}}},
      {"final",
       {{"max_displacement", r.final.max_displacement}, {"max_von_mises", optional_number(r.final.max_von_mises)},
        {"max_rotation", r.final.max_rotation}, {"max_strain", optional_number(r.final.max_strain)},
        {"exceeds_yield", r.final.exceeds_yield}}},
      {"large_pull",
       {{"ran", r.large_pull.ran}, {"distance", r.large_pull.distance}, {"per_size", r.large_pull.per_size},
        {"area_ratio", {{"linear", r.large_pull.ran ? nlohmann::json(r.large_pull.linear_area_ratio) : nlohmann::json(nullptr)},
                        {"nonlinear", optional_number(r.large_pull.nonlinear_area_ratio)}}},
        {"nonlinear_refused", r.large_pull.nonlinear_refused}, {"nonlinear_iterations", r.large_pull.nonlinear_iterations},
        {"ms", {{"linear", r.large_pull.linear_ms}, {"nonlinear", r.large_pull.nonlinear_ms}}}}},
      {"nonlinear_phases", r.nonlinear_phases},
      {"warnings", r.warnings},
      {"notes", r.notes},
      {"outputs", r.outputs},
  };
  return j.dump();
}

}  // namespace softshell::demo
