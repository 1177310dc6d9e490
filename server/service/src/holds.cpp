// Holds (PROTOCOL.md version 2): PUT/DELETE/GET of holds, leases, and the per-geometry solver
// loop that merges changes into hold-state solves.
//
// A change (a new version, a release, a lapsed lease) is queued in the geometry's HoldTable and
// answered through a promise. At most one solve task per geometry is queued or running; it takes
// every queued change at once ("a batch"), solves the state with all of them, and if that fails
// goes through them one by one in arrival order to find the ones to refuse. Releases always go
// through; a release that leaves the rest unsolvable makes the state "unsolvable". A PUT whose
// hold already has a change queued (not yet taken by a solve) replaces it, so the queue holds at
// most one change per hold besides releases.
#include <algorithm>

#include "service_impl.h"
#include "softshell/request_validation.h"
#include "softshell/wire.h"

namespace softshell::service {

using namespace internal;

namespace {

constexpr auto kMaxTtl = std::chrono::seconds(600);

Error unknown_hold(const GeomId& id, std::string_view hold_id) {
  return Error{ErrorCode::kNotFound, "geometry " + id.hex() + " has no hold '" + std::string(hold_id) + "'"};
}

// A ticket for a change of `hold_id` and the promise that answers it.
HoldTicket new_ticket(const std::string& hold_id, HoldPromise& promise) {
  promise = std::make_shared<std::promise<Result<HoldOutcome>>>();
  HoldTicket ticket;
  ticket.hold_id = hold_id;
  ticket.outcome = promise->get_future().share();
  return ticket;
}

void apply(HoldMap& holds, const HoldChange& change) {
  if (change.version) {
    holds[change.hold_id] = change.version;
  } else if (auto it = holds.find(change.hold_id); it != holds.end()) {
    holds.erase(it);
  }
}

// The displacement (3n) that takes the rest shape of `mesh` to `positions`.
Eigen::VectorXd displacement_of(const ControlMesh& mesh, const std::vector<Vec3>& positions) {
  Eigen::VectorXd u(3 * static_cast<Eigen::Index>(positions.size()));
  for (size_t i = 0; i < positions.size(); ++i) u.segment<3>(3 * static_cast<Eigen::Index>(i)) = positions[i] - mesh.positions()[i];
  return u;
}

bool same(const HoldMap& a, const HoldMap& b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](const auto& x, const auto& y) {
           return x.first == y.first && x.second == y.second;
         });
}

// What a batch of changes comes to.
struct BatchOutcome {
  HoldMap state;                               // the holds in force afterwards
  std::vector<std::optional<Error>> refusals;  // per change: why it was refused (puts only)
  std::optional<HoldSolution> solution;        // of `state`; empty if it cannot be solved
  Error failure;                               // why not
  DeformationRequest request;                  // `state` as one request (what the result stores)
  bool unchanged = false;                      // `state` is the state it started from: no new result
  int solves = 0;
};

class BatchSolver {
 public:
  BatchSolver(const HoldSolvers& solvers, double length) : solvers_(solvers), length_(length) {}

  Result<HoldSolution> solve(const HoldMap& holds, DeformationRequest* merged = nullptr) {
    ++solves_;
    AssembledHoldState state = assemble(holds);
    auto solution = capture([&] { return solve_hold_state(solvers_, state); });
    if (solution) {
      if (!solution->displacement.allFinite()) {
        return Error{ErrorCode::kUnprocessable,
                     "the solve produced non-finite positions: the holds' forces and constraints do not determine "
                     "the deformation"};
      }
      if (merged) *merged = std::move(state.merged);
    } else if (solution.error().code == ErrorCode::kCancelled) {
      return Error{ErrorCode::kUnavailable, "the server is shutting down"};
    }
    return solution;
  }

