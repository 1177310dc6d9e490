#include "shell_settings.h"

#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <random>

namespace softshell::bullet {

void check_settings(const ShellSettings& s) {
  const auto& c = s.contacts;
  if (!std::isfinite(s.response_time) || s.response_time < 0.0) {
    fail(ErrorCode::kInvalidArgument, "response time must be finite and >= 0 (s)");
  }
  if (std::isnan(c.contact_threshold)) fail(ErrorCode::kInvalidArgument, "contact threshold is NaN");
  if (!std::isfinite(c.min_force) || c.min_force < 0.0) {
    fail(ErrorCode::kInvalidArgument, "minimum contact force must be finite and >= 0 (N)");
  }
  if (!std::isfinite(c.force_scale) || c.force_scale <= 0.0) {
    fail(ErrorCode::kInvalidArgument, "force scale must be finite and > 0");
  }
  if (!std::isfinite(s.max_request_rate) || s.max_request_rate < 0.0) {
    fail(ErrorCode::kInvalidArgument, "max request rate must be finite and >= 0 (requests per second; 0 = unlimited)");
  }
  if (!std::isfinite(s.min_relative_change) || s.min_relative_change < 0.0) {
    fail(ErrorCode::kInvalidArgument, "min relative change must be finite and >= 0");
  }
  if (!std::isfinite(s.friction) || s.friction < 0.0) fail(ErrorCode::kInvalidArgument, "friction must be >= 0");
  if (!std::isfinite(s.restitution) || s.restitution < 0.0 || s.restitution > 1.0) {
    fail(ErrorCode::kInvalidArgument, "restitution must be in [0, 1]");
  }
  if (s.holds.enabled) {
    const std::string& name = s.holds.name;
    if (name.size() > kMaxHoldIdLength - 9) {  // room for ".contacts"
      fail(ErrorCode::kInvalidArgument, "the holds' name is at most " + std::to_string(kMaxHoldIdLength - 9) +
                                            " characters (the hold ids add \".floor\" and \".contacts\")");
    }
    for (char ch : name) {
      if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '.' && ch != '_' && ch != '-') {
        fail(ErrorCode::kInvalidArgument, "the holds' name '" + name + "' has a character outside [A-Za-z0-9._-]");
      }
    }
    if (s.holds.ttl.count() <= 0 || s.holds.ttl > std::chrono::seconds(600)) {
      fail(ErrorCode::kInvalidArgument, "the holds' ttl must be more than 0 and at most 600 s");
    }
  }
  const btTransform& t = s.transform;
  for (int r = 0; r < 3; ++r) {
    if (!std::isfinite(t.getOrigin()[r]) || !std::isfinite(t.getBasis()[r].x()) ||
        !std::isfinite(t.getBasis()[r].y()) || !std::isfinite(t.getBasis()[r].z())) {
      fail(ErrorCode::kInvalidArgument, "shell transform is not finite");
    }
  }
}

std::string random_hold_name() {
  static std::mutex mutex;
  static std::mt19937 random(std::random_device{}());
  std::lock_guard lock(mutex);
  char buf[24];
  std::snprintf(buf, sizeof buf, "bullet-%08x", static_cast<unsigned>(random()));
  return buf;
}

}  // namespace softshell::bullet
