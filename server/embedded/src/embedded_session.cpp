#include "softshell/embedded_session.h"

namespace softshell {

EmbeddedSession::EmbeddedSession(service::ServiceOptions options)
    : service_(std::make_shared<service::Service>(std::move(options))) {}

EmbeddedSession::EmbeddedSession(std::shared_ptr<service::Service> service) : service_(std::move(service)) {
  if (!service_) fail(ErrorCode::kInvalidArgument, "EmbeddedSession needs a service");
}

EmbeddedSession::~EmbeddedSession() { stop_listening(); }

Result<int> EmbeddedSession::listen(const std::string& host, int port, http::ServerOptions options) {
  std::lock_guard lock(listener_mu_);
  if (listener_) return Error{ErrorCode::kUnavailable, "the session is listening already (port " + std::to_string(listener_->port()) + ")"};
  auto server = std::make_unique<http::HttpServer>(service_, std::move(options));
  auto bound = server->start(host, port);
  if (!bound) return bound.error();
  listener_ = std::move(server);
  return *bound;
}

void EmbeddedSession::stop_listening() {
  std::unique_ptr<http::HttpServer> server;
  {
    std::lock_guard lock(listener_mu_);
    server.swap(listener_);
  }
  if (server) server->stop();
}

int EmbeddedSession::port() const {
  std::lock_guard lock(listener_mu_);
  return listener_ ? listener_->port() : 0;
}

Result<UploadResult> EmbeddedSession::upload(const ControlMesh& mesh, const Material& material,
                                             std::string_view name_space) {
  return capture([&] { return service_->upload(mesh, material, std::string(name_space)); }, "copying the mesh");
}

Result<std::vector<GeometryInfo>> EmbeddedSession::geometries() { return service_->geometries(); }

Result<GeometryInfo> EmbeddedSession::geometry_info(const GeomId& id) { return service_->info(id); }

Result<Geometry> EmbeddedSession::geometry(const GeomId& id) {
  auto g = service_->geometry(id);
  if (!g) return g.error();
  return Geometry(**g);
}

Result<DeformationResult> EmbeddedSession::deform(const GeomId& id, const DeformationRequest& request) {
  auto stored = service_->deform(id, request).get();
  if (!stored) return stored.error();
  return (*stored)->to_result();
}

std::future<Result<DeformationResult>> EmbeddedSession::deform_async(const GeomId& id,
                                                                     const DeformationRequest& request) {
  auto promise = std::make_shared<std::promise<Result<DeformationResult>>>();
  auto future = promise->get_future();
  service_->deform(id, request, [promise](Result<service::ResultPtr> stored) {
    if (stored) promise->set_value((*stored)->to_result());
    else promise->set_value(stored.error());
  });
  return future;
}

Result<std::vector<uint32_t>> EmbeddedSession::result_ids(const GeomId& id) { return service_->result_ids(id); }

Result<DeformationResult> EmbeddedSession::result(const GeomId& id, uint32_t res_id) {
  auto stored = service_->result(id, res_id);
  if (!stored) return stored.error();
  return (*stored)->to_result();
}

Result<DeformationRequest> EmbeddedSession::result_request(const GeomId& id, uint32_t res_id) {
  auto stored = service_->result(id, res_id);
  if (!stored) return stored.error();
  return (*stored)->request;
}

Result<std::optional<DeformationResult>> EmbeddedSession::latest_result(const GeomId& id, uint32_t have,
                                                                        std::chrono::milliseconds wait) {
  auto stored = service_->latest_result(id, have, wait);
  if (!stored) return stored.error();
  if (!*stored) return std::optional<DeformationResult>();
  return std::optional<DeformationResult>((*stored)->to_result());
}

Result<LimitComb> EmbeddedSession::limit_comb(const GeomId& id, const SurfacePoint& point) {
  return service_->limit_comb(id, point);
}

Result<StressField> EmbeddedSession::stresses(const GeomId& id, uint32_t res_id, const StressQuery& query) {
  return service_->stresses(id, res_id, query);
}

Result<void> EmbeddedSession::remove_geometry(const GeomId& id) { return service_->remove(id); }

}  // namespace softshell
