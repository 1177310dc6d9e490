#pragma once
/// \file
/// \brief `HoldLease`: one hold (PROTOCOL.md version 2) kept alive for as long as the object
/// lives: a hand's grab, a pin, a body resting on a sheet. It puts the hold, renews its lease
/// before it lapses, sends new contents as they come (latest wins) and releases the hold when it
/// is destroyed.
///
/// The lease works on a thread of its own that sleeps between renewals (one per lease; it only
/// waits on the network and a condition variable), so a frame loop that calls `update()` and
/// `poll()` never blocks on the network.

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "softshell/deformation.h"
#include "softshell/hold.h"
#include "softshell/result.h"
#include "softshell/session.h"

namespace softshell {

/// Options of a `HoldLease`.
struct HoldLeaseOptions {
  /// The lease the server is given with each put (more than 0, at most 600 s): how long the hold
  /// lasts after this client stops renewing it (crashed, lost its network).
  std::chrono::milliseconds ttl{3000};
  /// Renew once this fraction of `ttl` has passed since the last answer (in (0, 1); the default
  /// leaves two more tries before the lease lapses).
  double renew_after = 1.0 / 3.0;
  /// First wait before a put that failed on the way (not refused by the server) is tried again;
  /// doubled after each failure, at most `ttl * renew_after`.
  std::chrono::milliseconds retry_min{100};
};

/// A hold kept for the lifetime of the object.
///
/// Thread-safety: every member may be called from any thread. The session must outlive the lease.
class HoldLease {
 public:
  /// Starts holding `hold_id` on geometry `id` with `request`: the first put goes out at once, on
  /// the lease's thread (a bad hold id or request shows in `error()`). Throws
  /// `softshell::Exception` (kInvalidArgument) for options outside their ranges.
  HoldLease(Session& session, const GeomId& id, std::string hold_id, DeformationRequest request,
            HoldLeaseOptions options = {});
  /// Stops renewing and releases the hold (`release()`), waiting for the answer (one round trip
  /// to a remote server).
  ~HoldLease();
  HoldLease(const HoldLease&) = delete;
  HoldLease& operator=(const HoldLease&) = delete;

  /// Replaces the hold's contents. Sent as soon as the put in flight (if any) is answered; an
  /// update that was not sent yet is replaced by a newer one (latest wins). Renewals then carry
  /// the new contents once the server accepted them.
  void update(DeformationRequest request);

  /// The newest answer (a result including this hold) not taken yet; std::nullopt if none came
  /// since the last call.
  std::optional<HeldResult> poll();
  /// Why the last put failed (kConflict and kUnprocessable carry the server's reason; the hold
  /// keeps the contents it had); std::nullopt after an accepted answer.
  std::optional<Error> error() const;
  /// The newest version of this hold that an answer included (0 before the first).
  uint64_t version() const;
  /// Puts made, including renewals (for tests and diagnostics).
  uint64_t puts() const;
  const std::string& hold_id() const;

  /// Stops renewing and releases the hold now (idempotent; later calls return kNotFound). The
  /// first result without the hold, or the session's error (kNotFound if the hold had lapsed or
  /// was never accepted).
  Result<HeldResult> release();

 private:
  struct State;
  std::shared_ptr<State> state_;
};

}  // namespace softshell
