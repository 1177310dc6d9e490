// Service: uploads, precomputation, deformations, the result history, long polls, stresses and limit
// combinations (holds, subscriptions and metrics have their own files). (About 900 lines: the
// geometry lifecycle, upload to delete, the result history with its retention, and the solve path
// share the Impl helpers defined here.)
#include "softshell/service/service.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <thread>

#include "service_impl.h"
#include "softshell/content_id.h"
#include "softshell/engine/nonlinear_stresses.h"
#include "softshell/engine/stresses.h"
#include "softshell/mesh_validation.h"
#include "softshell/request_validation.h"
#include "softshell/tessellation.h"
#include "softshell/wire.h"

namespace softshell::service {

namespace internal {

std::string megabytes(size_t bytes) {
  std::ostringstream s;
  s.precision(bytes < (size_t{10} << 20) ? 2 : 0);
  s << std::fixed << static_cast<double>(bytes) / (1024.0 * 1024.0) << " MiB";
  return s.str();
}

size_t request_bytes(const DeformationRequest& r) {
  size_t bytes = sizeof(DeformationRequest) + r.vertex_constraints.size() * sizeof(VertexConstraint) +
                 r.forces.size() * sizeof(PointForce) + r.limit_constraints.size() * sizeof(LimitConstraint) +
                 r.surface_forces.size() * sizeof(SurfaceForce);
  for (const auto& c : r.lagrange_constraints) {
    bytes += sizeof(LagrangeConstraint) + c.indices.size() * sizeof(int32_t) + c.coefficients.size() * sizeof(Vec3);
  }
  return bytes;
}

Error not_found(const GeomId& id) {
  return Error{ErrorCode::kNotFound, "no geometry with id " + id.hex() + " (upload it first with POST /geometries)"};
}

Error shutdown_error() { return Error{ErrorCode::kUnavailable, "the server is shutting down"}; }

Error no_room(const MemoryBudget& budget, size_t bytes, const std::string& what) {
  return Error{ErrorCode::kResourceExhausted, "the server's memory budget (" + megabytes(budget.budget()) + ", " +
                                                  megabytes(budget.used()) + " in use) cannot hold " + what + " of " +
                                                  megabytes(bytes) +
                                                  "; free some (delete geometries, release holds) or restart the server "
                                                  "with a larger --store-mb"};
}

size_t mesh_bytes(const ControlMesh& mesh) {
  return sizeof(Geometry) + mesh.positions().size() * sizeof(Vec3) +
         (mesh.face_indices().size() + mesh.face_offsets().size()) * sizeof(int32_t) +
         mesh.creases().size() * sizeof(Crease) + mesh.corners().size() * sizeof(Corner);
}

// What a precomputed model will take before it exists (replaced by ShellModel::memory_bytes()
// once built).
size_t model_estimate(const ControlMesh& mesh, const engine::PrecomputeOptions& options) {
  return engine::ShellModel::estimate_memory_bytes(mesh, options);
}

size_t result_bytes(const StoredResult& r) {
  return sizeof(StoredResult) + r.positions.size() * sizeof(Vec3) + request_bytes(r.request) +
         (r.holds ? r.holds->size() * (sizeof(std::pair<std::string, uint64_t>) + 16) : 0);
}

Error deleted_error(const GeomId& id, const std::string& what) {
  return Error{ErrorCode::kGone, "geometry " + id.hex() + " was deleted (DELETE /geometries/{id}) " + what};
}

GeometryInfo Entry::info_locked() const {
  GeometryInfo info;
  info.id = id;
  info.name_space = geometry->name_space;
  info.vertices = geometry->mesh.num_vertices();
  info.faces = geometry->mesh.num_faces();
  info.status = status;
  info.results = static_cast<uint32_t>(results.size());
  info.progress = status == GeometryStatus::kReady ? 1.0 : progress.load(std::memory_order_relaxed);
  info.error = error;
  return info;
}

}  // namespace internal

namespace {

using namespace internal;

size_t physical_memory() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return size_t{4} << 30;
  return static_cast<size_t>(pages) * static_cast<size_t>(page);
}

int hardware_threads() { return std::max(1, static_cast<int>(std::thread::hardware_concurrency())); }

Result<void> check_namespace(std::string_view ns) {
  auto bad = [](const std::string& m) -> Result<void> { return Error{ErrorCode::kInvalidArgument, m}; };
  if (ns.size() > 256) return bad("a namespace is at most 256 bytes long, got " + std::to_string(ns.size()));
  // UTF-8 without control characters.
  for (size_t i = 0; i < ns.size();) {
    const auto c = static_cast<unsigned char>(ns[i]);
    if (c < 0x20 || c == 0x7f) return bad("a namespace must not contain control characters");
    size_t len = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xe ? 3 : (c >> 3) == 0x1e ? 4 : 0;
    if (len == 0 || i + len > ns.size()) return bad("a namespace must be valid UTF-8");
    for (size_t k = 1; k < len; ++k) {
      if ((static_cast<unsigned char>(ns[i + k]) >> 6) != 0x2) return bad("a namespace must be valid UTF-8");
    }
    i += len;
  }
  return {};
}

}  // namespace

