#include "softshell/event_subscription.h"

namespace softshell {

void EventFeed::offer(HeldResult result) {
  {
    std::lock_guard lock(mu_);
    if (result.result.res_id <= newest_) return;  // a repeat after a reconnect, or out of order
    newest_ = result.result.res_id;
    pending_ = std::move(result);
    if (state_ == FeedState::kConnecting) {
      state_ = FeedState::kLive;
      error_.reset();
    }
  }
  cv_.notify_all();
}

void EventFeed::set_live() {
  std::lock_guard lock(mu_);
  if (state_ == FeedState::kFailed) return;
  state_ = FeedState::kLive;
  error_.reset();
}

void EventFeed::set_connecting(Error why) {
  std::lock_guard lock(mu_);
  if (state_ == FeedState::kFailed) return;
  state_ = FeedState::kConnecting;
  error_ = std::move(why);
}

void EventFeed::fail(Error why) {
  {
    std::lock_guard lock(mu_);
    if (state_ == FeedState::kFailed) return;
    state_ = FeedState::kFailed;
    error_ = std::move(why);
  }
  cv_.notify_all();
}

uint32_t EventFeed::newest_id() const {
  std::lock_guard lock(mu_);
  return newest_;
}

std::optional<HeldResult> EventFeed::take() {
  std::lock_guard lock(mu_);
  if (!pending_) return std::nullopt;
  taken_ = pending_->result.res_id;
  std::optional<HeldResult> out = std::move(pending_);
  pending_.reset();
  return out;
}

Result<std::optional<HeldResult>> EventFeed::wait(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mu_);
  cv_.wait_for(lock, timeout, [&] { return pending_.has_value() || state_ == FeedState::kFailed; });
  if (pending_) {
    taken_ = pending_->result.res_id;
    std::optional<HeldResult> out = std::move(pending_);
    pending_.reset();
    return out;
  }
  if (state_ == FeedState::kFailed) return *error_;
  return std::optional<HeldResult>();
}

uint32_t EventFeed::taken_id() const {
  std::lock_guard lock(mu_);
  return taken_;
}

FeedState EventFeed::state() const {
  std::lock_guard lock(mu_);
  return state_;
}

std::optional<Error> EventFeed::error() const {
  std::lock_guard lock(mu_);
  return error_;
}

EventSubscription::EventSubscription(std::shared_ptr<EventFeed> feed, std::unique_ptr<Source> source)
    : feed_(std::move(feed)), source_(std::move(source)) {
  if (!feed_) fail(ErrorCode::kInvalidArgument, "EventSubscription needs a feed");
}

EventSubscription::~EventSubscription() { source_.reset(); }  // stop the feed before the mailbox

std::optional<HeldResult> EventSubscription::poll() { return feed_->take(); }

Result<std::optional<HeldResult>> EventSubscription::next(std::chrono::milliseconds timeout) {
  return feed_->wait(timeout);
}

uint32_t EventSubscription::last_id() const { return feed_->taken_id(); }
FeedState EventSubscription::state() const { return feed_->state(); }
std::optional<Error> EventSubscription::error() const { return feed_->error(); }

}  // namespace softshell
