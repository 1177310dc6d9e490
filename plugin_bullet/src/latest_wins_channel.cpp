#include "softshell/bullet/latest_wins_channel.h"

#include <algorithm>
#include <cmath>

namespace softshell::bullet {

LatestWinsChannel::LatestWinsChannel(std::shared_ptr<Session> session, GeomId geometry, double max_rate)
    : session_(std::move(session)), geometry_(geometry) {
  if (!session_) fail(ErrorCode::kInvalidArgument, "LatestWinsChannel needs a session");
  if (!std::isfinite(max_rate) || max_rate < 0.0) {
    fail(ErrorCode::kInvalidArgument, "max request rate must be finite and >= 0 (0 = unlimited)");
  }
  if (max_rate > 0.0) {
    min_interval_ = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / max_rate));
  }
}

LatestWinsChannel::LatestWinsChannel(std::shared_ptr<Session> session, GeomId geometry, HoldTarget hold,
                                     double max_rate)
    : LatestWinsChannel(std::move(session), geometry, max_rate) {
  if (hold.ttl.count() <= 0 || hold.ttl > std::chrono::seconds(600)) {
    fail(ErrorCode::kInvalidArgument, "a hold's ttl must be more than 0 and at most 600 s");
  }
  hold_ = std::move(hold);
}

LatestWinsChannel::~LatestWinsChannel() {
  if (hold_ && held_) (void)release();
}

Result<HeldResult> LatestWinsChannel::release(std::chrono::milliseconds timeout) {
  if (!hold_) return Error{ErrorCode::kInvalidArgument, "this channel sends requests, not a hold"};
  if (!held_) return Error{ErrorCode::kNotFound, "the hold '" + hold_->hold_id + "' was not put (or was released)"};
  // A put still in flight would bring the hold back after the release: wait for it first.
  (void)wait(timeout);
  held_ = false;
  pending_.reset();
  accepted_.reset();
  return session_->release_hold(geometry_, hold_->hold_id);
}

LatestWinsChannel::Clock::time_point LatestWinsChannel::next_send_time() const {
  return last_send_time_ ? *last_send_time_ + min_interval_ : Clock::time_point::min();
}

void LatestWinsChannel::note_depth() { stats_.max_depth = std::max(stats_.max_depth, depth()); }

void LatestWinsChannel::send(DeformationRequest request, Clock::time_point now) {
  if (hold_) {
    hold_in_flight_ = session_->put_hold_async(geometry_, hold_->hold_id, request, hold_->ttl);
    held_ = true;
    renewing_ = false;
  } else {
    in_flight_ = session_->deform_async(geometry_, request);
  }
  last_sent_ = std::move(request);
  last_send_time_ = now;
  ++stats_.sent;
}

// The same contents again once a third of the lease has passed, so that two more tries fit
// before it lapses. Not rate limited: the server answers a renewal without a solve.
void LatestWinsChannel::renew_if_due(Clock::time_point now) {
  if (!hold_ || !held_ || in_flight() || has_pending() || !accepted_) return;
  if (now < *last_send_time_ + hold_->ttl / 3) return;
  hold_in_flight_ = session_->put_hold_async(geometry_, hold_->hold_id, *accepted_, hold_->ttl);
  renewing_ = true;
  last_send_time_ = now;
  ++stats_.renewals;
}

void LatestWinsChannel::submit(DeformationRequest request, Clock::time_point now) {
  ++stats_.submitted;
  if (!in_flight() && !has_pending() && now >= next_send_time()) {
    send(std::move(request), now);
  } else {
    if (has_pending()) ++stats_.replaced;
    pending_ = std::move(request);
  }
  note_depth();
}

std::optional<ChannelAnswer> LatestWinsChannel::poll(Clock::time_point now) {
  std::optional<ChannelAnswer> outcome;
  const auto ready = [](const auto& future) {
    return future.valid() && future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
  };
  // get() leaves the future invalid: nothing in flight.
  if (ready(in_flight_)) outcome.emplace(ChannelAnswer{*last_sent_, in_flight_.get(), std::nullopt});
  if (ready(hold_in_flight_)) {
    Result<HeldResult> held = hold_in_flight_.get();
    if (held && !renewing_) accepted_ = *last_sent_;
    if (held) {
      outcome.emplace(ChannelAnswer{*last_sent_, std::move(held->result), std::move(held->holds)});
    } else {
      outcome.emplace(ChannelAnswer{*last_sent_, held.error(), std::nullopt});
    }
    if (renewing_ && held) outcome.reset();  // a renewal answers with a result seen before
    renewing_ = false;
  }
  if (outcome) {
    if (outcome->result.ok()) {
      ++stats_.completed;
    } else {
      ++stats_.failed;
    }
  }
  if (!in_flight() && has_pending() && now >= next_send_time()) {
    DeformationRequest request = std::move(*pending_);
    pending_.reset();
    send(std::move(request), now);
  }
  renew_if_due(now);
  return outcome;
}

bool LatestWinsChannel::wait(std::chrono::milliseconds timeout) const {
  if (in_flight_.valid()) return in_flight_.wait_for(timeout) == std::future_status::ready;
  if (hold_in_flight_.valid()) return hold_in_flight_.wait_for(timeout) == std::future_status::ready;
  return true;
}

}  // namespace softshell::bullet
