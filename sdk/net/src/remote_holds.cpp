// RemoteSession's holds (PROTOCOL.md version 2: PUT/DELETE/GET /geometries/{id}/holds/...).
#include "remote_impl.h"

namespace softshell {
namespace {

// The longest a PUT or DELETE may wait for its result (PROTOCOL.md: `wait` at most 60 s).
constexpr std::chrono::seconds kHoldWait{60};

std::string hold_path(const GeomId& id, const std::string& hold_id) {
  return geometry_path(id) + "/holds/" + url_encode(hold_id);
}

}  // namespace

Result<HeldResult> RemoteSession::Impl::held_answer(const GeomId& id, const Reply& reply) {
  if (reply.status == 200) return wire::decode_held_result_json(reply.body);
  if (reply.status != 202) return server_error(reply);
  // Accepted without a result: either not solved within the wait, or a release merged into the
  // same solve left the hold state unsolvable (no result is stored then).
  auto accepted = wire::decode_hold_accepted_json(reply.body);
  auto list = get(geometry_path(id) + "/holds", wire::kJsonMediaType);
  if (list && list->status == 200) {
    auto decoded = wire::decode_hold_list_json(list->body);
    if (decoded && decoded->state == HoldStateStatus::kUnsolvable) {
      return Error{ErrorCode::kConflict, "the hold state is unsolvable: " +
                                             (decoded->message.empty() ? std::string("the remaining holds cannot be solved")
                                                                       : decoded->message)};
    }
  }
  std::string what = accepted ? "version " + std::to_string(accepted->version) + " of hold '" + accepted->hold_id + "'"
                              : std::string("the change");
  return Error{ErrorCode::kUnavailable, "the server at " + url + " accepted " + what + " but did not solve it within " +
                                            std::to_string(kHoldWait.count()) +
                                            " s; its result follows through events or latest_result"};
}

Result<HeldResult> RemoteSession::Impl::put_hold(const GeomId& id, const std::string& hold_id,
                                                 const DeformationRequest& request, std::chrono::milliseconds ttl) {
  if (auto ok = wire::check_hold_id(hold_id); !ok) return ok.error();
  auto body = encode(request);
  if (!body) return body.error();
  const std::string path = hold_path(id, hold_id) + "?ttl=" + number_text(static_cast<double>(ttl.count()) / 1000.0) +
                           "&wait=" + std::to_string(kHoldWait.count());
  auto reply = put(path, body->bytes, body->format, wire::kJsonMediaType, kHoldWait);
  if (!reply) return reply.error();
  return held_answer(id, *reply);
}

Result<HeldResult> RemoteSession::put_hold(const GeomId& id, const std::string& hold_id,
                                           const DeformationRequest& request, std::chrono::milliseconds ttl) {
  return impl_->put_hold(id, hold_id, request, ttl);
}

std::future<Result<HeldResult>> RemoteSession::put_hold_async(const GeomId& id, const std::string& hold_id,
                                                              const DeformationRequest& request,
                                                              std::chrono::milliseconds ttl) {
  auto promise = std::make_shared<std::promise<Result<HeldResult>>>();
  auto future = promise->get_future();
  Impl* impl = impl_.get();
  impl_->submit([impl, promise, id, hold_id, request, ttl] {
    try {
      promise->set_value(impl->put_hold(id, hold_id, request, ttl));
    } catch (...) {
      promise->set_value(Error{ErrorCode::kInternal, "put_hold_async failed unexpectedly"});
    }
  });
  return future;
}

Result<HeldResult> RemoteSession::release_hold(const GeomId& id, const std::string& hold_id) {
  if (auto ok = wire::check_hold_id(hold_id); !ok) return ok.error();
  auto reply = impl_->del(hold_path(id, hold_id) + "?wait=" + std::to_string(kHoldWait.count()), wire::kJsonMediaType,
                          kHoldWait);
  if (!reply) return reply.error();
  return impl_->held_answer(id, *reply);
}

Result<HoldList> RemoteSession::holds(const GeomId& id) {
  auto reply = impl_->get(geometry_path(id) + "/holds", wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_hold_list_json(reply->body);
}

Result<HoldDetail> RemoteSession::hold(const GeomId& id, const std::string& hold_id) {
  if (auto ok = wire::check_hold_id(hold_id); !ok) return ok.error();
  auto reply = impl_->get(hold_path(id, hold_id), wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_hold_json(reply->body);
}

}  // namespace softshell
