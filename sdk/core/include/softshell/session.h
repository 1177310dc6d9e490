#pragma once
/// \file
/// \brief `Session`: a client's connection to a softshell server, in-process (`EmbeddedSession`,
/// server library) or over HTTP (`RemoteSession`). Code written against `Session` works with both.

#include <array>
#include <chrono>
#include <cstdint>
#include <future>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/event_subscription.h"
#include "softshell/hold.h"
#include "softshell/limit_evaluator.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/stresses.h"

namespace softshell {

/// A geometry's content-derived id (16 bytes; 32 lowercase hex characters on the wire).
struct GeomId {
  std::array<uint8_t, 16> bytes{};
  std::string hex() const;
  /// Parses 32 hex characters (either case); kInvalidArgument otherwise.
  static Result<GeomId> from_hex(std::string_view hex);
  auto operator<=>(const GeomId&) const = default;
};

/// Precomputation state of a geometry.
enum class GeometryStatus : uint8_t { kPrecomputing, kReady, kFailed };
std::string_view to_string(GeometryStatus status);

/// What the server knows about a geometry (`GET /geometries`).
struct GeometryInfo {
  GeomId id;
  std::string name_space;        ///< the namespace it was uploaded in ("" = default)
  int32_t vertices = 0;
  int32_t faces = 0;
  GeometryStatus status = GeometryStatus::kPrecomputing;
  uint32_t results = 0;          ///< number of stored results
  double progress = 0.0;         ///< precomputation progress in [0, 1] (extension)
  std::string error;             ///< why the precomputation failed, if it did (extension)
};

/// The answer to an upload.
struct UploadResult {
  GeomId id;
  bool created = false;          ///< false if the geometry already existed (HTTP 200 instead of 201)
  GeometryStatus status = GeometryStatus::kPrecomputing;
};

/// A control mesh with its material, as uploaded.
struct Geometry {
  ControlMesh mesh;
  Material material;
  std::string name_space;
};

/// The limit point and its tangents at a surface point as linear combinations of control points
/// (`GET /geometries/{id}/limit_comb`).
struct LimitComb {
  SurfacePoint point;
  std::vector<int32_t> indices;
  std::vector<double> position, du, dv;
};

/// A connection to a softshell server.
///
/// Every call returns a `Result`: network failures, timeouts and server errors are values, never
/// crashes or exceptions. Blocking calls block only the calling thread; `deform_async` never
/// blocks. Thread-safety: all member functions may be called from several threads at once.
class Session {
 public:
  virtual ~Session() = default;

  /// Uploads a control mesh and material into a namespace; idempotent (same content, same id).
  virtual Result<UploadResult> upload(const ControlMesh& mesh, const Material& material,
                                      std::string_view name_space = "") = 0;

  /// Every geometry the server holds.
  virtual Result<std::vector<GeometryInfo>> geometries() = 0;

  /// Status, precomputation progress and result count of one geometry
  /// (`GET /geometries/{id}/status`, an extension).
  virtual Result<GeometryInfo> geometry_info(const GeomId& id) = 0;

  /// The control mesh and material of a geometry, as uploaded.
  virtual Result<Geometry> geometry(const GeomId& id) = 0;

  /// Solves a deformation, stores it as the geometry's next result and returns it. Waits for the
  /// geometry's precomputation if it is still running.
  virtual Result<DeformationResult> deform(const GeomId& id, const DeformationRequest& request) = 0;

  /// The same without blocking: the future becomes ready when the result is stored (poll it
  /// with `wait_for(std::chrono::seconds(0))` from a game loop).
  virtual std::future<Result<DeformationResult>> deform_async(const GeomId& id, const DeformationRequest& request) = 0;

  /// Ids of the geometry's stored results, oldest first.
  virtual Result<std::vector<uint32_t>> result_ids(const GeomId& id) = 0;

  /// One stored result.
  virtual Result<DeformationResult> result(const GeomId& id, uint32_t res_id) = 0;

