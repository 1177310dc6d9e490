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

LatestWinsChannel::~LatestWinsChannel() = default;

LatestWinsChannel::Clock::time_point LatestWinsChannel::next_send_time() const {
  return last_send_time_ ? *last_send_time_ + min_interval_ : Clock::time_point::min();
}

void LatestWinsChannel::note_depth() { stats_.max_depth = std::max(stats_.max_depth, depth()); }

void LatestWinsChannel::send(DeformationRequest request, Clock::time_point now) {
  in_flight_ = session_->deform_async(geometry_, request);
  last_sent_ = std::move(request);
  last_send_time_ = now;
  ++stats_.sent;
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
  if (in_flight() && in_flight_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    // get() leaves the future invalid: nothing in flight.
    outcome.emplace(ChannelAnswer{*last_sent_, in_flight_.get()});
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
  return outcome;
}

bool LatestWinsChannel::wait(std::chrono::milliseconds timeout) const {
  if (!in_flight()) return true;
  return in_flight_.wait_for(timeout) == std::future_status::ready;
}

}  // namespace softshell::bullet
