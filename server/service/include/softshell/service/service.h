#pragma once
/// \file
/// \brief `Service`: the shared simulation service of PROTOCOL.md, free of HTTP. Holds geometries
/// by content id and namespace, precomputes them on a worker pool, solves deformations on another,
/// keeps each geometry's ordered result history and wakes long-poll waiters.
///
/// Threads: a `Service` owns two fixed pools, one for precomputations and one for solves.
/// Callers' threads (HTTP connection threads, an application's threads) only ever *wait*
/// (for a solve, a precomputation or a newer result) on condition variables or futures; they
/// never occupy a pool worker, so any number of waiting clients cannot delay a solve.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <stop_token>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/engine/factor_cache.h"
#include "softshell/engine/shell_model.h"
#include "softshell/engine/solver.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/service/log.h"
#include "softshell/service/metrics.h"
#include "softshell/session.h"
#include "softshell/stresses.h"

namespace softshell::service {

/// Configuration of a `Service`.
struct ServiceOptions {
  /// Workers that run solves, i.e. solves running at once (0 = std::thread::hardware_concurrency()).
  /// (If the system's BLAS is a sequential OpenBLAS, which is not thread-safe, the engine makes
  /// the BLAS parts of concurrent solves take turns; see ConcurrentSolvesMatchSequentialOnes.)
  int solve_threads = 0;
  /// Geometries precomputed at the same time.
  int precompute_jobs = 1;
  /// Threads of one precomputation (`PrecomputeOptions::threads`); 0 = hardware concurrency.
  int precompute_threads = 0;
  /// Budget of the CHOLMOD factor cache (bytes); least recently used factors are evicted.
  size_t cache_bytes = size_t{1} << 30;
  /// Budget for everything the service keeps (bytes): control meshes, precomputed models and
  /// results. Geometries and results are never dropped to make room: an upload or a result that
  /// does not fit is refused with kResourceExhausted (HTTP 507). 0 = half the physical memory.
  size_t store_bytes = 0;
  /// Quadrature and limit-evaluation options of every precomputation (its `threads`,
  /// `progress` and `cancel` are set by the service).
  engine::PrecomputeOptions precompute;
  /// Where the service's messages go (precomputations started/finished/failed).
  Logger logger;
};

/// A stored result: the deformed control points and the request that produced them.
struct StoredResult {
  uint32_t res_id = 0;                    ///< 1, 2, 3, ... per geometry, in the order stored
  std::vector<Vec3> positions;            ///< deformed control points (#V)
  DeformationRequest request;             ///< what was asked (for undo, replay, sharing)
  engine::SolveStats stats;               ///< how it was solved
  std::chrono::system_clock::time_point stored_at;

  DeformationResult to_result() const { return {res_id, positions}; }
};
using ResultPtr = std::shared_ptr<const StoredResult>;

/// Counters and gauges of a service (for /metrics and tests).
struct ServiceStats {
  size_t geometries = 0;                ///< all stored geometries
  size_t geometries_precomputing = 0;
  size_t geometries_ready = 0;
  size_t geometries_failed = 0;
  uint64_t results = 0;                 ///< stored results over all geometries
  int precomputations_running = 0;      ///< builds executing right now
  size_t pending_solves = 0;            ///< requests waiting for a precomputation
  size_t waiters = 0;                   ///< latest_result calls waiting right now
  size_t store_bytes = 0;               ///< memory held for meshes, models and results
  size_t store_budget = 0;
  engine::FactorCacheStats cache;       ///< factor cache bytes, budget, hits, misses, evictions
  uint64_t solves_ok = 0;
  uint64_t solves_failed = 0;           ///< 4xx-type failures (undetermined systems, bad points, ...)
  uint64_t refused_no_memory = 0;       ///< uploads and results refused by the store budget
  Histogram::Snapshot solve_seconds;    ///< solve time (on a worker) of successful solves
  Histogram::Snapshot precompute_seconds;
};

/// The simulation service. See the file comment for the threading model.
///
/// Errors: kInvalidArgument (malformed input, HTTP 400), kNotFound (404), kUnprocessable
/// (unusable mesh or material, undetermined or inconsistent system, failed precomputation; 422),
/// kResourceExhausted (the store budget; 507), kUnavailable (shutting down; 503).
///
/// Thread-safety: every member function may be called concurrently from any number of threads.
class Service {
 public:
  explicit Service(ServiceOptions options = {});
  /// Calls `shutdown()`.
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// Stores a geometry under its content id (see content_id.h) and starts its precomputation.
  /// Uploading an existing geometry again returns `created = false` and restarts nothing.
  /// Validates the mesh (mesh_validation.h), the material and the namespace (at most 256 bytes
  /// of UTF-8 without control characters).
  Result<UploadResult> upload(ControlMesh mesh, Material material, std::string name_space = "");

