#pragma once
/// \file
/// \brief `LatestWinsChannel`: asynchronous deformation requests of one geometry where a newer
/// request replaces the one still waiting (latest wins), so a game loop never queues up work.
/// Requests go out as `POST .../results` (each solved alone) or as the contents of one hold
/// (PROTOCOL.md version 2: each a new version of the hold, solved with every other live hold).

#include <chrono>
#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <string>

#include "softshell/deformation.h"
#include "softshell/result.h"
#include "softshell/session.h"

namespace softshell::bullet {

/// Counters of a channel.
struct ChannelStats {
  uint64_t submitted = 0;  ///< requests given to `submit`
  uint64_t sent = 0;       ///< requests handed to `Session::deform_async`
  uint64_t replaced = 0;   ///< pending requests replaced by a newer one before they were sent
  uint64_t completed = 0;  ///< results received
  uint64_t failed = 0;     ///< errors received
  uint32_t max_depth = 0;  ///< most requests held at once (in flight + pending); never above 2
  uint64_t renewals = 0;   ///< puts of an unchanged hold that only renewed its lease (not in `sent`)
};

/// Where a channel's requests go as a hold: its id on the geometry and its lease.
struct HoldTarget {
  std::string hold_id;                   ///< 1 to 64 characters of [A-Za-z0-9._-]
  std::chrono::milliseconds ttl{3000};   ///< lease of each put (more than 0, at most 600 s)
};

/// A finished request: what was sent and what the session answered (a result or an error).
struct ChannelAnswer {
  DeformationRequest request;
  Result<DeformationResult> result;
  /// For a hold: the hold versions the result includes (the first stored result that includes
  /// the version put, or a newer one, so it may include later changes of any hold).
  std::optional<HoldVersions> holds;
};

/// At most one request in flight and at most one pending; `submit` never blocks and never grows a
/// queue: a request submitted while another is in flight (or while the rate limit holds) becomes
/// the pending one, replacing any older pending request.
///
/// Results therefore arrive in the order sent, and every result answers a request that was the
/// newest one when it was sent. `poll` moves the pending request out as soon as the one in flight
/// is done and the rate limit allows.
///
/// As a hold (`HoldTarget`), each request is a `put_hold_async` of the hold's new contents, and
/// `poll` renews the lease (puts the last contents the server accepted again: no new version, no
/// solve) once a third of the `ttl` passed without a put, so the hold lives as long as the channel
/// is polled (a refused change is not sent again by a renewal).
/// `release` (and the destructor) lets go of it.
///
/// Ownership: shares the session. Destroying a channel of requests does not cancel a request in
/// flight (the session finishes it; a future from `std::async` waits for it in its destructor);
/// a channel of a hold waits for the put in flight, then releases the hold (one round trip).
/// Thread-safety: none; use a channel from one thread (the physics loop).
class LatestWinsChannel {
 public:
  using Clock = std::chrono::steady_clock;

  /// `max_rate` (requests per second, >= 0; 0 = unlimited) bounds how often requests are sent.
  /// Throws `Exception(kInvalidArgument)` for a null session or a negative / non-finite rate.
  LatestWinsChannel(std::shared_ptr<Session> session, GeomId geometry, double max_rate = 0.0);
  /// The same for a hold: requests become the contents of `hold.hold_id`. Throws as above, and
  /// for a ttl outside (0, 600 s] (the hold id is checked by the server: the first answer says).
  LatestWinsChannel(std::shared_ptr<Session> session, GeomId geometry, HoldTarget hold, double max_rate = 0.0);
  ~LatestWinsChannel();
  LatestWinsChannel(const LatestWinsChannel&) = delete;
  LatestWinsChannel& operator=(const LatestWinsChannel&) = delete;

  /// Sends `request` now if nothing is in flight and the rate allows; otherwise it becomes the
  /// pending request (replacing an older pending one). Never blocks on the session.
  void submit(DeformationRequest request, Clock::time_point now = Clock::now());

  /// Non-blocking: if the request in flight is done, returns it with its outcome (a result or the
  /// session's error); then sends the pending request if the rate allows. std::nullopt if no
  /// outcome is ready.
  std::optional<ChannelAnswer> poll(Clock::time_point now = Clock::now());

  /// Blocks up to `timeout` for the request in flight to finish (then `poll` returns it). True if
  /// nothing is in flight or it finished.
  bool wait(std::chrono::milliseconds timeout) const;

  /// For a hold: waits up to `timeout` for the put in flight, then releases the hold (blocking:
  /// one round trip) and stops renewing it. Returns the first result without it; kNotFound if it
  /// was never put (or released already); kInvalidArgument for a channel of requests.
  Result<HeldResult> release(std::chrono::milliseconds timeout = std::chrono::seconds(5));

  bool in_flight() const { return in_flight_.valid() || hold_in_flight_.valid(); }
  /// The hold this channel puts, or nullptr for a channel of requests.
  const HoldTarget* hold() const { return hold_ ? &*hold_ : nullptr; }
  bool has_pending() const { return pending_.has_value(); }
  /// Requests held: in flight (0 or 1) + pending (0 or 1).
  uint32_t depth() const { return (in_flight() ? 1u : 0u) + (has_pending() ? 1u : 0u); }
  /// Earliest time the rate limit lets the next request go.
  Clock::time_point next_send_time() const;
  /// The request sent most recently (the one in flight, if any), or nullptr.
  const DeformationRequest* last_sent() const { return last_sent_ ? &*last_sent_ : nullptr; }
  /// The pending request, or nullptr.
  const DeformationRequest* pending() const { return pending_ ? &*pending_ : nullptr; }
  const ChannelStats& stats() const { return stats_; }
  const GeomId& geometry() const { return geometry_; }
  Session& session() const { return *session_; }

 private:
  void send(DeformationRequest request, Clock::time_point now);
  void note_depth();
  void renew_if_due(Clock::time_point now);

  std::shared_ptr<Session> session_;
  GeomId geometry_;
  Clock::duration min_interval_{0};
  std::optional<HoldTarget> hold_;
  bool held_ = false;      // a put was made and the hold not released since
  bool renewing_ = false;  // the put in flight renews the lease
  std::future<Result<DeformationResult>> in_flight_;
  std::future<Result<HeldResult>> hold_in_flight_;
  std::optional<DeformationRequest> pending_;
  std::optional<DeformationRequest> last_sent_;
  std::optional<DeformationRequest> accepted_;  // a hold's contents the server accepted last
  std::optional<Clock::time_point> last_send_time_;
  ChannelStats stats_;
};

}  // namespace softshell::bullet
