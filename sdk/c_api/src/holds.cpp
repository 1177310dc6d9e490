// C ABI: holds (asynchronous puts, polled; releases) and event subscriptions (polled), PROTOCOL.md
// version 2. Nothing calls back into the host's threads.

#include <chrono>
#include <cstring>
#include <future>
#include <mutex>
#include <string>
#include <vector>

#include "c_api_internal.h"
#include "softshell/softshell_c_bridge.h"

using namespace softshell;         // NOLINT(google-build-using-namespace): a .cpp of entry points
using namespace softshell::c_api;  // NOLINT(google-build-using-namespace)

namespace {

std::string hold_id_arg(const char* hold_id) {
  required(hold_id, "hold_id");
  return std::string(hold_id, strnlen(hold_id, kMaxHoldIdLength + 1));  // the session checks the characters
}

Reaper<HoldPutObject>& reaper() {
  static auto* r = new Reaper<HoldPutObject>([](const HoldPutObject& o) { return "a put of hold '" + o.hold_id + "'"; });
  return *r;
}

}  // namespace

extern "C" {

ss_status ss_session_put_hold_begin(ss_session* session, const ss_geom_id* id, const char* hold_id,
                                    const ss_request* request, int32_t ttl_ms, ss_hold_put** out_operation) {
  return guard("ss_session_put_hold_begin", [&] {
    required(out_operation, "out_operation");
    *out_operation = nullptr;
    const auto s = live(session, "session");
    const auto req = live(request, "request");
    std::string name = hold_id_arg(hold_id);
    if (ttl_ms < 1 || ttl_ms > 600000) {
      fail(ErrorCode::kInvalidArgument,
           "ttl_ms (the hold's lease) must be 1 .. 600000 ms, got " + std::to_string(ttl_ms));
    }
    reaper().purge_finished();
    auto op = std::make_shared<HoldPutObject>();
    op->session = s;
    op->hold_id = name;
    op->future = s->put_hold_async(geom_id(id), name, *req, std::chrono::milliseconds(ttl_ms)).share();
    if (!op->future.valid()) fail(ErrorCode::kInternal, "the session returned no future");
    finish_before_exit(op->future);
    *out_operation = make_handle<ss_hold_put>(std::move(op));
  });
}

ss_status ss_hold_put_poll(ss_hold_put* operation, int32_t* out_ready) {
  return guard("ss_hold_put_poll", [&] {
    const auto op = live(operation, "operation");
    required(out_ready, "out_ready");
    *out_ready = op->ready() ? 1 : 0;
  });
}

ss_status ss_hold_put_read(ss_hold_put* operation, uint32_t* out_res_id, uint64_t* out_version, double* out_xyz,
                           int32_t capacity, int32_t* out_count) {
  return guard("ss_hold_put_read", [&] {
    const auto op = live(operation, "operation");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    if (!op->ready()) throw CStatus{SS_NOT_READY, "the put is still running; poll until it is ready"};
    const Result<HeldResult>& r = op->future.get();
    if (!r.ok()) throw Exception(r.error());
    write_xyz(r.value().result.positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r.value().result.res_id;
    if (out_version) *out_version = r.value().holds ? version_of(*r.value().holds, op->hold_id) : 0;
  });
}

ss_status ss_hold_put_read_model(ss_hold_put* operation, int32_t* out_model, int32_t* out_iterations,
                                 double* out_residual) {
  return guard("ss_hold_put_read_model", [&] {
    const auto op = live(operation, "operation");
    if (!op->ready()) throw CStatus{SS_NOT_READY, "the put is still running; poll until it is ready"};
    const Result<HeldResult>& r = op->future.get();
    if (!r.ok()) throw Exception(r.error());
    write_model(r.value().result, out_model, out_iterations, out_residual);
  });
}

void ss_hold_put_destroy(ss_hold_put* operation) {
  try {
    std::shared_ptr<void> object =
        handles().remove(reinterpret_cast<uintptr_t>(operation), Kind::kHoldPut, "ss_hold_put_destroy");
    const auto op = std::static_pointer_cast<HoldPutObject>(object);
    if (op && op->future.valid() && !op->ready()) reaper().adopt(*op);
  } catch (...) {
    // Out of memory while adopting: the operation is released here and may then wait.
  }
}

ss_status ss_session_release_hold(ss_session* session, const ss_geom_id* id, const char* hold_id,
                                  uint32_t* out_res_id) {
  return guard("ss_session_release_hold", [&] {
    const auto s = live(session, "session");
    const HeldResult r = s->release_hold(geom_id(id), hold_id_arg(hold_id)).value();
    if (out_res_id) *out_res_id = r.result.res_id;
  });
}

ss_status ss_session_subscribe(ss_session* session, const ss_geom_id* id, uint32_t after,
                               ss_subscription** out_subscription) {
  return guard("ss_session_subscribe", [&] {
    required(out_subscription, "out_subscription");
    *out_subscription = nullptr;
    const auto s = live(session, "session");
    auto object = std::make_shared<SubscriptionObject>();
    object->session = s;
    object->subscription = s->subscribe(geom_id(id), after).value();
    *out_subscription = make_handle<ss_subscription>(std::move(object));
  });
}

ss_status ss_subscription_poll(ss_subscription* subscription, int32_t* out_has_new, uint32_t* out_res_id,
                               double* out_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_subscription_poll", [&] {
    const auto o = live(subscription, "subscription");
    required(out_has_new, "out_has_new");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    *out_has_new = 0;
    std::lock_guard lock(o->mu);
    if (auto newer = o->subscription->poll()) o->held_back = std::move(newer);
    if (!o->held_back) {
      *out_count = 0;
      if (o->subscription->state() == FeedState::kFailed) {
        throw Exception(o->subscription->error().value_or(Error{ErrorCode::kUnavailable, "the subscription ended"}));
      }
      return;
    }
    write_xyz(o->held_back->result.positions, out_xyz, capacity, out_count, "deformed positions");  // may throw: kept
    *out_res_id = o->held_back->result.res_id;
    *out_has_new = 1;
    o->held_back.reset();
  });
}

ss_status ss_subscription_state(ss_subscription* subscription, int32_t* out_state) {
  return guard("ss_subscription_state", [&] {
    const auto o = live(subscription, "subscription");
    required(out_state, "out_state");
    switch (o->subscription->state()) {
      case FeedState::kConnecting: *out_state = SS_FEED_CONNECTING; break;
      case FeedState::kLive: *out_state = SS_FEED_LIVE; break;
      case FeedState::kFailed: *out_state = SS_FEED_FAILED; break;
    }
  });
}

void ss_subscription_destroy(ss_subscription* subscription) { destroy(subscription, "ss_subscription_destroy"); }

}  // extern "C"
