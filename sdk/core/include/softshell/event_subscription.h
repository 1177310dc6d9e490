#pragma once
/// \file
/// \brief `EventSubscription`: a follower of one geometry's results (PROTOCOL.md version 2,
/// `GET /geometries/{id}/events`), read by polling.
///
/// Pull, not callbacks: a game loop asks once a frame (`poll()`, never blocks) and gets the newest
/// result it has not seen, on its own thread; a follower thread may instead wait (`next(timeout)`).
/// Nothing runs on a foreign thread in the caller's code, which is also what the C ABI (Unity,
/// C#) needs. Latest wins: the subscription keeps one result, and a newer one replaces it, so a
/// consumer slower than the results gets the newest and never a queue.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>

#include "softshell/hold.h"
#include "softshell/result.h"

namespace softshell {

/// Where a subscription's feed is.
enum class FeedState : uint8_t {
  kConnecting,  ///< not (yet, or again) receiving: a remote stream that is (re)connecting
  kLive,        ///< receiving results as they are stored
  kFailed,      ///< ended for good (`EventSubscription::error()` says why); nothing more arrives
};

/// The mailbox between a feed (a service listener, an HTTP event stream) and its consumer: the
/// newest result not taken yet. For `Session` implementations; consumers use `EventSubscription`.
///
/// Thread-safety: every member may be called from any thread.
class EventFeed {
 public:
  /// `after`: results with this id or an older one are not delivered.
  explicit EventFeed(uint32_t after = 0) : newest_(after), taken_(after) {}

  /// Offers a result: kept if it is newer than everything offered before (it replaces a result
  /// not taken yet); older or repeated ids are ignored.
  void offer(HeldResult result);
  /// The feed is receiving (clears a transient error).
  void set_live();
  /// The feed lost its source and is trying again; `why` is kept for `error()`.
  void set_connecting(Error why);
  /// The feed ended for good.
  void fail(Error why);
  /// Newest id offered (or `after`): where a reconnecting stream resumes (`Last-Event-ID`).
  uint32_t newest_id() const;

  // (consumer side, see EventSubscription)
  std::optional<HeldResult> take();
  Result<std::optional<HeldResult>> wait(std::chrono::milliseconds timeout);
  uint32_t taken_id() const;
  FeedState state() const;
  std::optional<Error> error() const;

 private:
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::optional<HeldResult> pending_;
  uint32_t newest_ = 0, taken_ = 0;
  FeedState state_ = FeedState::kConnecting;
  std::optional<Error> error_;
};

/// A subscription to a geometry's results (`Session::subscribe`). Destroying it stops the feed
/// (a remote stream's connection is closed) and returns promptly.
///
/// Thread-safety: every member may be called from any thread.
class EventSubscription {
 public:
  /// What feeds the subscription (a service listener, a stream thread): destroyed first, and
  /// once its destructor has returned it offers nothing more.
  class Source {
   public:
    virtual ~Source() = default;
  };

  EventSubscription(std::shared_ptr<EventFeed> feed, std::unique_ptr<Source> source);
  ~EventSubscription();
  EventSubscription(const EventSubscription&) = delete;
  EventSubscription& operator=(const EventSubscription&) = delete;

  /// The newest result not taken yet, at once; std::nullopt if none arrived since the last take.
  std::optional<HeldResult> poll();
  /// The same, waiting up to `timeout` for one (std::nullopt on timeout). The error of a failed
  /// feed (see `state()`), once nothing is left to take.
  Result<std::optional<HeldResult>> next(std::chrono::milliseconds timeout);
  /// The id of the newest result taken (or the `after` the subscription was made with).
  uint32_t last_id() const;
  FeedState state() const;
  /// Why the feed is reconnecting or has failed; std::nullopt while it is live.
  std::optional<Error> error() const;

 private:
  std::shared_ptr<EventFeed> feed_;
  std::unique_ptr<Source> source_;
};

}  // namespace softshell
