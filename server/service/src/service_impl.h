#pragma once
// Service::Impl and the per-geometry Entry, shared by the service's source files (private):
// service.cpp (geometries, deformations, results), holds.cpp (holds and their solver loop),
// subscriptions.cpp and service_metrics.cpp.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "hold_state.h"
#include "lease_timer.h"
#include "memory_budget.h"
#include "persistent_store.h"
#include "softshell/service/service.h"
#include "task_queue.h"

namespace softshell::service {
namespace internal {

using Clock = std::chrono::steady_clock;

struct GeomIdHash {
  size_t operator()(const GeomId& id) const noexcept {
    size_t h = 0;
    std::memcpy(&h, id.bytes.data(), sizeof h);  // the id is a cryptographic hash already
    return h;
  }
};

std::string megabytes(size_t bytes);
size_t request_bytes(const DeformationRequest& r);
Error not_found(const GeomId& id);
Error shutdown_error();
Error no_room(const MemoryBudget& budget, size_t bytes, const std::string& what);
// What the service counts against its budget for a control mesh, a model not yet built (an
// estimate) and a stored result.
size_t mesh_bytes(const ControlMesh& mesh);
size_t model_estimate(const ControlMesh& mesh, const engine::PrecomputeOptions& options);
size_t result_bytes(const StoredResult& result);
// kGone for calls that waited on a geometry that was deleted meanwhile.
Error deleted_error(const GeomId& id, const std::string& what);

using Pending = std::pair<DeformationRequest, Service::DeformCallback>;
using HoldPromise = std::shared_ptr<std::promise<Result<HoldOutcome>>>;

// ---------------------------------------------------------------------------------------------
// Holds of one geometry (guarded by Entry::mu).

// A change waiting for the hold-state solve: a new version of a hold, or a release (a DELETE or
// a lapsed lease).
struct HoldChange {
  uint64_t seq = 0;            // per geometry, in arrival order
  std::string hold_id;
  uint64_t instance = 0;       // which incarnation of the hold (a released id may be used again)
  HoldVersionPtr version;      // null for a release
};

// A live hold as clients see it (GET .../holds).
struct LiveHold {
  uint64_t instance = 0;
  HoldVersionPtr accepted;     // in force; null while its first version waits for the solve
  HoldVersionPtr newest;       // `accepted`, or the version of a change waiting for the solve
  uint64_t newest_seq = 0;     // that change (0 when newest == accepted)
  uint64_t next_version = 1;
  Clock::time_point expires{};
  uint64_t lease = 0;          // LeaseTimer id
};

struct HoldTable {
  // Released holds' next versions, so that an id used again continues its count (the versions
  // in results and events only grow per hold id). Bounded: beyond kMaxRetired entries the first
  // by id is forgotten.
  static constexpr size_t kMaxRetired = 4096;
  std::map<std::string, uint64_t, std::less<>> retired;
  void retire(const std::string& id, const LiveHold& h) {
    retired[id] = h.next_version;
    if (retired.size() > kMaxRetired) retired.erase(retired.begin());
  }

  std::map<std::string, LiveHold, std::less<>> live;
  HoldMap committed;                 // what the last processed changes left: the solver's view
  std::deque<HoldChange> pending;    // not yet taken by a solve, in arrival order
  std::map<uint64_t, std::vector<HoldPromise>> waiters;  // by change seq (pending or in the solve)
  uint64_t next_seq = 1;
  uint64_t next_instance = 1;
  bool solving = false;              // a solve task is queued or running
  bool unsolvable = false;           // `committed` could not be solved
  std::string message;               // why
  ResultPtr latest;                  // newest stored result of the hold state
  size_t bytes = 0;                  // reserved for versions held here (live and pending)
};

// ---------------------------------------------------------------------------------------------

// A registered result listener; `mu` serializes its calls with its removal.
struct ListenerSlot {
  std::mutex mu;
  ResultListener fn;
  SubscriptionEnd ended;
  bool active = true;
};

// What a deleted geometry leaves behind, so that an upload of the same content continues its
// ids (results and hold versions) instead of reusing them.
struct Tombstone {
  uint64_t seq = 0;  // deletion order (Service::Impl::deleted_order)
  uint32_t next_res_id = 1;
  std::map<std::string, uint64_t, std::less<>> hold_versions;  // next version per hold id
  size_t bytes() const {
    size_t b = sizeof(Tombstone) + sizeof(GeomId) + 32;
    for (const auto& [id, v] : hold_versions) b += id.size() + sizeof(v) + 48;
    return b;
  }
};

// One geometry and everything the service keeps for it.
struct Entry {
  GeomId id;
  std::shared_ptr<const Geometry> geometry;