namespace {

// Stress query points must lie on the limit surface; the message names the first that does not.
Result<void> validate_points(const std::vector<SurfacePoint>& points, const LimitEvaluator& evaluator) {
  for (size_t k = 0; k < points.size(); ++k) {
    if (auto ok = evaluator.check(points[k]); !ok) {
      return Error{ErrorCode::kInvalidArgument, "stress point " + std::to_string(k) + ": " + ok.error().message};
    }
  }
  return {};
}

}  // namespace

Service::Impl::Impl(const ServiceOptions& o)
    : options(o),
      cache(std::make_shared<engine::FactorCache>(o.cache_bytes)),
      budget(o.store_bytes ? o.store_bytes : physical_memory() / 2),
      executor(o.executor ? o.executor
                          : std::make_shared<ThreadPool>(std::max(1, o.precompute_jobs) +
                                                         (o.solve_threads > 0 ? o.solve_threads : hardware_threads()))),
      precompute_pool(executor, std::max(1, o.precompute_jobs)),
      solve_pool(executor, o.solve_threads > 0 ? o.solve_threads : hardware_threads()) {
  // A host that gives its executor runs the precomputations' parallel work on it too.
  if (o.executor && !options.precompute.executor) options.precompute.executor = o.executor;
}

std::shared_ptr<Entry> Service::Impl::find(const GeomId& id) const {
  std::shared_lock lock(registry_mu);
  auto it = by_id.find(id);
  return it == by_id.end() ? nullptr : it->second;
}

std::vector<std::shared_ptr<Entry>> Service::Impl::all() const {
  std::shared_lock lock(registry_mu);
  return in_order;
}

Result<LimitEvaluator> Service::Impl::evaluator(const Entry& e) const {
  {
    std::lock_guard lock(e.mu);
    if (e.model) return e.model->evaluator();
  }
  std::lock_guard lock(e.evaluator_mu);
  if (!e.evaluator && !e.evaluator_error) {
    // The same surface the model will have: the engine simulates the smooth limit surface of
    // the control mesh, without crease and corner tags (ShellModel::build).
    ControlMesh smooth = e.geometry->mesh;
    smooth.creases().clear();
    smooth.corners().clear();
    auto created = capture([&] { return LimitEvaluator::create(smooth, options.precompute.evaluator); });
    if (created) e.evaluator = std::move(*created);
    else e.evaluator_error = created.error();
  }
  if (e.evaluator_error) return *e.evaluator_error;
  return *e.evaluator;
}

Result<void> Service::Impl::validate(const Entry& e, const DeformationRequest& request) const {
  RequestContext context{e.geometry->mesh.num_vertices(), nullptr};
  std::optional<LimitEvaluator> surface;
  if (!request.limit_constraints.empty() || !request.surface_forces.empty()) {
    auto made = evaluator(e);
    if (!made) return made.error();
    surface = std::move(*made);
    context.evaluator = &*surface;
  }
  return validate_request(request, context);
}

void Service::Impl::start_precompute(const std::shared_ptr<Entry>& e) {
  precompute_pool.submit([this, e] {
    if (stopping.load()) {
      finish_precompute(e, shutdown_error(), 0.0);
      return;
    }
    const auto& g = *e->geometry;
    options.logger.info("precomputing geometry " + e->id.hex() + " (" + std::to_string(g.mesh.num_vertices()) +
                        " control points, " + std::to_string(g.mesh.num_faces()) + " faces)");
    engine::PrecomputeOptions opts = options.precompute;
    opts.threads = options.precompute_threads;
    opts.progress = [e](double f) { e->progress.store(std::clamp(f, 0.0, 1.0), std::memory_order_relaxed); };
    opts.cancel = &e->cancel;  // set by Service::remove and by shutdown
    precomputing_now.fetch_add(1);
    const auto start = Clock::now();
    auto model = capture([&] { return engine::ShellModel::build(g.mesh, g.material, opts); });
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    precomputing_now.fetch_sub(1);
    if (model && !*model) model = Error{ErrorCode::kInternal, "the precomputation returned no model"};
    finish_precompute(e, std::move(model), seconds);
  });
}

