#pragma once
/// \file
/// \brief `Service`: the shared simulation service of PROTOCOL.md, free of HTTP. Holds geometries
/// by content id and namespace, precomputes them on a worker pool, solves deformations on another,
/// keeps each geometry's ordered result history, wakes long-poll waiters and notifies
/// subscribers; and, for PROTOCOL.md version 2, keeps every geometry's *holds* (many clients'
/// standing constraints and loads) and solves their combined hold state.
///
/// Threads: a `Service` owns two fixed pools, one for precomputations and one for solves, and one
/// thread that ends lapsed hold leases. Callers' threads (HTTP connection threads, an
/// application's threads) only ever *wait* (for a solve, a precomputation or a newer result) on
/// condition variables or futures; they never occupy a pool worker, so any number of waiting
/// clients cannot delay a solve.
///
/// Holds: each geometry has one hold-state solver loop that runs on the solve pool with at most
/// one solve in flight. Changes (PUT, DELETE, lapsed leases) that arrive while it solves are
/// merged into its next solve, which takes the newest version of every live hold; its result is
/// stored in the same history as `deform` results.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/engine/factor_cache.h"
#include "softshell/engine/nonlinear_solver.h"
#include "softshell/engine/shell_model.h"
#include "softshell/engine/solver.h"
#include "softshell/hold.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/service/log.h"
#include "softshell/service/metrics.h"
#include "softshell/executor.h"
#include "softshell/session.h"
#include "softshell/stresses.h"

namespace softshell::service {

/// Which results a geometry keeps (`ServiceOptions::retention`). The oldest go first; the newest
/// result of a geometry is never dropped. A dropped result's id is never used again: asking for it
/// is kGone (HTTP 410), while an id never stored stays kNotFound (404).
struct ResultRetention {
  /// Results kept per geometry (the newest ones); 0 = no count limit. At spot_quadrangulated's
  /// ~70 KB per result the default keeps ~70 MB per geometry.
  size_t keep_results = 1000;
  /// Bytes of results kept per geometry (as counted against `store_bytes`); 0 = no byte limit.
  size_t bytes_per_geometry = 0;
  /// When a new result does not fit the store budget: true drops the geometry's own oldest
  /// results until it fits (only a result that does not fit even then is refused with 507);
  /// false refuses it with 507 at once (nothing stored is dropped to make room).
  bool drop_oldest_when_full = true;
};

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
  /// results. Geometries are never dropped to make room (an upload that does not fit is refused
  /// with kResourceExhausted, HTTP 507); results are dropped oldest first as `retention` says.
  /// 0 = half the physical memory.
  size_t store_bytes = 0;
  /// Which results each geometry keeps (bounds a long session's memory).
  ResultRetention retention;
  /// Quadrature and limit-evaluation options of every precomputation (its `threads`,
  /// `progress` and `cancel` are set by the service).
  engine::PrecomputeOptions precompute;
  /// What one follower of a geometry's results (an event stream) counts against `store_bytes`
  /// (see `Service::subscribe`): its share of the memory the server keeps for it.
  size_t follower_bytes = 4096;
  /// Live holds one geometry takes at once (every hold-state solve combines all of them, so the
  /// count bounds its cost). A PUT that would create one more is refused with kConflict (HTTP
  /// 409) naming the limit; changes of existing holds are always taken.
  size_t max_holds_per_geometry = 256;
  /// Deformation requests one geometry holds while they wait for its precomputation; one more
  /// is refused with kUnavailable (HTTP 503, retry once it is ready). Each also counts its
  /// request against `store_bytes` while it waits.
  size_t max_waiting_per_geometry = 1024;
  /// Where the service's precomputations and solves run: the host's threads (at most
  /// `precompute_jobs` and `solve_threads` of them at once; a host executor also runs the
  /// precomputations' parallel work unless `precompute.executor` says otherwise). Empty: a pool
  /// of the service's own with `precompute_jobs + solve_threads` threads.
  std::shared_ptr<Executor> executor;
  /// Limits and tolerances of every nonlinear solve (`POST .../results` and hold states with
  /// `model` = nonlinear). A solve may take 60 s here (`time_limit_seconds`; the engine's own
  /// default is no limit): one that has not converged by then is refused (422), so that one
  /// request on a large mesh cannot hold a solver thread for minutes.
  engine::NonlinearOptions nonlinear = [] {
    engine::NonlinearOptions o;
    o.time_limit_seconds = 60.0;
    return o;
  }();
  /// Where the service's messages go (precomputations started/finished/failed).
  Logger logger;
  /// Directory of the persistent store (created if missing); empty = everything in memory only.
  /// With a directory, every geometry and result is written to an SQLite database there before
  /// it is answered, and a new service on the same directory restores them (see `Service`).
  /// One service at a time holds a directory (a lock file).
  std::string data_dir;
};

