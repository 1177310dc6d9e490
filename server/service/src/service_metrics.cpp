// The service's counters and gauges in Prometheus text format (served by the HTTP layer).
#include "softshell/service/metrics.h"
#include "softshell/service/service.h"

namespace softshell::service {

std::string Service::metrics_text() const {
  const ServiceStats s = stats();
  PrometheusText m;
  auto gauge = [&](const char* name, const char* help, double value) {
    m.family(name, "gauge", help);
    m.sample(name, "", value);
  };
  auto counter = [&](const char* name, const char* help, double value) {
    m.family(name, "counter", help);
    m.sample(name, "", value);
  };
  auto d = [](auto v) { return static_cast<double>(v); };

  m.family("softshell_geometries", "gauge", "Stored geometries by precomputation status.");
  m.sample("softshell_geometries", PrometheusText::label("status", "precomputing"), d(s.geometries_precomputing));
  m.sample("softshell_geometries", PrometheusText::label("status", "ready"), d(s.geometries_ready));
  m.sample("softshell_geometries", PrometheusText::label("status", "failed"), d(s.geometries_failed));
  gauge("softshell_results", "Results kept now over all geometries.", d(s.results));
  counter("softshell_results_dropped_total", "Results dropped by the retention policy (--keep-results, --result-budget-mb).",
          d(s.results_dropped));
  counter("softshell_geometries_deleted_total", "Geometries deleted (DELETE /geometries/{id}).", d(s.geometries_deleted));
  gauge("softshell_precomputations_running", "Precomputations executing now.", d(s.precomputations_running));
  gauge("softshell_pending_solves", "Deformation requests waiting for a precomputation.", d(s.pending_solves));
  gauge("softshell_factor_cache_bytes", "Memory held by cached factorizations.", d(s.cache.bytes));
  gauge("softshell_factor_cache_budget_bytes", "Factor cache budget (--cache-mb).", d(s.cache.budget));
  gauge("softshell_factor_cache_entries", "Cached factorizations.", d(s.cache.entries));
  m.family("softshell_factor_cache_events_total", "counter", "Factor cache hits, misses and evictions.");
  m.sample("softshell_factor_cache_events_total", PrometheusText::label("event", "hit"), d(s.cache.hits));
  m.sample("softshell_factor_cache_events_total", PrometheusText::label("event", "miss"), d(s.cache.misses));
  m.sample("softshell_factor_cache_events_total", PrometheusText::label("event", "eviction"), d(s.cache.evictions));
  gauge("softshell_store_bytes", "Memory held for meshes, precomputed models (linear and nonlinear), results, holds and followers.",
        d(s.store_bytes));
  gauge("softshell_store_budget_bytes", "Budget of the store (--store-mb).", d(s.store_budget));
  counter("softshell_refused_no_memory_total", "Uploads, results, holds and followers refused by the store budget (507).",
          d(s.refused_no_memory));
  m.family("softshell_solves_total", "counter", "Deformation solves by outcome (hold-state solves included).");
  m.sample("softshell_solves_total", PrometheusText::label("outcome", "ok"), d(s.solves_ok));
  m.sample("softshell_solves_total", PrometheusText::label("outcome", "failed"), d(s.solves_failed));
  gauge("softshell_longpoll_waiters", "Service-level latest_result waiters (HTTP and embedded).", d(s.waiters));
  m.family("softshell_solve_duration_seconds", "histogram", "Time of successful solves on a worker.");
  m.histogram("softshell_solve_duration_seconds", "", s.solve_seconds);
  m.family("softshell_precompute_duration_seconds", "histogram", "Time of successful precomputations.");
  m.histogram("softshell_precompute_duration_seconds", "", s.precompute_seconds);

  gauge("softshell_holds", "Live holds over all geometries.", d(s.holds));
  gauge("softshell_hold_changes_pending", "Hold changes waiting for their geometry's next hold-state solve.",
        d(s.hold_changes_pending));
  gauge("softshell_hold_states_unsolvable", "Geometries whose remaining holds cannot be solved.",
        d(s.hold_states_unsolvable));
  counter("softshell_hold_solves_total", "Hold-state solves (each takes every change queued meanwhile).",
          d(s.hold_solves));
  counter("softshell_hold_changes_solved_total", "Hold changes taken by hold-state solves.", d(s.hold_changes_solved));
  counter("softshell_hold_changes_superseded_total",
          "Hold changes replaced by a newer PUT of their hold before a solve took them.", d(s.hold_changes_superseded));
  counter("softshell_hold_renewals_total", "PUTs of an unchanged hold (lease renewed only).", d(s.hold_renewals));
  m.family("softshell_hold_refusals_total", "counter", "Hold changes refused, by status.");
  m.sample("softshell_hold_refusals_total", PrometheusText::label("status", "409"), d(s.hold_conflicts));
  m.sample("softshell_hold_refusals_total", PrometheusText::label("status", "422"), d(s.hold_rejections));
  counter("softshell_leases_expired_total", "Holds released because their lease lapsed.", d(s.leases_expired));
  gauge("softshell_followers", "Followers of result streams (event streams) counted against the budget.",
        d(s.followers));
  m.family("softshell_hold_solve_duration_seconds", "histogram", "Time of each hold-state solve (a batch of changes).");
  m.histogram("softshell_hold_solve_duration_seconds", "", s.hold_solve_seconds);

  // Only with a data directory (--data-dir): a server in memory has no store to report.
  if (s.data_dir) {
    gauge("softshell_data_dir_bytes", "Bytes of the data directory's store on disk (database and write-ahead log).",
          d(s.data_dir_bytes));
    counter("softshell_data_dir_writes_total",
            "Write transactions committed to the data directory (uploads, results, deletes, retention).",
            d(s.data_dir_writes));
    counter("softshell_data_dir_write_failures_total",
            "Write transactions to the data directory that failed (disk full, I/O errors; answered 507 or logged).",
            d(s.data_dir_write_failures));
    m.family("softshell_data_dir_write_duration_seconds", "histogram",
             "Time of each write transaction to the data directory, committed or failed.");
    m.histogram("softshell_data_dir_write_duration_seconds", "", s.data_dir_write_seconds);
  }
  return m.take();
}

}  // namespace softshell::service