  BatchOutcome run(const HoldMap& committed, const std::vector<HoldChange>& batch) {
    BatchOutcome out;
    out.refusals.resize(batch.size());
    HoldMap candidate = committed;
    for (const auto& change : batch) apply(candidate, change);
    // The state the batch started from (a new hold released before it was solved; every change
    // refused, below): nothing to store, and the state keeps its status (solved, never solved or
    // unsolvable).
    if (same(candidate, committed)) {
      out.state = committed;
      out.unchanged = true;
      return out;
    }
    auto attempt = solve(candidate, &out.request);
    const bool any_put = std::any_of(batch.begin(), batch.end(), [](const HoldChange& c) { return c.version != nullptr; });
    if (attempt || !any_put) {
      finish(out, candidate, std::move(attempt));
      return out;
    }
    // Some change cannot stay: apply them one by one, refusing each put whose state fails.
    HoldMap state = committed;
    std::optional<Result<HoldSolution>> last;  // of `state`, when known
    for (size_t i = 0; i < batch.size(); ++i) {
      const HoldChange& change = batch[i];
      if (!change.version) {
        apply(state, change);
        last.reset();
        continue;
      }
      HoldMap trial = state;
      apply(trial, change);
      auto tried = same(trial, candidate) ? attempt : solve(trial);
      if (tried) {
        state = std::move(trial);
        last = std::move(tried);
        continue;
      }
      const auto kept = state.find(change.hold_id);
      out.refusals[i] = explain_refusal(trial, change.hold_id, kept == state.end() ? 0 : kept->second->version,
                                        tried.error(), solvers_.linear.model().evaluator(), length_);
    }
    if (!last && same(state, committed)) {  // every change refused
      out.state = committed;
      out.unchanged = true;
      out.solves = solves_;
      return out;
    }
    if (!last) last = same(state, candidate) ? attempt : solve(state);
    DeformationRequest merged = assemble(state).merged;
    out.request = std::move(merged);
    finish(out, state, std::move(*last));
    return out;
  }

  int solves() const { return solves_; }

 private:
  void finish(BatchOutcome& out, const HoldMap& state, Result<HoldSolution> solution) {
    out.state = state;
    if (solution) {
      out.solution = std::move(*solution);
    } else {
      out.failure = solution.error();
    }
    out.solves = solves_;
  }