/// A stored result: the deformed control points and the request that produced them.
struct StoredResult {
  uint32_t res_id = 0;                    ///< 1, 2, 3, ... per geometry, in the order stored
  std::vector<Vec3> positions;            ///< deformed control points (#V)
  DeformationRequest request;             ///< what was asked (for undo, replay, sharing)
  engine::SolveStats stats;               ///< how it was solved (linear model)
  std::optional<engine::NonlinearStats> nonlinear;  ///< how it was solved, if with the nonlinear model
  std::chrono::system_clock::time_point stored_at;
  /// For a result of the hold state: the version of every hold it includes (sorted by hold id;
  /// empty when no hold is left and the object is at rest). Absent for `deform` results.
  std::optional<HoldVersions> holds;

  DeformationResult to_result() const {
    DeformationResult r{res_id, positions};
    if (nonlinear) {
      r.model = DeformationModel::kNonlinear;
      r.iterations = nonlinear->iterations;
      r.residual = nonlinear->residual;
    }
    return r;
  }
};
using ResultPtr = std::shared_ptr<const StoredResult>;

/// Counters and gauges of a service (for /metrics and tests).
struct ServiceStats {
  size_t geometries = 0;                ///< all stored geometries
  size_t geometries_precomputing = 0;
  size_t geometries_ready = 0;
  size_t geometries_failed = 0;
  uint64_t results = 0;                 ///< results kept now over all geometries
  uint64_t results_dropped = 0;         ///< results dropped by the retention policy (not by deletes)
  uint64_t geometries_deleted = 0;      ///< `Service::remove` calls that deleted a geometry
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
  // Holds (PROTOCOL.md version 2)
  size_t holds = 0;                     ///< live holds over all geometries
  size_t hold_changes_pending = 0;      ///< changes waiting for their geometry's next hold-state solve
  size_t hold_states_unsolvable = 0;    ///< geometries whose remaining holds cannot be solved
  uint64_t hold_solves = 0;             ///< hold-state solves (a batch of merged changes each)
  uint64_t hold_changes_solved = 0;     ///< changes those solves took (/ hold_solves = merged per solve)
  uint64_t hold_changes_superseded = 0; ///< changes replaced by a newer PUT of their hold before a solve took them
  uint64_t hold_renewals = 0;           ///< PUTs that only renewed a lease
  uint64_t hold_conflicts = 0;          ///< changes refused with kConflict (409)
  uint64_t hold_rejections = 0;         ///< changes refused with kUnprocessable (422)
  uint64_t leases_expired = 0;          ///< holds released because their lease lapsed
  size_t followers = 0;                 ///< followers counted by subscriptions (event streams)
  Histogram::Snapshot hold_solve_seconds;  ///< time of each hold-state solve (batch)
  // The persistent store (`ServiceOptions::data_dir`); zeros without one.
  bool data_dir = false;                ///< the service has a persistent store
  size_t data_dir_bytes = 0;            ///< its database and write-ahead log on disk
  uint64_t data_dir_writes = 0;         ///< write transactions committed (uploads, results, deletes, retention)
  uint64_t data_dir_write_failures = 0; ///< write transactions that failed (disk full, I/O errors)
  Histogram::Snapshot data_dir_write_seconds;  ///< time of each write transaction, committed or failed
};

/// A change of a hold (`Service::put_hold`).
struct HoldOptions {
  /// The lease: without another PUT within it the hold is released (PROTOCOL.md: default 10 s,
  /// at most 600 s; must be positive).
  std::chrono::milliseconds ttl{10000};
};

/// What a PUT or DELETE of a hold is answered with once its change went through a solve.
struct HoldOutcome {
  /// The first stored result that includes the change (this version of the hold or a newer one;
  /// for a release, the first one without the hold). Null when the change was accepted but the
  /// hold state is unsolvable after a release merged into the same solve (see `Service::holds`).
  ResultPtr result;
};

