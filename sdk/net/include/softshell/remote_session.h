#pragma once
/// \file
/// \brief `RemoteSession`: a `Session` over HTTP (PROTOCOL.md) to a softshell server.

#include <chrono>
#include <memory>
#include <string>
#include <string_view>

#include "softshell/executor.h"
#include "softshell/session.h"
#include "softshell/wire.h"

namespace softshell {

/// Options of a `RemoteSession`.
struct RemoteSessionOptions {
  /// Preferred body format. With kBinary (the paper's layouts) a body is sent as JSON instead
  /// when the binary layout cannot carry it: a mesh with non-quad faces, crease/corner tags,
  /// boundary "none", or numbers that f32 would round (so that an upload gets the id of exactly
  /// the values given), and a request with JSON-only fields (limit constraints, surface forces,
  /// surface load, pressure). Binary requests and results carry f32 values (deformed positions
  /// are rounded to f32); use kJson for full double precision.
  wire::Format format = wire::Format::kBinary;
  /// Time allowed to open a TCP connection.
  std::chrono::milliseconds connect_timeout{5000};
  /// Time allowed for one request/response (a deformation waits for the geometry's
  /// precomputation, so this is generous). `latest_result` adds its `wait` to it.
  std::chrono::milliseconds request_timeout{300000};
  /// Where `deform_async` calls run (each blocks one thread on the network while it runs). Empty:
  /// the session's own pool of `async_threads` threads (not the shared default executor, whose
  /// threads compute).
  std::shared_ptr<Executor> executor;
  /// Threads of the session's own pool when `executor` is empty.
  int async_threads = 2;
  /// Idle keep-alive connections kept for reuse.
  int max_idle_connections = 8;
  /// Ask the server to gzip JSON responses (useful on slow links, wasteful on loopback/LAN).
  bool compress = false;
  /// Event streams (`subscribe`): the first wait before reconnecting a dropped stream, doubled
  /// after each failed attempt up to `events_retry_max`; reset once a stream is up again.
  std::chrono::milliseconds events_retry_min{100};
  std::chrono::milliseconds events_retry_max{5000};
  /// A stream that carries nothing (not even the server's keep-alive comment, sent at least
  /// every 15 s) for this long is taken as dropped and reconnected.
  std::chrono::milliseconds events_idle_timeout{45000};
  /// Access token of a server started with `--auth-token-file`, sent as `Authorization: Bearer
  /// <token>` on every request and event stream. Empty: none. A server that needs one refuses
  /// every call but `health` (and so `connect`) without it, or with a wrong one (HTTP 401):
  /// kInvalidArgument with the server's message and a note naming this option.
  std::string auth_token;
};

/// A connection to a softshell server over HTTP/1.1 (cpp-httplib's client), with keep-alive
/// connections reused across calls.
///
/// Every failure is a value: transport errors and timeouts are `kUnavailable`, server errors keep
/// the server's code and message (`kInvalidArgument` for a 400, `kNotFound` for a 404, ...).
///
/// Thread-safety: every member function may be called from several threads at once (each call
/// uses its own connection). Destroying the session waits for running `deform_async` calls.
class RemoteSession final : public Session {
 public:
  /// A session to `url` (`http://host:port`, `https://host:port`, or `host:port`). Does not
  /// connect yet; see `connect` to check that the server answers.
  explicit RemoteSession(std::string_view url, RemoteSessionOptions options = {});
  ~RemoteSession() override;
  RemoteSession(const RemoteSession&) = delete;
  RemoteSession& operator=(const RemoteSession&) = delete;

  /// A session whose server answered `GET /health`; kUnavailable if it did not.
  static Result<std::unique_ptr<RemoteSession>> connect(std::string_view url, RemoteSessionOptions options = {});

  /// `GET /health`: ok if the server can take requests.
  Result<void> health();

  /// The server's URL as given.
  const std::string& url() const;
  const RemoteSessionOptions& options() const;

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

  // Holds (`PUT/DELETE/GET .../holds`): bodies in the preferred format, answers always in JSON
  // (only JSON carries the hold versions; positions then have full precision). A PUT waits up to
  // 60 s (the protocol's most) for its result. `put_hold_async` runs on the executor.
  Result<HeldResult> put_hold(const GeomId& id, const std::string& hold_id, const DeformationRequest& request,
                              std::chrono::milliseconds ttl = std::chrono::seconds(10)) override;
  std::future<Result<HeldResult>> put_hold_async(const GeomId& id, const std::string& hold_id,
                                                 const DeformationRequest& request,
                                                 std::chrono::milliseconds ttl = std::chrono::seconds(10)) override;
  Result<HeldResult> release_hold(const GeomId& id, const std::string& hold_id) override;
  Result<HoldList> holds(const GeomId& id) override;
  Result<HoldDetail> hold(const GeomId& id, const std::string& hold_id) override;
  /// `GET .../events` on a thread of the subscription's own: returns once the server answered
  /// the stream (an error status is returned as the error), then reconnects by itself after a
  /// dropped connection with `Last-Event-ID` (backoff from `events_retry_min` doubling up to
  /// `events_retry_max`). A subscription may outlive the session.
  Result<std::unique_ptr<EventSubscription>> subscribe(const GeomId& id, uint32_t after = 0) override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Percent-encodes a string for a URL query value (RFC 3986 unreserved characters stay).
std::string url_encode(std::string_view text);

}  // namespace softshell