void Service::Impl::finish_precompute(const std::shared_ptr<Entry>& e,
                                      Result<std::shared_ptr<const engine::ShellModel>> model, double seconds) {
  std::vector<Pending> pending;
  std::shared_ptr<const engine::Solver> solver;
  std::string error;
  bool launch_holds = false;
  {
    std::lock_guard lock(e->mu);
    if (e->deleted) return;  // remove() answered everyone and returned the memory; the model is dropped
    if (model) {
      e->model = std::move(*model);
      e->model_id = e->model->id();
      solver = std::make_shared<const engine::Solver>(e->model, cache);
      e->solver = solver;
      engine::NonlinearOptions nonlinear_options = options.nonlinear;
      nonlinear_options.cancel = &stopping;  // a shutdown stops a long nonlinear solve
      e->nonlinear = std::make_shared<const engine::NonlinearSolver>(e->model, cache, nonlinear_options);
      precompute_hist.observe(seconds);  // before the status is visible: stats never lag it
      e->status = GeometryStatus::kReady;
      const size_t actual = mesh_bytes(e->geometry->mesh) + e->model->memory_bytes();
      budget.resize(e->reserved_bytes, actual);
      e->reserved_bytes = actual;
      launch_holds = claim_hold_solve_locked(*e);  // hold changes made while it precomputed
    } else {
      e->status = GeometryStatus::kFailed;
      e->error = model.error().message;
      const size_t kept = mesh_bytes(e->geometry->mesh);
      budget.resize(e->reserved_bytes, kept);
      e->reserved_bytes = kept;
      error = "the precomputation of geometry " + e->id.hex() + " failed: " + e->error;
    }
    pending.swap(e->pending);
  }
  e->cv.notify_all();
  if (solver) {
    options.logger.info("geometry " + e->id.hex() + " is ready (precomputed in " + std::to_string(seconds) + " s)");
    for (auto& [request, done] : pending) submit_solve(e, solver, std::move(request), std::move(done));
    if (launch_holds) launch_hold_solve(e);
  } else {
    const bool shutdown = model.error().code == ErrorCode::kUnavailable || model.error().code == ErrorCode::kCancelled;
    if (!shutdown) options.logger.warning(error);
    const Error failure = shutdown ? shutdown_error() : Error{ErrorCode::kUnprocessable, error};
    for (auto& [request, done] : pending) done(failure);
    fail_hold_waiters(*e, failure, /*drop_changes=*/true);
  }
}

Result<ResultPtr> Service::Impl::store(Entry& e, std::shared_ptr<StoredResult> stored,
                                       const std::function<void()>& locked) {
  const size_t bytes = result_bytes(*stored);
  {
    // The id is assigned here, under the geometry's lock, at the moment the result is stored:
    // ids follow the storage order and none is skipped or reused.
    std::lock_guard lock(e.mu);
    if (e.deleted) {
      // A solve that ran while the geometry was deleted: its result is discarded, and any factor
      // it put into the cache goes too.
      if (e.model_id) cache->forget_model(e.model_id);
      return deleted_error(e.id, "while this request was solved; its result was discarded");
    }
    if (!retain_locked(e, bytes)) {
      refused_no_memory.fetch_add(1);
      if (!options.retention.drop_oldest_when_full) return no_room(budget, bytes, "another result");
      return Error{ErrorCode::kResourceExhausted,
                   "the server's memory budget (" + megabytes(budget.budget()) + ", " + megabytes(budget.used()) +
                       " in use) cannot hold another result of " + megabytes(bytes) +
                       " even without this geometry's older results (the newest is always kept); other geometries "
                       "hold the rest (delete some, or restart the server with a larger --store-mb)"};
    }
    stored->res_id = e.next_res_id();
    stored->stored_at = std::chrono::system_clock::now();
    // On disk before anyone can see it; a failed write uses up no id.
    if (persistent) {
      if (auto saved = persistent->save_result(e.id, *stored); !saved) {
        budget.release(bytes);
        return saved.error();
      }
    }
    total_results.fetch_add(1);  // counters first, so that whoever sees the result also sees them
    e.results.push_back(stored);
    e.result_bytes += bytes;
    retain_locked(e, 0);  // the count and byte limits, now that the new result is the newest
    if (locked) locked();
  }
  e.cv.notify_all();
  notify(e);
  return ResultPtr(std::move(stored));
}

bool Service::Impl::retain_locked(Entry& e, size_t room) {
  const ResultRetention& keep = options.retention;
  auto drop_oldest = [&] {
    const size_t b = result_bytes(*e.results.front());
    e.results.pop_front();
    ++e.first_kept;
    e.result_bytes -= std::min(e.result_bytes, b);
    budget.release(b);
    total_results.fetch_sub(1);
    results_dropped.fetch_add(1);
  };
  // What was dropped leaves the data directory too (one transaction for all of them); a failed
  // write is logged: at a restart the store would only bring back results retention dropped.
  struct OnDisk {
    Impl& impl;
    Entry& e;
    uint32_t first;
    ~OnDisk() {
      if (!impl.persistent || e.first_kept == first) return;
      if (auto ok = impl.persistent->drop_results_through(e.id, e.first_kept - 1); !ok) {
        impl.options.logger.error("the data directory did not take the retention of geometry " + e.id.hex() + ": " +
                                  ok.error().message);
      }
    }
  } on_disk{*this, e, e.first_kept};
  if (room == 0) {  // after a store: the policy's limits (the newest result always stays)
    while (e.results.size() > 1 && ((keep.keep_results && e.results.size() > keep.keep_results) ||
                                    (keep.bytes_per_geometry && e.result_bytes > keep.bytes_per_geometry))) {
      drop_oldest();
    }
    return true;
  }
  if (budget.try_reserve(room)) return true;
  if (!keep.drop_oldest_when_full || e.results.size() <= 1) return false;
  // Drop only if that makes room: everything but the newest result must free enough (other
  // geometries may take memory meanwhile; then the loop stops at the newest and refuses).
  const size_t droppable = e.result_bytes - result_bytes(*e.results.back());
  const size_t used = budget.used(), total = budget.budget();
  if (room > total || used - std::min(used, droppable) > total - room) return false;
  while (e.results.size() > 1) {
    drop_oldest();
    if (budget.try_reserve(room)) return true;
  }
  return false;
}

