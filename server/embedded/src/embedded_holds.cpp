// EmbeddedSession's holds and events (PROTOCOL.md version 2): straight into the service.
#include "softshell/embedded_session.h"

namespace softshell {
namespace {

HeldResult held(const service::StoredResult& stored) { return HeldResult{stored.to_result(), stored.holds}; }

// A change accepted while a release merged into the same solve left the hold state unsolvable
// has no result to answer with (HTTP: 202 and `"state": "unsolvable"`): that is a refusal here.
Error unsolvable(service::Service& service, const GeomId& id) {
  auto list = service.holds(id);
  std::string why = list && !list->message.empty() ? list->message : "the remaining holds cannot be solved";
  return Error{ErrorCode::kConflict, "the hold state is unsolvable: " + why};
}

Result<HeldResult> answer(service::Service& service, const GeomId& id, const Result<service::HoldOutcome>& outcome) {
  if (!outcome) return outcome.error();
  if (!outcome->result) return unsolvable(service, id);
  return held(*outcome->result);
}

// The service's subscription, kept alive by the EventSubscription, with the service it is
// registered with (the subscription may outlive the session).
class ServiceSource final : public EventSubscription::Source {
 public:
  ServiceSource(std::shared_ptr<service::Service> service, std::unique_ptr<service::Subscription> s)
      : service_(std::move(service)), subscription_(std::move(s)) {}

 private:
  std::shared_ptr<service::Service> service_;             // destroyed last
  std::unique_ptr<service::Subscription> subscription_;
};

}  // namespace

Executor& EmbeddedSession::waiters() {
  std::lock_guard lock(waiters_mu_);
  if (!waiters_) waiters_ = std::make_unique<ThreadPool>(1);
  return *waiters_;
}

Result<HeldResult> EmbeddedSession::put_hold(const GeomId& id, const std::string& hold_id,
                                             const DeformationRequest& request, std::chrono::milliseconds ttl) {
  auto ticket = service_->put_hold(id, hold_id, request, {ttl});
  if (!ticket) return ticket.error();
  return answer(*service_, id, ticket->outcome.get());
}

std::future<Result<HeldResult>> EmbeddedSession::put_hold_async(const GeomId& id, const std::string& hold_id,
                                                                const DeformationRequest& request,
                                                                std::chrono::milliseconds ttl) {
  auto promise = std::make_shared<std::promise<Result<HeldResult>>>();
  auto future = promise->get_future();
  auto ticket = service_->put_hold(id, hold_id, request, {ttl});
  if (!ticket) {
    promise->set_value(ticket.error());
    return future;
  }
  auto outcome = ticket->outcome;
  if (outcome.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    promise->set_value(answer(*service_, id, outcome.get()));  // a renewal, or a refusal at once
    return future;
  }
  // The service answers changes in the order of its solves, so one thread waiting on them in
  // turn delays none by more than the solve it waits for.
  std::shared_ptr<service::Service> service = service_;
  waiters().post([service, id, outcome, promise] {
    try {
      promise->set_value(answer(*service, id, outcome.get()));
    } catch (...) {
      promise->set_value(Error{ErrorCode::kInternal, "put_hold_async failed unexpectedly"});
    }
  });
  return future;
}

Result<HeldResult> EmbeddedSession::release_hold(const GeomId& id, const std::string& hold_id) {
  auto ticket = service_->release_hold(id, hold_id);
  if (!ticket) return ticket.error();
  return answer(*service_, id, ticket->outcome.get());
}

Result<HoldList> EmbeddedSession::holds(const GeomId& id) { return service_->holds(id); }

Result<HoldDetail> EmbeddedSession::hold(const GeomId& id, const std::string& hold_id) {
  return service_->hold(id, hold_id);
}

Result<std::unique_ptr<EventSubscription>> EmbeddedSession::subscribe(const GeomId& id, uint32_t after) {
  auto feed = std::make_shared<EventFeed>(after);
  auto subscription = service_->subscribe(
      id, [feed](const service::ResultPtr& stored) { feed->offer(held(*stored)); }, 1,
      [feed](const Error& deleted) { feed->fail(deleted); });  // the geometry was deleted: kGone
  if (!subscription) return subscription.error();
  // After subscribing, so that nothing stored in between is missed (a repeat is ignored by id).
  auto newest = service_->latest_result(id, after, std::chrono::milliseconds(0));
  if (!newest) return newest.error();
  if (*newest) feed->offer(held(**newest));
  feed->set_live();
  return std::make_unique<EventSubscription>(feed, std::make_unique<ServiceSource>(service_, std::move(*subscription)));
}

}  // namespace softshell