  const HoldSolvers& solvers_;
  double length_;
  int solves_ = 0;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// The solver loop

bool Service::Impl::claim_hold_solve_locked(Entry& e) {
  HoldTable& t = e.holds;
  if (t.solving || t.pending.empty() || e.status != GeometryStatus::kReady || stopping.load()) return false;
  t.solving = true;
  return true;
}

void Service::Impl::launch_hold_solve(const std::shared_ptr<Entry>& e) {
  solve_pool.submit([this, e] { run_hold_solve(e); }, e.get());
}

void Service::Impl::run_hold_solve(const std::shared_ptr<Entry>& e) {
  HoldTable& t = e->holds;
  std::vector<HoldChange> batch;
  HoldMap committed;
  std::shared_ptr<const engine::Solver> solver;
  std::shared_ptr<const engine::NonlinearSolver> nonlinear;
  ResultPtr previous;  // the newest result of the hold state: a nonlinear one is the warm start
  {
    std::lock_guard lock(e->mu);
    if (stopping.load()) {
      t.solving = false;
    } else {
      batch.assign(std::make_move_iterator(t.pending.begin()), std::make_move_iterator(t.pending.end()));
      t.pending.clear();
      committed = t.committed;
      solver = e->solver;
      nonlinear = e->nonlinear;
      previous = t.latest;
    }
  }
  if (!solver || !nonlinear) {
    fail_hold_waiters(*e, shutdown_error(), /*drop_changes=*/false);
    return;
  }

  const auto start = Clock::now();
  // A drag of a nonlinear hold starts each solve from the previous answer (the displacement of
  // the newest result; none when the state was linear).
  Eigen::VectorXd warm;
  if (previous && previous->nonlinear) warm = displacement_of(e->geometry->mesh, previous->positions);
  previous.reset();
  const HoldSolvers solvers{*solver, *nonlinear, warm.size() ? &warm : nullptr};
  BatchSolver solve(solvers, e->geometry->mesh.bounding_diagonal());
  BatchOutcome out = solve.run(committed, batch);
  account_nonlinear(*e, *nonlinear);
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  if (out.solves > 0) hold_solves.fetch_add(1);
  hold_changes_solved.fetch_add(batch.size());
  hold_solve_hist.observe(seconds);

  // Everything a client can see changes under one lock together with the stored result, so
  // that a renewal or GET never sees a version accepted without the result that includes it.
  std::map<uint64_t, std::vector<HoldPromise>> answers;
  bool launch_next = false;
  auto commit = [&](const ResultPtr& result, const std::string& failure) {
    t.committed = out.state;
    t.unsolvable = !result;
    t.message = failure;
    if (result) t.latest = result;
    for (size_t i = 0; i < batch.size(); ++i) {
      const HoldChange& change = batch[i];
      if (auto w = t.waiters.find(change.seq); w != t.waiters.end()) {
        answers[change.seq] = std::move(w->second);
        t.waiters.erase(w);
      }
      if (!change.version) continue;
      auto live = t.live.find(change.hold_id);
      if (live == t.live.end() || live->second.instance != change.instance) continue;  // released since
      LiveHold& h = live->second;
      if (!out.refusals[i]) {
        if (!h.accepted || h.accepted->version < change.version->version) h.accepted = change.version;
        if (h.newest_seq == change.seq) h.newest_seq = 0;
      } else if (h.newest_seq == change.seq) {  // refused and nothing newer queued: back to what it had
        h.newest = h.accepted;
        h.newest_seq = 0;
        if (!h.accepted) {  // a refused new hold is not created
          leases.cancel(h.lease);
          t.retire(change.hold_id, h);
          t.live.erase(live);
        }
      }
    }
    t.solving = false;
    launch_next = claim_hold_solve_locked(*e);
  };

  ResultPtr result;
  Error store_error{ErrorCode::kOk, ""};
  if (out.unchanged) {
    std::lock_guard lock(e->mu);
    result = t.latest;
    const bool unsolvable = t.unsolvable;
    const std::string message = t.message;
    commit(result, "");
    t.unsolvable = unsolvable;  // the state did not change, nor did its status
    t.message = message;
  } else if (out.solution) {
    auto stored = std::make_shared<StoredResult>();
    stored->positions = engine::Solution{out.solution->displacement, {}}.positions(e->geometry->mesh);
    stored->stats = out.solution->stats;
    stored->nonlinear = out.solution->nonlinear;
    stored->request = std::move(out.request);
    stored->holds = versions_of(out.state);
    auto kept = store(*e, std::move(stored), [&] {
      solves_ok.fetch_add(1);
      solve_hist.observe(seconds);
      // `result` is not known inside; t.latest is set from the stored vector's last entry.
      commit(e->results.back(), "");
    });
    if (kept) {
      result = *kept;
    } else {
      store_error = kept.error();
      std::lock_guard lock(e->mu);
      commit(nullptr, store_error.message);
    }
  } else {
    std::lock_guard lock(e->mu);
    commit(nullptr, "the remaining holds cannot be solved: " + out.failure.message);
  }

  // Versions no longer in force are freed (and their bytes returned) before anyone is answered.
  std::vector<bool> is_put(batch.size());
  for (size_t i = 0; i < batch.size(); ++i) {
    is_put[i] = batch[i].version != nullptr;
    batch[i].version.reset();
  }
  committed.clear();
  out.state.clear();

  // Answers, outside the lock.
  for (size_t i = 0; i < batch.size(); ++i) {
    const HoldChange& change = batch[i];
    if (out.refusals[i]) (out.refusals[i]->code == ErrorCode::kConflict ? hold_conflicts : hold_rejections).fetch_add(1);
    auto it = answers.find(change.seq);
    if (it == answers.end()) continue;
    Result<HoldOutcome> answer = HoldOutcome{result};
    if (out.refusals[i]) {
      answer = *out.refusals[i];
    } else if (store_error.code != ErrorCode::kOk) {
      answer = store_error;
    } else if (!result && !is_put[i]) {
      answer = Error{ErrorCode::kConflict, "hold '" + change.hold_id +
                                               "' was released, but the remaining holds cannot be solved: " +
                                               out.failure.message + " (no result is stored until a change of the "
                                               "holds makes them solvable again)"};
    }
    for (auto& promise : it->second) promise->set_value(answer);
  }
  if (launch_next) launch_hold_solve(e);
}

void Service::Impl::fail_hold_waiters(Entry& e, const Error& error, bool drop_changes) {
  std::map<uint64_t, std::vector<HoldPromise>> waiting;
  {
    std::lock_guard lock(e.mu);
    HoldTable& t = e.holds;
    waiting.swap(t.waiters);
    if (drop_changes) {
      t.pending.clear();
      for (auto& [id, h] : t.live) {
        leases.cancel(h.lease);
        t.retire(id, h);
      }
      t.live.clear();
    }
  }
  for (auto& [seq, promises] : waiting) {
    for (auto& promise : promises) promise->set_value(error);
  }
}

// ---------------------------------------------------------------------------------------------
// Leases

void Service::Impl::schedule_lease_locked(const std::shared_ptr<Entry>& e, const std::string& hold_id, LiveHold& h,
                                          std::chrono::milliseconds ttl) {
  h.expires = Clock::now() + ttl;
  if (!h.lease) h.lease = next_lease.fetch_add(1);
  leases.schedule(h.lease, h.expires, [this, weak = std::weak_ptr<Entry>(e), hold_id, lease = h.lease] {
    expire_hold(weak, hold_id, lease);
  });
}

void Service::Impl::expire_hold(const std::weak_ptr<Entry>& weak, const std::string& hold_id, uint64_t lease) {
  auto e = weak.lock();
  if (!e) return;
  bool launch = false;
  {
    std::lock_guard lock(e->mu);
    HoldTable& t = e->holds;
    auto it = t.live.find(hold_id);
    if (stopping.load() || it == t.live.end() || it->second.lease != lease || it->second.expires > Clock::now()) return;
    t.pending.push_back(HoldChange{t.next_seq++, hold_id, it->second.instance, nullptr});
    t.retire(hold_id, it->second);
    t.live.erase(it);
    leases_expired.fetch_add(1);
    launch = claim_hold_solve_locked(*e);
  }
  options.logger.info("the lease of hold '" + hold_id + "' on geometry " + e->id.hex() + " lapsed; released");
  if (launch) launch_hold_solve(e);
}

// ---------------------------------------------------------------------------------------------
// The API

Result<HoldTicket> Service::put_hold(const GeomId& id, const std::string& hold_id, DeformationRequest request,
                                     HoldOptions options) {
  return capture([&]() -> Result<HoldTicket> {
    if (impl_->stopping.load()) return shutdown_error();
    if (auto ok = wire::check_hold_id(hold_id); !ok) return ok.error();
    if (options.ttl.count() <= 0 || options.ttl > kMaxTtl) {
      return Error{ErrorCode::kInvalidArgument, "a hold's ttl is more than 0 and at most 600 seconds, got " +
                                                    std::to_string(static_cast<double>(options.ttl.count()) / 1000.0)};
    }
    auto e = impl_->find(id);
    if (!e) return not_found(id);
    if (auto ok = impl_->validate(*e, request); !ok) return ok.error();
    auto made = make_hold_version(std::move(request), impl_->budget);
    if (!made) {
      impl_->refused_no_memory.fetch_add(1);
      return made.error();
    }
    std::shared_ptr<HoldVersion> version = std::move(*made);

    HoldPromise promise;
    HoldTicket ticket = new_ticket(hold_id, promise);
    bool launch = false;
    {
      std::lock_guard lock(e->mu);
      if (impl_->stopping.load()) return shutdown_error();
      if (e->deleted) return not_found(id);  // deleted since it was found
      if (e->status == GeometryStatus::kFailed) {
        return Error{ErrorCode::kUnprocessable, "the precomputation of geometry " + id.hex() + " failed: " + e->error};
      }
      HoldTable& t = e->holds;
      auto it = t.live.find(hold_id);
      if (it != t.live.end() && it->second.newest->canonical == version->canonical) {
        // The same contents again: only the lease is renewed.
        LiveHold& h = it->second;
        impl_->hold_renewals.fetch_add(1);
        impl_->schedule_lease_locked(e, hold_id, h, options.ttl);
        ticket.version = h.newest->version;
        ticket.renewal = true;
        if (h.newest_seq) {
          t.waiters[h.newest_seq].push_back(promise);  // answered with that change
        } else {
          promise->set_value(HoldOutcome{t.unsolvable ? nullptr : t.latest});
        }
        return ticket;
      }
      if (it == t.live.end() && t.live.size() >= impl_->options.max_holds_per_geometry) {
        impl_->hold_conflicts.fetch_add(1);
        return Error{ErrorCode::kConflict,
                     "geometry " + id.hex() + " already has " + std::to_string(t.live.size()) +
                         " live holds, the most one geometry takes; hold '" + hold_id +
                         "' was not created: release a hold (DELETE) or let its lease lapse, or update an "
                         "existing hold instead of creating a new one"};
      }
      // The hold state solves every hold's constraints at once: together they stay within what
      // one request may have (RequestLimits), or the solve would be as heavy as such a request.
      size_t surface = version->request.lagrange_constraints.size() + version->request.limit_constraints.size();
      for (const auto& [other_id, other] : t.live) {
        if (other_id != hold_id && other.newest) {
          surface += other.newest->request.lagrange_constraints.size() + other.newest->request.limit_constraints.size();
        }
      }
      const size_t most = RequestLimits::for_control_points(e->geometry->mesh.num_vertices()).surface_constraints;
      if (surface > most) {
        impl_->hold_conflicts.fetch_add(1);
        return Error{ErrorCode::kConflict,
                     "with hold '" + hold_id + "' the holds of geometry " + id.hex() + " would have " +
                         std::to_string(surface) + " Lagrange and limit constraints together, more than the " +
                         std::to_string(most) +
                         " one solve takes; the hold was not changed: use fewer surface points, pin control points "
                         "with vertex constraints instead, or release other holds"};
      }
      if (it == t.live.end()) {
        LiveHold h;
        h.instance = t.next_instance++;
        if (auto r = t.retired.find(hold_id); r != t.retired.end()) {
          h.next_version = r->second;
          t.retired.erase(r);
        }
        it = t.live.emplace(hold_id, std::move(h)).first;
      }
      LiveHold& h = it->second;
      // A change of this hold that no solve has taken yet is superseded by this one: it leaves the
      // queue and its waiters wait for this change (whose result includes a newer version). So the
      // queue holds at most one change per hold (plus releases), however fast a client PUTs while
      // a solve or the precomputation runs.
      std::vector<HoldPromise> superseded;
      if (h.newest_seq) {
        const auto old = std::find_if(t.pending.begin(), t.pending.end(),
                                      [&](const HoldChange& c) { return c.seq == h.newest_seq; });
        if (old != t.pending.end()) {
          t.pending.erase(old);
          if (auto w = t.waiters.find(h.newest_seq); w != t.waiters.end()) {
            superseded = std::move(w->second);
            t.waiters.erase(w);
          }
          impl_->hold_changes_superseded.fetch_add(1);
        }
      }
      version->version = h.next_version++;
      h.newest = version;
      h.newest_seq = t.next_seq++;
      t.pending.push_back(HoldChange{h.newest_seq, hold_id, h.instance, version});
      auto& waiting = t.waiters[h.newest_seq];
      waiting = std::move(superseded);
      waiting.push_back(promise);
      impl_->schedule_lease_locked(e, hold_id, h, options.ttl);
      ticket.version = version->version;
      launch = impl_->claim_hold_solve_locked(*e);
    }
    if (launch) impl_->launch_hold_solve(e);
    return ticket;
  });
}

Result<HoldTicket> Service::release_hold(const GeomId& id, const std::string& hold_id) {
  return capture([&]() -> Result<HoldTicket> {
    if (impl_->stopping.load()) return shutdown_error();
    if (auto ok = wire::check_hold_id(hold_id); !ok) return ok.error();
    auto e = impl_->find(id);
    if (!e) return not_found(id);
    HoldPromise promise;
    HoldTicket ticket = new_ticket(hold_id, promise);
    bool launch = false;
    {
      std::lock_guard lock(e->mu);
      if (impl_->stopping.load()) return shutdown_error();
      HoldTable& t = e->holds;
      auto it = t.live.find(hold_id);
      if (it == t.live.end()) return unknown_hold(id, hold_id);
      ticket.version = it->second.newest->version;
      impl_->leases.cancel(it->second.lease);
      const uint64_t seq = t.next_seq++;
      t.pending.push_back(HoldChange{seq, hold_id, it->second.instance, nullptr});
      t.waiters[seq].push_back(promise);
      t.retire(hold_id, it->second);
      t.live.erase(it);
      launch = impl_->claim_hold_solve_locked(*e);
    }
    if (launch) impl_->launch_hold_solve(e);
    return ticket;
  });
}

Result<HoldList> Service::holds(const GeomId& id) const {
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  const auto now = Clock::now();
  std::lock_guard lock(e->mu);
  const HoldTable& t = e->holds;
  HoldList list;
  for (const auto& [hold_id, h] : t.live) {
    list.holds.push_back({hold_id, h.newest->version, std::max(0.0, std::chrono::duration<double>(h.expires - now).count())});
  }
  list.res_id = t.latest ? t.latest->res_id : 0;
  if (t.solving || !t.pending.empty()) {
    list.state = HoldStateStatus::kSolving;
  } else if (t.unsolvable) {
    list.state = HoldStateStatus::kUnsolvable;
    list.message = t.message;
  }
  return list;
}

Result<HoldDetail> Service::hold(const GeomId& id, const std::string& hold_id) const {
  if (auto ok = wire::check_hold_id(hold_id); !ok) return ok.error();
  auto e = impl_->find(id);
  if (!e) return not_found(id);
  const auto now = Clock::now();
  std::lock_guard lock(e->mu);
  auto it = e->holds.live.find(hold_id);
  if (it == e->holds.live.end()) return unknown_hold(id, hold_id);
  const LiveHold& h = it->second;
  return HoldDetail{{hold_id, h.newest->version, std::max(0.0, std::chrono::duration<double>(h.expires - now).count())},
                    h.newest->request};
}

}  // namespace softshell::service