  /// Every geometry, in upload order.
  std::vector<GeometryInfo> geometries() const;
  /// One geometry's status, progress and result count.
  Result<GeometryInfo> info(const GeomId& id) const;
  /// The control mesh and material as uploaded (shared, immutable).
  Result<std::shared_ptr<const Geometry>> geometry(const GeomId& id) const;
  /// Waits until the geometry's precomputation has finished (ready or failed) or `timeout`
  /// passed, and returns its info.
  Result<GeometryInfo> wait_until_precomputed(const GeomId& id, std::chrono::milliseconds timeout) const;

  /// Called once with the outcome of a deformation, on a solve worker or on the calling thread.
  using DeformCallback = std::function<void(Result<ResultPtr>)>;

  /// Validates the request, waits (without holding a thread) for the geometry's precomputation,
  /// solves it on a worker, stores the result under the next id and reports it to `done`.
  /// `done` must not block for long (it runs on a solve worker).
  void deform(const GeomId& id, DeformationRequest request, DeformCallback done);
  /// The same as a future.
  std::future<Result<ResultPtr>> deform(const GeomId& id, DeformationRequest request);

  /// Ids of a geometry's results, oldest first (1..count).
  Result<std::vector<uint32_t>> result_ids(const GeomId& id) const;
  /// One result; kNotFound if the geometry or the result is unknown.
  Result<ResultPtr> result(const GeomId& id, uint32_t res_id) const;

  /// The newest result if its id is greater than `have`; otherwise waits up to `wait` for one.
  /// Returns nullptr if none arrived in time. kUnavailable if the service shuts down or `stop`
  /// is requested while waiting. Waiters are woken as soon as a result is stored.
  Result<ResultPtr> latest_result(const GeomId& id, uint32_t have, std::chrono::milliseconds wait,
                                  std::stop_token stop = {}) const;

  /// The limit point and tangents at `point` as combinations of control points (available
  /// while the geometry is still precomputing). kInvalidArgument for a bad point.
  Result<LimitComb> limit_comb(const GeomId& id, const SurfacePoint& point) const;
  /// The geometry's limit evaluator (the surface the simulation uses; available while it
  /// precomputes), for extensions that evaluate the surface (render tables). kNotFound if unknown.
  Result<LimitEvaluator> limit_evaluator(const GeomId& id) const;

  /// Stresses of a stored result (softshell/stresses.h), computed on the calling thread:
  /// kNotFound for an unknown geometry or result, kInvalidArgument for a bad query (level outside
  /// 1..4, too many points, a point not on the surface).
  Result<StressField> stresses(const GeomId& id, uint32_t res_id, const StressQuery& query) const;

  ServiceStats stats() const;
  const ServiceOptions& options() const { return options_; }

  /// Refuses new work (kUnavailable), cancels running precomputations, answers requests that
  /// wait for a precomputation and releases every `latest_result` waiter, then joins the pools
  /// (solves already running finish first). Idempotent.
  void shutdown();
  bool shutting_down() const;

 private:
  Result<UploadResult> upload_checked(ControlMesh mesh, const Material& material, std::string name_space);
  struct Impl;
  ServiceOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace softshell::service
