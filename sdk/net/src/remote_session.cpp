#include "softshell/remote_session.h"

#include "remote_impl.h"

namespace softshell {

Result<std::unique_ptr<httplib::Client>> remote::make_client(const std::string& url, const RemoteSessionOptions& options) {
  std::string target = url;
  while (!target.empty() && target.back() == '/') target.pop_back();
  auto c = std::make_unique<httplib::Client>(target);
  if (!c->is_valid()) {
    return Error{ErrorCode::kInvalidArgument, "'" + url + "' is not a server URL (expected http://host:port or host:port)"};
  }
  c->set_keep_alive(true);
  c->set_tcp_nodelay(true);
  c->set_connection_timeout(options.connect_timeout);
  c->set_write_timeout(options.request_timeout);
  c->set_decompress(options.compress);
  if (!options.auth_token.empty()) c->set_bearer_token_auth(options.auth_token);
  return c;
}

std::string url_encode(std::string_view text) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(text.size());
  for (unsigned char c : text) {
    if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '_' ||
        c == '.' || c == '~') {
      out.push_back(static_cast<char>(c));
    } else {
      out.push_back('%');
      out.push_back(kHex[c >> 4]);
      out.push_back(kHex[c & 0xf]);
    }
  }
  return out;
}

RemoteSession::RemoteSession(std::string_view url, RemoteSessionOptions options)
    : impl_(std::make_unique<Impl>(url, std::move(options))) {}

RemoteSession::~RemoteSession() = default;

Result<std::unique_ptr<RemoteSession>> RemoteSession::connect(std::string_view url, RemoteSessionOptions options) {
  auto session = std::make_unique<RemoteSession>(url, std::move(options));
  if (auto ok = session->health(); !ok) return ok.error();
  return session;
}

const std::string& RemoteSession::url() const { return impl_->url; }
const RemoteSessionOptions& RemoteSession::options() const { return impl_->options; }