void Service::Impl::notify(Entry& e) {
  std::lock_guard serial(e.notify_mu);
  for (;;) {
    ResultPtr result;
    std::vector<std::shared_ptr<ListenerSlot>> listeners;
    {
      std::lock_guard lock(e.mu);
      // The next id not handed out yet; ids the retention policy dropped meanwhile are skipped.
      const uint32_t next = std::max(e.notified + 1, e.first_kept);
      if (e.deleted || next >= e.next_res_id()) return;
      result = e.results[next - e.first_kept];
      e.notified = next;
      listeners = e.listeners;
    }
    for (const auto& slot : listeners) {
      std::lock_guard call(slot->mu);
      if (slot->active) slot->fn(result);
    }
  }
}

void Service::Impl::account_nonlinear(Entry& e, const engine::NonlinearSolver& nonlinear) {
  const size_t bytes = nonlinear.memory_bytes();
  std::lock_guard lock(e.mu);
  if (e.deleted) return;  // its memory went with it
  budget.resize(e.nonlinear_bytes, bytes);
  e.nonlinear_bytes = bytes;
}

void Service::Impl::submit_solve(const std::shared_ptr<Entry>& e, std::shared_ptr<const engine::Solver> solver,
                                 DeformationRequest request, DeformCallback done) {
  solve_pool.submit([this, e, solver = std::move(solver), request = std::move(request),
                     done = std::move(done)]() mutable {
    if (stopping.load()) {
      done(shutdown_error());
      return;
    }
    const auto start = Clock::now();
    auto stored = std::make_shared<StoredResult>();
    // Each model's answer passed its engine's check (equilibrium and every constraint).
    Result<Eigen::VectorXd> displacement = capture([&]() -> Result<Eigen::VectorXd> {
      if (request.model == DeformationModel::kNonlinear) {
        std::shared_ptr<const engine::NonlinearSolver> nonlinear;
        {
          std::lock_guard lock(e->mu);
          nonlinear = e->nonlinear;
        }
        auto answer = nonlinear->solve(request);  // from rest: a request is solved alone
        account_nonlinear(*e, *nonlinear);
        if (!answer) return answer.error();
        stored->nonlinear = answer->stats;
        return std::move(answer->displacement);
      }
      auto answer = solver->solve(request);
      if (!answer) return answer.error();
      stored->stats = answer->stats;
      return std::move(answer->displacement);
    });
    if (!displacement) {
      solves_failed.fetch_add(1);
      Error err = displacement.error();
      if (err.code == ErrorCode::kCancelled) err = shutdown_error();  // only a shutdown cancels a solve
      if (err.code == ErrorCode::kInternal) options.logger.error("solve failed: " + err.message);
      done(std::move(err));
      return;
    }
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    stored->positions = engine::Solution{*displacement, {}}.positions(e->geometry->mesh);
    for (const Vec3& p : stored->positions) {
      if (!p.allFinite()) {
        solves_failed.fetch_add(1);
        done(Error{ErrorCode::kUnprocessable,
                   "the solve produced non-finite positions: the forces and constraints do not determine the "
                   "deformation"});
        return;
      }
    }
    stored->request = std::move(request);
    auto kept = store(*e, std::move(stored), [&] {
      solves_ok.fetch_add(1);
      solve_hist.observe(seconds);
    });
    done(std::move(kept));
  }, e.get());  // round-robin over the geometries with queued solves
}

Service::Service(ServiceOptions options) : options_(std::move(options)), impl_(std::make_unique<Impl>(options_)) {
  if (!options_.data_dir.empty()) {
    if (auto restored = impl_->restore(); !restored) throw Exception(restored.error());
  }
}

Result<std::shared_ptr<Service>> Service::create(ServiceOptions options) {
  return capture([&] { return Result<std::shared_ptr<Service>>(std::make_shared<Service>(std::move(options))); });
}

Service::~Service() { shutdown(); }

bool Service::shutting_down() const { return impl_->stopping.load(); }

void Service::shutdown() {
  std::lock_guard once(impl_->shutdown_mu);
  impl_->stopping.store(true);
  // Answer every request that waits for a precomputation and wake every waiter.
  impl_->leases.stop();
  for (const auto& e : impl_->all()) {
    e->cancel.store(true);
    std::vector<Pending> pending;
    {
      std::lock_guard lock(e->mu);
      pending.swap(e->pending);
    }
    e->cv.notify_all();
    for (auto& p : pending) p.second(shutdown_error());
    impl_->fail_hold_waiters(*e, shutdown_error(), /*drop_changes=*/false);
  }
  impl_->precompute_pool.shutdown();
  impl_->solve_pool.shutdown();
}

