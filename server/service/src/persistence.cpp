// Service::Impl::restore: a service started on a data directory takes back what it holds.
#include <algorithm>

#include "service_impl.h"

namespace softshell::service {

using namespace internal;

Result<void> Service::Impl::restore() {
  auto opened = PersistentStore::open(options.data_dir);
  if (!opened) return opened.error();
  auto loaded = (*opened)->load();
  if (!loaded) return loaded.error();
  auto deleted_records = (*opened)->load_deleted();
  if (!deleted_records) return deleted_records.error();

  // What is stored must fit the budget, all of it: nothing is dropped to make room. The models
  // are rebuilt, so they count (as estimates, then their real size) beyond that, as uploads'
  // models do once built.
  size_t stored_bytes = 0, results = 0;
  for (const RestoredGeometry& g : *loaded) {
    stored_bytes += mesh_bytes(g.geometry.mesh);
    for (const auto& r : g.results) stored_bytes += result_bytes(*r);
    results += g.results.size();
    // Ids are contiguous after the dropped ones (the store's primary key makes them unique).
    uint32_t expect = g.dropped_through;
    for (const auto& r : g.results) {
      if (r->res_id != ++expect) {
        return Error{ErrorCode::kInvalidArgument, "the data directory " + options.data_dir + " is damaged: result " +
                                                      std::to_string(expect) + " of geometry " + g.id.hex() +
                                                      " is missing"};
      }
    }
  }
  if (!budget.try_reserve(stored_bytes)) {
    return Error{ErrorCode::kResourceExhausted,
                 "the data directory " + options.data_dir + " holds " + std::to_string(loaded->size()) +
                     " geometries and " + std::to_string(results) + " results (" + megabytes(stored_bytes) +
                     " in memory), more than the memory budget of " + megabytes(budget.budget()) +
                     "; start with a larger --store-mb (nothing stored is dropped to make room)"};
  }

  std::vector<std::shared_ptr<Entry>> restored;
  for (RestoredGeometry& g : *loaded) {
    auto e = std::make_shared<Entry>();
    e->id = g.id;
    const size_t estimate = model_estimate(g.geometry.mesh, options.precompute);
    e->reserved_bytes = mesh_bytes(g.geometry.mesh) + estimate;
    budget.resize(0, estimate);  // may exceed the budget until the model is built (then its real size)
    e->geometry = std::make_shared<const Geometry>(std::move(g.geometry));
    // Hold versions continue after the newest one a result includes (versions only grow per id).
    for (const auto& r : g.results) {
      if (!r->holds) continue;
      for (const auto& [hold_id, version] : *r->holds) {
        uint64_t& next = e->holds.retired[hold_id];
        next = std::max(next, version + 1);
      }
    }
    while (e->holds.retired.size() > HoldTable::kMaxRetired) e->holds.retired.erase(e->holds.retired.begin());
    // Results retention dropped stay dropped (410): the history starts after them.
    e->first_kept = g.dropped_through + 1;
    e->results.assign(g.results.begin(), g.results.end());
    for (const auto& r : g.results) e->result_bytes += result_bytes(*r);
    e->notified = e->next_res_id() - 1;  // listeners registered from now on see only new results
    total_results.fetch_add(e->results.size());
    restored.push_back(e);
  }
  {
    std::unique_lock lock(registry_mu);
    for (const auto& e : restored) {
      by_id.emplace(e->id, e);
      in_order.push_back(e);
    }
    // Deleted geometries, oldest delete first: a tombstone again, or, for content uploaded again
    // since, where that upload's life began and its holds' versions (its row's dropped_through
    // already starts its ids after the deleted ones).
    for (DeletedGeometry& d : *deleted_records) {
      Tombstone dead;
      dead.next_res_id = d.next_res_id;
      for (auto& [hold_id, version] : d.hold_versions) dead.hold_versions[std::move(hold_id)] = version;
      auto live = by_id.find(d.id);
      if (live == by_id.end()) {
        remember_deleted_locked(d.id, std::move(dead));
        continue;
      }
      Entry& e = *live->second;
      std::lock_guard entry_lock(e.mu);
      e.first_of_life = std::min(dead.next_res_id, e.first_kept);
      for (const auto& [hold_id, version] : dead.hold_versions) {
        uint64_t& next = e.holds.retired[hold_id];
        next = std::max(next, version);
      }
      while (e.holds.retired.size() > HoldTable::kMaxRetired) e.holds.retired.erase(e.holds.retired.begin());
    }
  }
  persistent = std::move(*opened);
  options.logger.info("restored " + std::to_string(restored.size()) + " geometries and " + std::to_string(results) +
                      " results from " + options.data_dir + " (" + megabytes(persistent->disk_bytes()) +
                      " on disk); precomputing them");
  // At once, in upload order, precompute_jobs at a time: the first requests find them ready
  // sooner than if each waited for its first use.
  for (const auto& e : restored) start_precompute(e);
  return {};
}

}  // namespace softshell::service
