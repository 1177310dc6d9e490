#include "softshell/hold_lease.h"

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <thread>

namespace softshell {

using Clock = std::chrono::steady_clock;

struct HoldLease::State {
  Session* session = nullptr;
  GeomId id;
  std::string hold_id;
  HoldLeaseOptions options;

  mutable std::mutex mu;
  std::condition_variable cv;
  std::optional<DeformationRequest> pending;   // contents to send (latest wins)
  std::optional<DeformationRequest> accepted;  // the contents the server holds (what renewals send)
  Clock::time_point renew_at{};
  std::optional<HeldResult> latest;
  std::optional<Error> error;
  uint64_t version = 0, puts = 0;
  bool stopping = false, released = false;
  std::thread thread;

  std::chrono::milliseconds renew_period() const {
    return std::chrono::milliseconds(std::max<int64_t>(1, static_cast<int64_t>(static_cast<double>(options.ttl.count()) * options.renew_after)));
  }

  // Refusals of the server: sending the same contents again cannot help.
  static bool refused(ErrorCode code) {
    return code == ErrorCode::kConflict || code == ErrorCode::kUnprocessable || code == ErrorCode::kInvalidArgument ||
           code == ErrorCode::kNotFound || code == ErrorCode::kPayloadTooLarge;
  }

  void run() {
    std::chrono::milliseconds retry = options.retry_min;
    std::unique_lock lock(mu);
    for (;;) {
      // Sleep until there are contents to send, a renewal is due, or the lease ends.
      const auto due = [&] { return stopping || pending || (accepted && Clock::now() >= renew_at); };
      if (accepted) cv.wait_until(lock, renew_at, due);
      else cv.wait(lock, due);
      if (stopping) return;
      const bool change = pending.has_value();
      if (!change && !(accepted && Clock::now() >= renew_at)) continue;
      DeformationRequest body = change ? std::move(*pending) : *accepted;
      pending.reset();
      ++puts;
      lock.unlock();
      Result<HeldResult> answer = session->put_hold(id, hold_id, body, options.ttl);
      lock.lock();
      if (answer) {
        if (answer->holds) version = std::max(version, version_of(*answer->holds, hold_id));
        accepted = std::move(body);
        latest = std::move(*answer);
        error.reset();
        retry = options.retry_min;
        renew_at = Clock::now() + renew_period();
        continue;
      }
      error = answer.error();
      if (refused(answer.error().code)) {
        // The hold keeps its previous contents (if any): renewals go on with those, on schedule.
        if (!change) renew_at = Clock::now() + renew_period();
        continue;
      }
      // Lost on the way: try the same contents again soon (unless newer ones came meanwhile).
      if (change && !pending) pending = std::move(body);
      if (!change) renew_at = Clock::now() + retry;
      if (change) {
        cv.wait_for(lock, retry, [&] { return stopping; });
        if (stopping) return;
      }
      retry = std::min(retry * 2, std::max(options.retry_min, renew_period()));
    }
  }
};

HoldLease::HoldLease(Session& session, const GeomId& id, std::string hold_id, DeformationRequest request,
                     HoldLeaseOptions options)
    : state_(std::make_shared<State>()) {
  if (!(options.ttl.count() > 0) || options.ttl > std::chrono::seconds(600)) {
    fail(ErrorCode::kInvalidArgument, "a hold's lease (ttl) must be more than 0 and at most 600 s, got " +
                                          std::to_string(options.ttl.count()) + " ms");
  }
  if (!(options.renew_after > 0.0 && options.renew_after < 1.0)) {
    fail(ErrorCode::kInvalidArgument, "HoldLeaseOptions::renew_after is a fraction of the lease in (0, 1), got " +
                                          std::to_string(options.renew_after));
  }
  if (options.retry_min.count() <= 0) options.retry_min = std::chrono::milliseconds(1);
  State& s = *state_;
  s.session = &session;
  s.id = id;
  s.hold_id = std::move(hold_id);
  s.options = options;
  s.pending = std::move(request);
  s.thread = std::thread([&s] { s.run(); });
}

HoldLease::~HoldLease() { (void)release(); }

void HoldLease::update(DeformationRequest request) {
  {
    std::lock_guard lock(state_->mu);
    if (state_->stopping) return;
    state_->pending = std::move(request);
  }
  state_->cv.notify_all();
}

std::optional<HeldResult> HoldLease::poll() {
  std::lock_guard lock(state_->mu);
  std::optional<HeldResult> out = std::move(state_->latest);
  state_->latest.reset();
  return out;
}

std::optional<Error> HoldLease::error() const {
  std::lock_guard lock(state_->mu);
  return state_->error;
}

uint64_t HoldLease::version() const {
  std::lock_guard lock(state_->mu);
  return state_->version;
}

uint64_t HoldLease::puts() const {
  std::lock_guard lock(state_->mu);
  return state_->puts;
}

const std::string& HoldLease::hold_id() const { return state_->hold_id; }

Result<HeldResult> HoldLease::release() {
  State& s = *state_;
  {
    std::lock_guard lock(s.mu);
    if (s.released) return Error{ErrorCode::kNotFound, "the hold '" + s.hold_id + "' was released already"};
    s.released = true;
    s.stopping = true;
  }
  s.cv.notify_all();
  s.thread.join();  // a put in flight is answered first, so the release comes after it
  return s.session->release_hold(s.id, s.hold_id);
}

}  // namespace softshell