Result<UploadResult> Service::upload(ControlMesh mesh, Material material, std::string name_space) {
  return capture([&] { return upload_checked(std::move(mesh), material, std::move(name_space)); });
}

Result<UploadResult> Service::upload_checked(ControlMesh mesh, const Material& material, std::string name_space) {
  if (impl_->stopping.load()) return shutdown_error();
  if (auto ok = check_namespace(name_space); !ok) return ok.error();
  const GeomId id = geometry_id(mesh, material, name_space);
  auto existing = [&](const Entry& e) {
    std::lock_guard lock(e.mu);
    return UploadResult{id, false, e.status};
  };
  if (auto e = impl_->find(id)) return existing(*e);

  // New content: validate before storing anything.
  if (auto ok = capture([&] { return validate_mesh(mesh); }); !ok) return ok.error();
  if (auto ok = material.check(); !ok) return ok.error();
  const size_t bytes = mesh_bytes(mesh) + model_estimate(mesh, impl_->options.precompute);

  auto entry = std::make_shared<Entry>();
  entry->id = id;
  entry->geometry = std::make_shared<const Geometry>(Geometry{std::move(mesh), material, std::move(name_space)});
  entry->reserved_bytes = bytes;
  {
    std::unique_lock lock(impl_->registry_mu);
    if (auto it = impl_->by_id.find(id); it != impl_->by_id.end()) {
      auto e = it->second;
      lock.unlock();
      return existing(*e);
    }
    if (!impl_->budget.try_reserve(bytes)) {
      impl_->refused_no_memory.fetch_add(1);
      return Error{ErrorCode::kResourceExhausted,
                   "the server's memory budget (" + megabytes(impl_->budget.budget()) + ", " +
                       megabytes(impl_->budget.used()) + " in use) cannot hold this geometry (about " +
                       megabytes(bytes) + " with its precomputation); geometries are never dropped to make room"};
    }
    auto dead = impl_->deleted.find(id);
    const uint32_t first_res_id = dead != impl_->deleted.end() ? dead->second.next_res_id : 1;
    if (impl_->persistent) {
      if (auto saved = impl_->persistent->save_geometry(id, *entry->geometry, first_res_id); !saved) {
        impl_->budget.release(bytes);
        return saved.error();
      }
    }
    if (dead != impl_->deleted.end()) {
      // The same content uploaded again after a delete: a new life whose ids continue the old ones.
      entry->first_kept = entry->first_of_life = first_res_id;
      entry->notified = first_res_id - 1;
      impl_->budget.release(dead->second.bytes());
      entry->holds.retired = std::move(dead->second.hold_versions);
      impl_->deleted_order.erase(dead->second.seq);
      impl_->deleted.erase(dead);
    }
    impl_->by_id.emplace(id, entry);
    impl_->in_order.push_back(entry);
  }
  impl_->start_precompute(entry);
  return UploadResult{id, true, GeometryStatus::kPrecomputing};
}

void Service::Impl::remember_deleted_locked(const GeomId& id, Tombstone dead) {
  dead.seq = next_deleted_seq++;
  budget.resize(0, dead.bytes());  // small and never refused: a delete always goes through
  deleted_order.emplace(dead.seq, id);
  deleted[id] = std::move(dead);
  while (deleted.size() > PersistentStore::kMaxDeletedGeometries) {
    auto oldest = deleted.find(deleted_order.begin()->second);
    budget.release(oldest->second.bytes());
    deleted.erase(oldest);
    deleted_order.erase(deleted_order.begin());
  }
}