/// A registered change of a hold: its version at once, its outcome later.
struct HoldTicket {
  std::string hold_id;
  uint64_t version = 0;  ///< the version this PUT made or renewed; for a release, the released one
  bool renewal = false;  ///< the body equalled the hold's newest contents: lease renewed, no new version
  /// Ready once the change is decided: the result, or kConflict (409: contradicts other holds,
  /// or a release left the rest unsolvable), kUnprocessable (422), kResourceExhausted,
  /// kUnavailable (shutting down).
  std::shared_future<Result<HoldOutcome>> outcome;
};

/// Called with every result of one geometry stored after `Service::subscribe`, in id order,
/// on the thread that stored it (a solve worker). It must return quickly, and must not destroy
/// its own `Subscription`.
using ResultListener = std::function<void(const ResultPtr&)>;
/// Called at most once, when the subscribed geometry is deleted (`Service::remove`), with the
/// kGone error to pass on; no result follows. The same rules as for `ResultListener`.
using SubscriptionEnd = std::function<void(const Error&)>;

/// A registration with a geometry's results (`Service::subscribe`). Destroying it unsubscribes;
/// once the destructor has returned, the listener is not called again.
class Subscription {
 public:
  ~Subscription();
  Subscription(const Subscription&) = delete;
  Subscription& operator=(const Subscription&) = delete;

  /// The clients this registration serves (e.g. event streams sharing it); each counts
  /// `ServiceOptions::follower_bytes` against the memory budget. kResourceExhausted (nothing
  /// changed) if more do not fit.
  Result<void> set_followers(size_t followers);
  size_t followers() const;

  struct State;  ///< (private)
  explicit Subscription(std::shared_ptr<State> state);

 private:
  std::shared_ptr<State> state_;
};

/// The simulation service. See the file comment for the threading model.
///
/// Errors: kInvalidArgument (malformed input, HTTP 400), kNotFound (404), kUnprocessable
/// (unusable mesh or material, undetermined or inconsistent system, failed precomputation; 422),
/// kResourceExhausted (the store budget; 507), kUnavailable (shutting down; 503), kConflict (a hold
/// that contradicts other holds, or a release that leaves the rest unsolvable; 409), kGone (a
/// result dropped by the retention policy, or a geometry deleted while the call waited; 410).
///
/// Thread-safety: every member function may be called concurrently from any number of threads.
///
/// Persistence (`ServiceOptions::data_dir`): uploads and results are written to the store before
/// they are returned (a failed write is kResourceExhausted, HTTP 507, and nothing is kept, so no
/// result id is used up). The constructor restores what the directory holds: geometries in
/// upload order, each with its whole result history (later ids continue after the last stored
/// one), and starts their precomputations at once in the background, as for uploads (requests
/// wait for them). Holds are leases and are not kept: clients renew them with a PUT, and their
/// versions continue. The stored meshes and results must fit `store_bytes`; models count
/// against it as they are built.
class Service {
 public:
  /// Throws `softshell::Exception` if `options.data_dir` is given and cannot be used: held by
  /// another service (kUnavailable), not a softshell store, damaged or of a newer schema
  /// (kInvalidArgument), its contents larger than `store_bytes` (kResourceExhausted). See
  /// `create` for the same as a `Result`.
  explicit Service(ServiceOptions options = {});
  /// The constructor's errors as a `Result`.
  static Result<std::shared_ptr<Service>> create(ServiceOptions options = {});
  /// Calls `shutdown()`.
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// Stores a geometry under its content id (see content_id.h) and starts its precomputation.
  /// Uploading an existing geometry again returns `created = false` and restarts nothing.
  /// Validates the mesh (mesh_validation.h), the material and the namespace (at most 256 bytes
  /// of UTF-8 without control characters).
  Result<UploadResult> upload(ControlMesh mesh, Material material, std::string name_space = "");