Result<void> RemoteSession::health() {
  auto reply = impl_->get("/health", wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return {};
}

Result<UploadResult> RemoteSession::upload(const ControlMesh& mesh, const Material& material,
                                           std::string_view name_space) {
  // Binary only when it carries exactly these values (the id names the values).
  const bool binary = impl_->options.format == wire::Format::kBinary && wire::geometry_fits_binary(mesh) &&
                      wire::geometry_is_float32_exact(mesh, material);
  std::string body;
  if (binary) {
    auto encoded = wire::encode_geometry_binary(mesh, material);
    if (!encoded) return encoded.error();
    body = std::move(*encoded);
  } else {
    auto ok = capture([&] { body = wire::encode_geometry_json(mesh, material); });
    if (!ok) return ok.error();
  }
  std::string path = "/geometries";
  if (!name_space.empty()) path += "?namespace=" + url_encode(name_space);
  // The JSON answer also carries the status, which the 16-byte binary answer lacks.
  auto reply = impl_->post(path, body, binary ? wire::Format::kBinary : wire::Format::kJson, wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200 && reply->status != 201) return impl_->server_error(*reply);
  const bool created = reply->status == 201;
  return is_binary(reply->content_type) ? wire::decode_upload_response_binary(reply->body, created)
                                        : wire::decode_upload_response_json(reply->body, created);
}

Result<std::vector<GeometryInfo>> RemoteSession::geometries() {
  auto reply = impl_->get("/geometries", wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_geometry_list_json(reply->body);
}

Result<GeometryInfo> RemoteSession::geometry_info(const GeomId& id) {
  auto reply = impl_->get(geometry_path(id) + "/status", wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_geometry_info_json(reply->body);
}

Result<Geometry> RemoteSession::geometry(const GeomId& id) {
  // JSON: full precision, any faces, tags and the namespace.
  auto reply = impl_->get(geometry_path(id), wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return is_binary(reply->content_type) ? wire::decode_geometry_binary(reply->body)
                                        : wire::decode_geometry_json(reply->body);
}

Result<DeformationResult> RemoteSession::deform(const GeomId& id, const DeformationRequest& request) {
  return impl_->deform(id, request);
}

std::future<Result<DeformationResult>> RemoteSession::deform_async(const GeomId& id,
                                                                   const DeformationRequest& request) {
  auto promise = std::make_shared<std::promise<Result<DeformationResult>>>();
  auto future = promise->get_future();
  Impl* impl = impl_.get();
  impl_->submit([impl, promise, id, request] {
    try {
      promise->set_value(impl->deform(id, request));
    } catch (...) {
      promise->set_value(Error{ErrorCode::kInternal, "deform_async failed unexpectedly"});
    }
  });
  return future;
}

Result<std::vector<uint32_t>> RemoteSession::result_ids(const GeomId& id) {
  auto reply = impl_->get(geometry_path(id) + "/results", wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_result_ids_json(reply->body);
}

Result<DeformationResult> RemoteSession::result(const GeomId& id, uint32_t res_id) {
  auto reply = impl_->get(geometry_path(id) + "/results/" + std::to_string(res_id), impl_->preferred_accept());
  if (!reply) return reply.error();
  return impl_->decode_result(*reply);
}

Result<DeformationRequest> RemoteSession::result_request(const GeomId& id, uint32_t res_id) {
  auto reply =
      impl_->get(geometry_path(id) + "/results/" + std::to_string(res_id) + "/request", wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_request_json(reply->body);
}

Result<std::optional<DeformationResult>> RemoteSession::latest_result(const GeomId& id, uint32_t have,
                                                                      std::chrono::milliseconds wait) {
  if (wait.count() < 0) wait = std::chrono::milliseconds(0);
  const std::string path = geometry_path(id) + "/latest_result?have=" + std::to_string(have) +
                           "&wait=" + number_text(static_cast<double>(wait.count()) / 1000.0);
  auto reply = impl_->get(path, impl_->preferred_accept(), wait);
  if (!reply) return reply.error();
  if (reply->status == 204) return std::optional<DeformationResult>();
  auto r = impl_->decode_result(*reply);
  if (!r) return r.error();
  return std::optional<DeformationResult>(std::move(*r));
}

Result<LimitComb> RemoteSession::limit_comb(const GeomId& id, const SurfacePoint& point) {
  const std::string path = geometry_path(id) + "/limit_comb?u=" + number_text(point.u) + "&v=" + number_text(point.v) +
                           "&face-index=" + std::to_string(point.face) + "&subface=" + std::to_string(point.subface);
  auto reply = impl_->get(path, impl_->preferred_accept());
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return is_binary(reply->content_type) ? wire::decode_limit_comb_binary(reply->body, point)
                                        : wire::decode_limit_comb_json(reply->body);
}

Result<StressField> RemoteSession::stresses(const GeomId& id, uint32_t res_id, const StressQuery& query) {
  const std::string path = geometry_path(id) + "/results/" + std::to_string(res_id) + "/stresses";
  auto reply = query.level > 0 ? impl_->get(path + "?level=" + std::to_string(query.level) +
                                                "&yield_strength=" + number_text(query.yield_strength),
                                            wire::kJsonMediaType)
                               : impl_->post(path, wire::encode_stress_query_json(query), wire::Format::kJson,
                                             wire::kJsonMediaType);
  if (!reply) return reply.error();
  if (reply->status != 200) return impl_->server_error(*reply);
  return wire::decode_stress_field_json(reply->body);
}

Result<void> RemoteSession::remove_geometry(const GeomId& id) {
  auto reply = impl_->del(geometry_path(id), wire::kJsonMediaType, std::chrono::milliseconds(0));
  if (!reply) return reply.error();
  if (reply->status != 204) return impl_->server_error(*reply);
  return {};
}

}  // namespace softshell