Result<void> Service::remove(const GeomId& id) {
  if (impl_->stopping.load()) return shutdown_error();
  std::shared_ptr<Entry> e;
  std::vector<Pending> pending;
  std::vector<std::shared_ptr<ListenerSlot>> listeners;
  std::deque<ResultPtr> results;  // freed outside the locks
  std::shared_ptr<const engine::ShellModel> model;
  {
    std::unique_lock registry(impl_->registry_mu);
    auto it = impl_->by_id.find(id);
    if (it == impl_->by_id.end()) return not_found(id);
    e = it->second;
    std::lock_guard lock(e->mu);
    // What the next upload of this content continues from (registered with the removal, under
    // the registry lock, so that an upload sees either the geometry or its tombstone).
    Tombstone dead;
    dead.next_res_id = e->next_res_id();
    dead.hold_versions = e->holds.retired;
    for (const auto& [hold_id, h] : e->holds.live) dead.hold_versions[hold_id] = h.next_version;
    // Off the disk first, with its tombstone: a geometry whose delete was answered must not come
    // back at a restart, nor its next upload reuse its ids. (Under e->mu: no result is stored
    // meanwhile, so the tombstone's next id is still the next one.)
    if (impl_->persistent) {
      DeletedGeometry record{id, dead.next_res_id, {dead.hold_versions.begin(), dead.hold_versions.end()}};
      if (auto gone = impl_->persistent->delete_geometry(record); !gone) return gone.error();
    }
    impl_->by_id.erase(it);
    auto& order = impl_->in_order;
    order.erase(std::remove(order.begin(), order.end(), e), order.end());

    e->deleted = true;
    e->cancel.store(true);  // a running precomputation stops at its next check
    impl_->remember_deleted_locked(id, std::move(dead));

    pending.swap(e->pending);
    listeners.swap(e->listeners);
    results.swap(e->results);
    impl_->total_results.fetch_sub(results.size());
    impl_->budget.release(e->reserved_bytes + e->result_bytes + e->nonlinear_bytes);
    e->reserved_bytes = 0;
    e->result_bytes = 0;
    e->nonlinear_bytes = 0;
    model = std::move(e->model);
    e->solver.reset();
    e->nonlinear.reset();
    e->holds.committed.clear();
    e->holds.latest.reset();
    if (e->model_id) impl_->cache->forget_model(e->model_id);
    impl_->geometries_deleted.fetch_add(1);
  }
  e->cv.notify_all();  // latest_result and wait_until_precomputed waiters
  for (auto& p : pending) p.second(deleted_error(id, "while this request waited for its precomputation"));
  impl_->fail_hold_waiters(*e, deleted_error(id, "before this hold change was solved"), /*drop_changes=*/true);
  const Error ended = deleted_error(id, "; no more results follow");
  for (const auto& slot : listeners) {
    std::lock_guard call(slot->mu);
    if (slot->active && slot->ended) slot->ended(ended);
  }
  impl_->options.logger.info("geometry " + id.hex() + " was deleted");
  return {};
}

std::vector<GeometryInfo> Service::geometries() const {
  std::vector<GeometryInfo> out;
  for (const auto& e : impl_->all()) {
    std::lock_guard lock(e->mu);
    out.push_back(e->info_locked());
  }
  return out;
}

Result<GeometryInfo> Service::info(const GeomId& id) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  std::lock_guard lock(e->mu);
  return e->info_locked();
}

Result<std::shared_ptr<const Geometry>> Service::geometry(const GeomId& id) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  return e->geometry;
}

Result<GeometryInfo> Service::wait_until_precomputed(const GeomId& id, std::chrono::milliseconds timeout) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  std::unique_lock lock(e->mu);
  e->cv.wait_for(lock, timeout, [&] {
    return e->status != GeometryStatus::kPrecomputing || e->deleted || impl_->stopping.load();
  });
  if (e->deleted) return deleted_error(id, "while this call waited for its precomputation");
  return e->info_locked();
}

void Service::deform(const GeomId& id, DeformationRequest request, DeformCallback done) {
  if (impl_->stopping.load()) return done(shutdown_error());
  auto e = impl_->find(id);
  if (!e) return done(not_found(id));

  if (auto ok = impl_->validate(*e, request); !ok) return done(ok.error());

  std::unique_lock lock(e->mu);
  if (impl_->stopping.load()) {
    lock.unlock();
    return done(shutdown_error());
  }
  if (e->deleted) {
    lock.unlock();
    return done(not_found(id));
  }
  switch (e->status) {
    case GeometryStatus::kFailed: {
      Error err{ErrorCode::kUnprocessable, "the precomputation of geometry " + id.hex() + " failed: " + e->error};
      lock.unlock();
      return done(std::move(err));
    }
    case GeometryStatus::kReady: {
      auto solver = e->solver;
      lock.unlock();
      return impl_->submit_solve(e, std::move(solver), std::move(request), std::move(done));
    }
    case GeometryStatus::kPrecomputing: {
      // Bounded in number and budgeted while it waits: a burst of requests on a geometry still
      // precomputing cannot fill memory.
      if (e->pending.size() >= impl_->options.max_waiting_per_geometry) {
        const size_t most = impl_->options.max_waiting_per_geometry;
        lock.unlock();
        return done(Error{ErrorCode::kUnavailable, std::to_string(most) + " requests wait for the precomputation of "
                                                       "geometry " + id.hex() + " already (the most it takes); "
                                                       "retry once it is ready (GET /geometries/{id}/status)"});
      }
      const size_t bytes = request_bytes(request);
      if (!impl_->budget.try_reserve(bytes)) {
        lock.unlock();
        impl_->refused_no_memory.fetch_add(1);
        return done(no_room(impl_->budget, bytes, "a request waiting for the precomputation"));
      }
      MemoryBudget& budget = impl_->budget;
      e->pending.emplace_back(std::move(request), [&budget, bytes, done = std::move(done)](Result<ResultPtr> r) {
        budget.release(bytes);  // answered: it waits no more
        done(std::move(r));
      });
      return;
    }
  }
}

std::future<Result<ResultPtr>> Service::deform(const GeomId& id, DeformationRequest request) {
  auto promise = std::make_shared<std::promise<Result<ResultPtr>>>();
  auto future = promise->get_future();
  deform(id, std::move(request), [promise](Result<ResultPtr> r) { promise->set_value(std::move(r)); });
  return future;
}

