#include "follower.h"

namespace softshell::demo {

void Timeline::stored(uint32_t res_id) {
  std::lock_guard lock(mutex_);
  at_[res_id] = Clock::now();
}

std::optional<Clock::time_point> Timeline::when(uint32_t res_id) const {
  std::lock_guard lock(mutex_);
  auto it = at_.find(res_id);
  if (it == at_.end()) return std::nullopt;
  return it->second;
}

Follower::Follower(std::unique_ptr<Session> session, GeomId id, const Timeline& timeline)
    : session_(std::move(session)), id_(id), timeline_(timeline), thread_([this] { run(); }) {}

void Follower::finish(uint32_t last) {
  {
    std::lock_guard lock(mutex_);
    target_ = last;
    stopping_ = true;
  }
  if (thread_.joinable()) thread_.join();
}

void Follower::run() {
  uint32_t have = 0;
  auto give_up = Clock::time_point::max();
  while (true) {
    {
      std::lock_guard lock(mutex_);
      if (stopping_ && have >= target_) break;
      if (stopping_ && give_up == Clock::time_point::max()) give_up = Clock::now() + std::chrono::seconds(20);
    }
    if (Clock::now() > give_up) {
      error_ = "the follower did not receive result " + std::to_string(target_) + " in time";
      break;
    }
    auto answer = session_->latest_result(id_, have, std::chrono::milliseconds(500));
    if (!answer) {
      error_ = answer.error().message;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    if (!*answer) continue;  // 204: nothing newer yet
    const auto received = Clock::now();
    const DeformationResult& result = **answer;
    have = result.res_id;
    positions_ = result.positions;
    ++report_.received;
    report_.final_res_id = have;
    if (auto stored = timeline_.when(have)) {
      report_.max_lag_ms = std::max(report_.max_lag_ms, std::max(0.0, ms_between(*stored, received)));
    }
  }
}

}  // namespace softshell::demo
