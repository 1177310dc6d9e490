#pragma once
/// \file
/// \brief `EmbeddedSession`: a `Session` that runs the softshell service inside the application
/// (no sockets, no serialization), and can open the HTTP listener so that other devices join the
/// same geometries and results.

#include <chrono>
#include <memory>
#include <mutex>
#include <string>

#include "softshell/executor.h"
#include "softshell/http/server.h"
#include "softshell/service/service.h"
#include "softshell/session.h"

namespace softshell {

/// The service in-process.
///
/// Results are the service's own values (double precision), so a script gives the same numbers
/// through an `EmbeddedSession` as through a `RemoteSession` in JSON format (and the same up to
/// f32 rounding of inputs and outputs in binary format).
///
/// Thread-safety: every member function may be called from several threads at once.
class EmbeddedSession final : public Session {
 public:
  /// A session with its own service. With `options.data_dir` its geometries and results are kept
  /// there and a later session on the same directory restores them; throws `softshell::Exception`
  /// if the directory cannot be used (held by another service, damaged; see `service::Service`).
  explicit EmbeddedSession(service::ServiceOptions options = {});
  /// A session on a shared service (several sessions, or a session and other code).
  explicit EmbeddedSession(std::shared_ptr<service::Service> service);
  /// Stops the listener. The service shuts down when its last owner lets it go.
  ~EmbeddedSession() override;
  EmbeddedSession(const EmbeddedSession&) = delete;
  EmbeddedSession& operator=(const EmbeddedSession&) = delete;

  /// Opens the HTTP API (PROTOCOL.md) on `host:port` (port 0 = any free port) so that other
  /// clients share this service. Returns the bound port. kUnavailable if it is open already or
  /// the address cannot be bound. The default host is loopback, as for softshell-server: pass
  /// "0.0.0.0" (or an interface's address) to let other devices join.
  Result<int> listen(const std::string& host = "127.0.0.1", int port = 0, http::ServerOptions options = {});
  /// Closes the listener (releases its long polls); the session keeps working. Idempotent.
  void stop_listening();
  /// The listening port, or 0.
  int port() const;

  /// The service behind the session.
  const std::shared_ptr<service::Service>& service() const { return service_; }

  Result<UploadResult> upload(const ControlMesh& mesh, const Material& material,
                              std::string_view name_space = "") override;
  Result<std::vector<GeometryInfo>> geometries() override;
  Result<GeometryInfo> geometry_info(const GeomId& id) override;
  Result<Geometry> geometry(const GeomId& id) override;
  Result<DeformationResult> deform(const GeomId& id, const DeformationRequest& request) override;
  std::future<Result<DeformationResult>> deform_async(const GeomId& id, const DeformationRequest& request) override;
  Result<std::vector<uint32_t>> result_ids(const GeomId& id) override;
  Result<DeformationResult> result(const GeomId& id, uint32_t res_id) override;
  Result<DeformationRequest> result_request(const GeomId& id, uint32_t res_id) override;
  Result<std::optional<DeformationResult>> latest_result(const GeomId& id, uint32_t have,
                                                         std::chrono::milliseconds wait) override;
  Result<LimitComb> limit_comb(const GeomId& id, const SurfacePoint& point) override;
  Result<StressField> stresses(const GeomId& id, uint32_t res_id, const StressQuery& query) override;
  Result<void> remove_geometry(const GeomId& id) override;

  // Holds and events: the service's own (`put_hold_async` waits for an unanswered change on a
  // small pool of the session's, one thread, started on first use; `subscribe` is a service
  // listener, nothing polls).
  Result<HeldResult> put_hold(const GeomId& id, const std::string& hold_id, const DeformationRequest& request,
                              std::chrono::milliseconds ttl = std::chrono::seconds(10)) override;
  std::future<Result<HeldResult>> put_hold_async(const GeomId& id, const std::string& hold_id,
                                                 const DeformationRequest& request,
                                                 std::chrono::milliseconds ttl = std::chrono::seconds(10)) override;
  Result<HeldResult> release_hold(const GeomId& id, const std::string& hold_id) override;
  Result<HoldList> holds(const GeomId& id) override;
  Result<HoldDetail> hold(const GeomId& id, const std::string& hold_id) override;
  Result<std::unique_ptr<EventSubscription>> subscribe(const GeomId& id, uint32_t after = 0) override;

 private:
  Executor& waiters();

  std::shared_ptr<service::Service> service_;
  std::mutex waiters_mu_;
  std::unique_ptr<ThreadPool> waiters_;  // waits for put_hold_async outcomes (declared after service_:
                                         // joined first)
  mutable std::mutex listener_mu_;
  std::unique_ptr<http::HttpServer> listener_;
};

}  // namespace softshell