Result<std::vector<uint32_t>> Service::result_ids(const GeomId& id) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  std::lock_guard lock(e->mu);
  std::vector<uint32_t> ids(e->results.size());
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = e->first_kept + static_cast<uint32_t>(i);
  return ids;
}

Result<ResultPtr> Service::result(const GeomId& id, uint32_t res_id) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  std::lock_guard lock(e->mu);
  const uint32_t next = e->next_res_id();
  auto kept = [&] {
    return e->results.empty() ? std::string("it keeps none")
                              : "it keeps " + std::to_string(e->first_kept) + ".." + std::to_string(next - 1);
  };
  if (res_id == 0 || res_id >= next) {
    return Error{ErrorCode::kNotFound, "geometry " + id.hex() + " has no result " + std::to_string(res_id) +
                                           " (" + kept() + ")"};
  }
  if (res_id < e->first_of_life) {
    return Error{ErrorCode::kGone, "result " + std::to_string(res_id) + " of geometry " + id.hex() +
                                       " belonged to an earlier upload of it that was deleted (this upload's "
                                       "results start at " + std::to_string(e->first_of_life) + "; " + kept() + ")"};
  }
  if (res_id < e->first_kept) {
    return Error{ErrorCode::kGone, "result " + std::to_string(res_id) + " of geometry " + id.hex() +
                                       " is no longer kept: the server keeps the newest results of each geometry (" +
                                       kept() + "; see --keep-results)"};
  }
  return e->results[res_id - e->first_kept];
}

namespace {

// The stresses of a result of the nonlinear model: the Cauchy (true) resultants of the deformed
// surface from its Green-Lagrange strains, in the layout of the linear ones (a linear evaluation
// of a large displacement would show the strains of the rotation).
StressSample from_nonlinear(const engine::ShellModel& model, const engine::NonlinearStressSample& n) {
  StressSample s;
  s.point = n.point;
  s.position = model.evaluator().evaluate(n.point).position;  // rest position, as the linear samples
  s.membrane_force = n.cauchy_membrane_force;
  s.bending_moment = n.cauchy_bending_moment;
  s.von_mises_top = n.von_mises_top;
  s.von_mises_bottom = n.von_mises_bottom;
  return s;
}

Result<StressField> nonlinear_stresses(const engine::ShellModel& model, const Eigen::VectorXd& u,
                                       const StressQuery& query, StressField field) {
  const engine::NonlinearStressSummary summary = engine::nonlinear_max_stress(model, u, field.yield_strength);
  field.max = from_nonlinear(model, summary.max);
  field.exceeds_yield = field.yield_strength > 0.0 && summary.exceeds_yield;
  std::vector<SurfacePoint> points;
  if (query.level > 0) {
    points = Tessellation::create(model.evaluator(), query.level).value().vertex_points();
  } else {
    if (auto ok = validate_points(query.points, model.evaluator()); !ok) return ok.error();
    points = query.points;
  }
  field.samples.reserve(points.size());
  for (const SurfacePoint& p : points) field.samples.push_back(from_nonlinear(model, engine::evaluate_nonlinear_stress(model, u, p)));
  return field;
}

}  // namespace

Result<StressField> Service::stresses(const GeomId& id, uint32_t res_id, const StressQuery& query) const {
  if (query.level != 0 && (query.level < 1 || query.level > StressQuery::kMaxLevel)) {
    return Error{ErrorCode::kInvalidArgument, "stresses: level " + std::to_string(query.level) +
                                                  " is outside 1.." + std::to_string(StressQuery::kMaxLevel)};
  }
  if (!(query.yield_strength >= 0.0) || !std::isfinite(query.yield_strength)) {
    return Error{ErrorCode::kInvalidArgument, "stresses: the yield strength must be a finite number >= 0 (Pa)"};
  }
  if (query.level == 0 && query.points.size() > StressQuery::kMaxPoints) {
    return Error{ErrorCode::kInvalidArgument, "stresses: " + std::to_string(query.points.size()) +
                                                  " points asked for, at most " +
                                                  std::to_string(StressQuery::kMaxPoints) + " are served at once"};
  }
  auto stored = result(id, res_id);
  if (!stored) return stored.error();
  std::shared_ptr<const engine::ShellModel> model;
  {
    auto e = impl_->find(id);
    if (!e) return not_found(id);  // deleted since
    std::lock_guard lock(e->mu);
    model = e->model;  // a stored result implies a finished precomputation
  }
  if (!model) return Error{ErrorCode::kInternal, "stresses: geometry " + id.hex() + " has results but no model"};
  return capture([&] {
    const ControlMesh& mesh = model->mesh();
    Eigen::VectorXd u(model->num_dofs());
    for (int32_t i = 0; i < mesh.num_vertices(); ++i) {
      u.segment<3>(3 * i) = (*stored)->positions[static_cast<size_t>(i)] - mesh.positions()[static_cast<size_t>(i)];
    }
    StressField field;
    field.res_id = res_id;
    field.yield_strength = query.yield_strength;
    if ((*stored)->nonlinear) return nonlinear_stresses(*model, u, query, std::move(field));
    const engine::StressSummary summary = engine::max_stress(*model, u, field.yield_strength);
    field.max = summary.max;
    field.exceeds_yield = field.yield_strength > 0.0 && summary.exceeds_yield;
    if (query.level > 0) {
      const Tessellation tessellation = Tessellation::create(model->evaluator(), query.level).value();
      field.samples = engine::evaluate_stresses(*model, u, tessellation.vertex_points());
    } else {
      if (auto ok = validate_points(query.points, model->evaluator()); !ok) return Result<StressField>(ok.error());
      field.samples = engine::evaluate_stresses(*model, u, query.points);
    }
    return Result<StressField>(std::move(field));
  }, "computing stresses");
}