  mutable std::mutex mu;  // guards everything below but `progress`, the evaluator and `notify_mu`
  mutable std::condition_variable cv;  // notified when a result is stored or the status changes
  GeometryStatus status = GeometryStatus::kPrecomputing;
  std::string error;
  size_t reserved_bytes = 0;  // mesh + model (estimate until built)
  std::shared_ptr<const engine::ShellModel> model;
  std::shared_ptr<const engine::Solver> solver;
  // The nonlinear model's solver (its quadrature basis is built by its first solve).
  std::shared_ptr<const engine::NonlinearSolver> nonlinear;
  // The results kept (the retention policy drops the oldest): results[k] has res_id
  // first_kept + k, so ids never shift and are never reused. The next id is next_res_id().
  std::deque<ResultPtr> results;
  uint32_t first_kept = 1;
  uint32_t first_of_life = 1;      // the first id of this upload (above a deleted upload's last)
  size_t result_bytes = 0;         // what the kept results count against the budget
  size_t nonlinear_bytes = 0;      // what the nonlinear solver holds (its basis, last factor), as last counted
  uint32_t next_res_id() const { return first_kept + static_cast<uint32_t>(results.size()); }
  std::vector<Pending> pending;    // requests waiting for the precomputation
  HoldTable holds;
  std::vector<std::shared_ptr<ListenerSlot>> listeners;
  uint32_t notified = 0;           // the newest res_id handed to listeners (under notify_mu)
  bool deleted = false;            // Service::remove ran: nothing more is stored or waited for
  uint64_t model_id = 0;           // the model's ShellModel::id() (its factor-cache key)
  std::atomic<bool> cancel{false}; // the precomputation's cancel flag (delete, shutdown)

  std::mutex notify_mu;            // one thread at a time hands results to listeners, in id order

  std::atomic<double> progress{0.0};

  mutable std::mutex evaluator_mu;  // guards the lazily created evaluator
  mutable std::optional<LimitEvaluator> evaluator;
  mutable std::optional<Error> evaluator_error;

  GeometryInfo info_locked() const;
};

}  // namespace internal

struct Service::Impl {
  using Entry = internal::Entry;
  using Clock = internal::Clock;

  explicit Impl(const ServiceOptions& o);

  std::shared_ptr<Entry> find(const GeomId& id) const;
  std::vector<std::shared_ptr<Entry>> all() const;
  // The limit evaluator of a geometry: the model's once built, before that one made on demand.
  Result<LimitEvaluator> evaluator(const Entry& e) const;
  // The one validation of a request (validate_request) for this geometry, deformations and holds
  // alike: indices against its control points, surface points against its limit surface (checked
  // now, not after the precomputation). kInvalidArgument naming the first bad element.
  Result<void> validate(const Entry& e, const DeformationRequest& request) const;

  void start_precompute(const std::shared_ptr<Entry>& e);
  void finish_precompute(const std::shared_ptr<Entry>& e, Result<std::shared_ptr<const engine::ShellModel>> model,
                         double seconds);
  void submit_solve(const std::shared_ptr<Entry>& e, std::shared_ptr<const engine::Solver> solver,
                    DeformationRequest request, DeformCallback done);

  // Stores a result under the next id (budget permitting) and hands it to the listeners.
  // `locked` runs under the geometry's lock right after the result is stored (for bookkeeping
  // that must be visible together with it). kResourceExhausted if it does not fit.
  Result<ResultPtr> store(Entry& e, std::shared_ptr<StoredResult> stored, const std::function<void()>& locked = {});
  // Hands every stored result not yet handed out to the listeners, in id order.
  void notify(Entry& e);
  // Drops the geometry's oldest results (never the newest) while the retention policy asks for
  // it, or until `room` more bytes fit the budget; caller holds e.mu. True if `room` fits.
  bool retain_locked(Entry& e, size_t room);

