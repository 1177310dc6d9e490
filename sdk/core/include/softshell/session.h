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
};

}  // namespace softshell
