// Subscriptions: listeners of a geometry's stored results (what event streams are fed from),
// counted against the memory budget per follower.
#include <algorithm>

#include "service_impl.h"

namespace softshell::service {

using namespace internal;

struct Subscription::State {
  Service::Impl* impl = nullptr;
  std::shared_ptr<Entry> entry;
  std::shared_ptr<ListenerSlot> slot;
  mutable std::mutex mu;  // guards followers
  size_t followers = 0;
};

Subscription::Subscription(std::shared_ptr<State> state) : state_(std::move(state)) {}

Subscription::~Subscription() {
  Entry& e = *state_->entry;
  {
    std::lock_guard lock(e.mu);
    auto& list = e.listeners;
    list.erase(std::remove(list.begin(), list.end(), state_->slot), list.end());
  }
  {
    // Waits for a call in progress; none starts afterwards.
    std::lock_guard call(state_->slot->mu);
    state_->slot->active = false;
  }
  std::lock_guard lock(state_->mu);
  state_->impl->budget.release(state_->followers * state_->impl->options.follower_bytes);
  state_->impl->followers.fetch_sub(state_->followers);
}

Result<void> Subscription::set_followers(size_t followers) {
  std::lock_guard lock(state_->mu);
  Service::Impl& impl = *state_->impl;
  const size_t per = impl.options.follower_bytes;
  if (followers > state_->followers) {
    const size_t more = (followers - state_->followers) * per;
    if (!impl.budget.try_reserve(more)) {
      impl.refused_no_memory.fetch_add(1);
      return no_room(impl.budget, more, "another follower");
    }
    impl.followers.fetch_add(followers - state_->followers);
  } else {
    impl.budget.release((state_->followers - followers) * per);
    impl.followers.fetch_sub(state_->followers - followers);
  }
  state_->followers = followers;
  return {};
}

size_t Subscription::followers() const {
  std::lock_guard lock(state_->mu);
  return state_->followers;
}

Result<std::unique_ptr<Subscription>> Service::subscribe(const GeomId& id, ResultListener listener, size_t followers,
                                                         SubscriptionEnd ended) {
  if (impl_->stopping.load()) return shutdown_error();
  if (!listener) return Error{ErrorCode::kInvalidArgument, "subscribe needs a listener"};
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  auto state = std::make_shared<Subscription::State>();
  state->impl = impl_.get();
  state->entry = e;
  state->slot = std::make_shared<ListenerSlot>();
  state->slot->fn = std::move(listener);
  state->slot->ended = std::move(ended);
  auto subscription = std::make_unique<Subscription>(state);
  if (auto ok = subscription->set_followers(followers); !ok) return ok.error();
  std::lock_guard lock(e->mu);
  if (e->deleted) return not_found(id);  // deleted since it was found
  e->listeners.push_back(state->slot);
  return subscription;
}

}  // namespace softshell::service