  // --- holds (holds.cpp) ---
  // True if the geometry's hold-state solve should be queued now: changes wait and no solve is
  // queued or running (marks it queued; caller holds e.mu and calls launch_hold_solve after
  // unlocking, because a pool that shuts down runs tasks on the calling thread).
  bool claim_hold_solve_locked(Entry& e);
  void launch_hold_solve(const std::shared_ptr<Entry>& e);
  void run_hold_solve(const std::shared_ptr<Entry>& e);
  // Counts what the geometry's nonlinear solver holds against the budget (after each of its
  // solves: the first builds its basis). Kept even beyond the budget, as a model that turned out
  // larger than estimated; later requests are refused instead.
  void account_nonlinear(Entry& e, const engine::NonlinearSolver& nonlinear);
  // Ends a hold whose lease lapsed (from the lease timer).
  void expire_hold(const std::weak_ptr<Entry>& weak, const std::string& hold_id, uint64_t lease);
  // Answers every hold change that waits (shutdown; a failed precomputation, which also drops
  // the changes, since none can ever be solved).
  void fail_hold_waiters(Entry& e, const Error& error, bool drop_changes);
  void schedule_lease_locked(const std::shared_ptr<Entry>& e, const std::string& hold_id, internal::LiveHold& h,
                             std::chrono::milliseconds ttl);

  // --- persistence (persistence.cpp) ---
  // Opens options.data_dir and restores what it holds (before any other call; starts the
  // restored geometries' precomputations).
  Result<void> restore();

  ServiceOptions options;
  std::shared_ptr<engine::FactorCache> cache;
  internal::MemoryBudget budget;
  // The persistent store (ServiceOptions::data_dir), or null. Written before a geometry or a
  // result becomes visible; outlives the pools (declared before them).
  std::unique_ptr<internal::PersistentStore> persistent;

  mutable std::shared_mutex registry_mu;
  std::unordered_map<GeomId, std::shared_ptr<Entry>, internal::GeomIdHash> by_id;
  std::vector<std::shared_ptr<Entry>> in_order;
  // Deleted geometries by content id, and by deletion order (guarded by registry_mu). Bounded as
  // the persistent store's table is (PersistentStore::kMaxDeletedGeometries): the oldest goes.
  std::unordered_map<GeomId, internal::Tombstone, internal::GeomIdHash> deleted;
  std::map<uint64_t, GeomId> deleted_order;
  uint64_t next_deleted_seq = 1;
  // Registers a tombstone (caller holds registry_mu exclusively; counts it against the budget).
  void remember_deleted_locked(const GeomId& id, internal::Tombstone dead);

  std::atomic<bool> stopping{false};
  std::mutex shutdown_mu;
  std::atomic<int> precomputing_now{0};
  mutable std::atomic<size_t> waiters{0};
  std::atomic<uint64_t> total_results{0}, solves_ok{0}, solves_failed{0}, refused_no_memory{0};
  std::atomic<uint64_t> results_dropped{0}, geometries_deleted{0};
  Histogram solve_hist, precompute_hist;

  // Holds
  std::atomic<uint64_t> next_lease{1};
  std::atomic<uint64_t> hold_solves{0}, hold_changes_solved{0}, hold_renewals{0}, hold_conflicts{0},
      hold_rejections{0}, leases_expired{0}, hold_changes_superseded{0};
  std::atomic<size_t> followers{0};
  Histogram hold_solve_hist;

  // Declared last: destroyed (joined) first, while everything their tasks use still exists.
  // Where the tasks run: the host's executor, or a pool of the service's own (destroyed after the
  // queues, which wait for their tasks).
  std::shared_ptr<Executor> executor;
  internal::LeaseTimer leases;
  internal::TaskQueue precompute_pool;
  internal::TaskQueue solve_pool;
};

}  // namespace softshell::service