  /// The request that produced a stored result, as the server received it (for undo, replay
  /// and sharing constraints; `GET /geometries/{id}/results/{res_id}/request`, an extension).
  virtual Result<DeformationRequest> result_request(const GeomId& id, uint32_t res_id) = 0;

  /// The newest result if it is newer than `have`; otherwise waits up to `wait` for one and
  /// returns std::nullopt if none arrived (HTTP 204).
  virtual Result<std::optional<DeformationResult>> latest_result(const GeomId& id, uint32_t have,
                                                                 std::chrono::milliseconds wait) = 0;

  /// The limit point and tangents at `point` as combinations of control points.
  virtual Result<LimitComb> limit_comb(const GeomId& id, const SurfacePoint& point) = 0;

  /// Stresses of a stored result, computed by the server's engine, at the vertices of a
  /// tessellation level or at given points (`GET|POST /geometries/{id}/results/{res_id}/stresses`,
  /// an extension).
  virtual Result<StressField> stresses(const GeomId& id, uint32_t res_id, const StressQuery& query) = 0;

  /// Deletes a geometry and everything kept for it (`DELETE /geometries/{id}`, an extension):
  /// its results, holds and precomputed model. Calls waiting on it are answered kGone; later
  /// calls for the id are kNotFound until the same content is uploaded again, whose result ids
  /// then continue after the deleted ones (which stay kGone). kNotFound for an unknown geometry.
  /// (Not pure: a session without it, such as a test double, refuses it with kUnavailable.)
  virtual Result<void> remove_geometry(const GeomId& id);

  // --- holds and events (PROTOCOL.md version 2) ---------------------------------------------
  // (Not pure: a session without them, such as a test double, refuses them with kUnavailable.)

  /// Creates the hold `hold_id` on a geometry or replaces its contents, with a lease of `ttl`
  /// (more than 0, at most 600 s; without another put within it the hold lapses). The same
  /// contents again only renew the lease (no new version, no solve). Returns the first stored
  /// result whose hold state includes this version of the hold (or a newer one), with the hold
  /// versions it includes. Errors carry the server's message: kConflict (409: the hold
  /// contradicts other live holds, which the message names; or a release merged into the same
  /// solve left the hold state unsolvable), kUnprocessable (422: the hold state would be
  /// undetermined, or the hold is invalid in itself), kInvalidArgument (hold id, body, ttl),
  /// kNotFound. A refused change leaves the hold as it was.
  virtual Result<HeldResult> put_hold(const GeomId& id, const std::string& hold_id, const DeformationRequest& request,
                                      std::chrono::milliseconds ttl = std::chrono::seconds(10));
  /// The same without blocking: the future becomes ready with the answer (poll it with
  /// `wait_for(std::chrono::seconds(0))` from a frame loop). (The default implementation calls
  /// `put_hold` on the calling thread; the embedded and remote sessions do not block.)
  virtual std::future<Result<HeldResult>> put_hold_async(const GeomId& id, const std::string& hold_id,
                                                         const DeformationRequest& request,
                                                         std::chrono::milliseconds ttl = std::chrono::seconds(10));
  /// Releases the hold at once and returns the first result without it (with no hold left, the
  /// rest shape). kNotFound for an unknown hold; kConflict naming the cause when the remaining
  /// holds cannot be solved (the hold is released all the same; `holds()` shows kUnsolvable).
  virtual Result<HeldResult> release_hold(const GeomId& id, const std::string& hold_id);
  /// The live holds of a geometry and the state of their solve.
  virtual Result<HoldList> holds(const GeomId& id);
  /// One live hold with its contents; kNotFound if there is none by that id.
  virtual Result<HoldDetail> hold(const GeomId& id, const std::string& hold_id);

  /// Follows a geometry's results: the newest one with an id above `after` at once (if there is
  /// one), then each newly stored one (see `EventSubscription`: polled, latest wins). A remote
  /// session reconnects by itself after a dropped connection and resumes after the newest id it
  /// received. kNotFound for an unknown geometry.
  virtual Result<std::unique_ptr<EventSubscription>> subscribe(const GeomId& id, uint32_t after = 0);
};

}  // namespace softshell