Result<ResultPtr> Service::latest_result(const GeomId& id, uint32_t have, std::chrono::milliseconds wait,
                                         std::stop_token stop) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  auto newer = [&] { return !e->results.empty() && e->results.back()->res_id > have; };
  {
    std::lock_guard lock(e->mu);
    if (newer()) return e->results.back();
    if (e->deleted) return not_found(id);
  }
  if (wait.count() <= 0) return ResultPtr();
  if (impl_->stopping.load() || stop.stop_requested()) return shutdown_error();

  // The stop callback takes the geometry's lock, so it is registered before this thread takes
  // it (a callback that runs at once, in the constructor, must not deadlock).
  std::stop_callback wake(stop, [&] {
    std::lock_guard lock(e->mu);
    e->cv.notify_all();
  });
  std::unique_lock lock(e->mu);
  impl_->waiters.fetch_add(1);
  e->cv.wait_for(lock, wait,
                 [&] { return newer() || e->deleted || impl_->stopping.load() || stop.stop_requested(); });
  impl_->waiters.fetch_sub(1);
  if (newer()) return e->results.back();
  if (e->deleted) return deleted_error(id, "while this request waited for a newer result");
  if (impl_->stopping.load() || stop.stop_requested()) return shutdown_error();
  return ResultPtr();
}

Result<LimitComb> Service::limit_comb(const GeomId& id, const SurfacePoint& point) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  auto evaluator = impl_->evaluator(*e);
  if (!evaluator) return evaluator.error();
  if (auto ok = evaluator->check(point); !ok) return ok.error();
  return capture([&]() -> Result<LimitComb> {
    LimitStencil s = evaluator->stencil(point);
    return LimitComb{point, std::move(s.indices), std::move(s.position), std::move(s.du), std::move(s.dv)};
  });
}

Result<LimitEvaluator> Service::limit_evaluator(const GeomId& id) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  return impl_->evaluator(*e);
}

ServiceStats Service::stats() const {
  ServiceStats s;
  for (const auto& e : impl_->all()) {
    std::lock_guard lock(e->mu);
    ++s.geometries;
    switch (e->status) {
      case GeometryStatus::kPrecomputing: ++s.geometries_precomputing; break;
      case GeometryStatus::kReady: ++s.geometries_ready; break;
      case GeometryStatus::kFailed: ++s.geometries_failed; break;
    }
    s.pending_solves += e->pending.size();
    s.holds += e->holds.live.size();
    s.hold_changes_pending += e->holds.pending.size();
    if (e->holds.unsolvable) ++s.hold_states_unsolvable;
  }
  s.results = impl_->total_results.load();
  s.results_dropped = impl_->results_dropped.load();
  s.geometries_deleted = impl_->geometries_deleted.load();
  s.precomputations_running = impl_->precomputing_now.load();
  s.waiters = impl_->waiters.load();
  s.store_bytes = impl_->budget.used();
  s.store_budget = impl_->budget.budget();
  s.cache = impl_->cache->stats();
  s.solves_ok = impl_->solves_ok.load();
  s.solves_failed = impl_->solves_failed.load();
  s.refused_no_memory = impl_->refused_no_memory.load();
  s.solve_seconds = impl_->solve_hist.snapshot();
  s.precompute_seconds = impl_->precompute_hist.snapshot();
  s.hold_solves = impl_->hold_solves.load();
  s.hold_changes_solved = impl_->hold_changes_solved.load();
  s.hold_changes_superseded = impl_->hold_changes_superseded.load();
  s.hold_renewals = impl_->hold_renewals.load();
  s.hold_conflicts = impl_->hold_conflicts.load();
  s.hold_rejections = impl_->hold_rejections.load();
  s.leases_expired = impl_->leases_expired.load();
  s.followers = impl_->followers.load();
  s.hold_solve_seconds = impl_->hold_solve_hist.snapshot();
  if (impl_->persistent) {
    const internal::PersistentStore::WriteStats w = impl_->persistent->write_stats();
    s.data_dir = true;
    s.data_dir_bytes = impl_->persistent->disk_bytes();
    s.data_dir_writes = w.writes;
    s.data_dir_write_failures = w.failures;
    s.data_dir_write_seconds = w.seconds;
  }
  return s;
}

}  // namespace softshell::service