  /// Deletes a geometry and everything kept for it: its results, holds, model, factor-cache
  /// entries and memory (returned to the budget at once; a running precomputation is cancelled,
  /// a running solve finishes and its result is discarded). Everyone waiting on it is answered
  /// kGone: requests waiting for the precomputation, `latest_result` waiters, hold changes
  /// waiting for a solve, and subscriptions (their `SubscriptionEnd`). kNotFound if unknown.
  ///
  /// The same content can be uploaded again; it is a new geometry (precomputed again, no
  /// holds), but its result ids continue after the deleted one's last id (the service remembers
  /// the last id and hold versions of a deleted geometry, about 100 bytes each), so that no
  /// client that cached (geometry, res_id) pairs or holds a `have` can take an old result for a
  /// new one. With a data directory this is written in the delete's transaction and restored by
  /// the next service on the directory. The newest 16,384 deletes are remembered; past that the
  /// oldest is forgotten (its content uploaded again starts at id 1). A failed write is
  /// kResourceExhausted and deletes nothing.
  Result<void> remove(const GeomId& id);

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

  /// Ids of the results a geometry keeps, oldest first (consecutive; the retention policy drops
  /// the oldest, so the first may be above 1).
  Result<std::vector<uint32_t>> result_ids(const GeomId& id) const;
  /// One result; kNotFound if the geometry is unknown or the result was never stored, kGone if
  /// the retention policy dropped it (or it belonged to a deleted upload of this geometry).
  Result<ResultPtr> result(const GeomId& id, uint32_t res_id) const;

  /// The newest result if its id is greater than `have`; otherwise waits up to `wait` for one.
  /// Returns nullptr if none arrived in time. kUnavailable if the service shuts down or `stop`
  /// is requested while waiting, kGone if the geometry is deleted meanwhile. Waiters are woken as
  /// soon as a result is stored.
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

  // --- holds (PROTOCOL.md version 2) --------------------------------------------------------

  /// Creates the hold or replaces its contents, and renews its lease. A request equal to the
  /// hold's newest contents only renews the lease (`renewal`, no new version, no solve). Errors
  /// returned at once: kInvalidArgument (hold id, request, ttl), kNotFound, kUnprocessable (the
  /// geometry's precomputation failed), kResourceExhausted, kUnavailable. Whether the change is
  /// accepted is decided by the hold-state solve and reported through `outcome`; a refused change
  /// leaves the hold with its previous contents (and a refused new hold is not created).
  Result<HoldTicket> put_hold(const GeomId& id, const std::string& hold_id, DeformationRequest request,
                              HoldOptions options = {});
  /// Releases the hold at once; `outcome` is the first result without it, or kConflict naming
  /// the cause when the remaining holds cannot be solved (the hold is released all the same and
  /// the state is `kUnsolvable` until a change makes it solvable). kNotFound for an unknown hold.
  Result<HoldTicket> release_hold(const GeomId& id, const std::string& hold_id);
  /// The live holds (newest versions, including changes still waiting for the solve) and the
  /// state of their solve.
  Result<HoldList> holds(const GeomId& id) const;
  /// One live hold and its newest contents; kNotFound if there is none by that id.
  Result<HoldDetail> hold(const GeomId& id, const std::string& hold_id) const;

  // --- subscriptions ------------------------------------------------------------------------

  /// Calls `listener` with every result of the geometry stored from now on, in id order, until
  /// the returned subscription is destroyed. The newest result stored before it is available
  /// from `latest_result(id, have, 0)`, which a subscriber calls *after* subscribing (a result
  /// may then be seen twice; ids tell). `followers` counts against the memory budget (see
  /// `Subscription::set_followers`). `ended` is called if the geometry is deleted. kNotFound,
  /// kResourceExhausted, kUnavailable.
  Result<std::unique_ptr<Subscription>> subscribe(const GeomId& id, ResultListener listener, size_t followers = 1,
                                                  SubscriptionEnd ended = {});

  ServiceStats stats() const;
  /// Every counter and gauge of `stats()` in Prometheus text format (families `softshell_*`),
  /// for an HTTP front end to serve under `/metrics`.
  std::string metrics_text() const;
  const ServiceOptions& options() const { return options_; }

  /// Refuses new work (kUnavailable), cancels running precomputations, answers requests that
  /// wait for a precomputation, hold changes that wait for a solve and every `latest_result`
  /// waiter, stops ending leases, then joins the pools (solves already running finish first).
  /// Idempotent.
  void shutdown();
  bool shutting_down() const;

 private:
  Result<UploadResult> upload_checked(ControlMesh mesh, const Material& material, std::string name_space);
  friend class Subscription;
  struct Impl;  // defined in src/service_impl.h, shared by the service's source files
  ServiceOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace softshell::service
