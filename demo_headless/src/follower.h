#pragma once
// The demo's second client (the paper's tablet): it mirrors the master through latest_result on
// its own connection, and measures how far behind it is.

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "demo.h"
#include "softshell/session.h"

namespace softshell::demo {

using Clock = std::chrono::steady_clock;
inline double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// The p-quantile (0..1, nearest rank) of `v`; 0 for none.
inline double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5))];
}

/// When the master got each result, for the follower's lag. Thread-safe.
class Timeline {
 public:
  void stored(uint32_t res_id);
  std::optional<Clock::time_point> when(uint32_t res_id) const;

 private:
  mutable std::mutex mutex_;
  std::map<uint32_t, Clock::time_point> at_;
};

/// Follows geometry `id` on its own thread from construction until `finish`.
class Follower {
 public:
  Follower(std::unique_ptr<Session> session, GeomId id, const Timeline& timeline);
  ~Follower() { finish(0); }
  Follower(const Follower&) = delete;
  Follower& operator=(const Follower&) = delete;

  /// Waits until the follower holds result `last` (or gives up after 20 s) and stops it.
  void finish(uint32_t last);
  DemoReport::Follower report() const { return report_; }
  const std::vector<Vec3>& positions() const { return positions_; }
  const std::string& error() const { return error_; }

 private:
  void run();

  std::unique_ptr<Session> session_;
  GeomId id_;
  const Timeline& timeline_;
  std::mutex mutex_;
  uint32_t target_ = 0;
  bool stopping_ = false;
  DemoReport::Follower report_;
  std::vector<Vec3> positions_;
  std::string error_;
  std::thread thread_;  // last: starts after everything above exists
};

}  // namespace softshell::demo
