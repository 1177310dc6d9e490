#pragma once
// PersistentStore: the service's geometries and result histories on disk (ServiceOptions::data_dir),
// in one SQLite database in WAL mode (private to the service).
//
// Durability: WAL with synchronous=NORMAL. A write has reached the operating system when its call
// returns, so it survives the process being killed (kill -9, a crash); the last writes before a
// power failure or a kernel crash may be lost (that would need synchronous=FULL: an fsync per
// result). The database is never left inconsistent either way.
//
// Layout of DIR: softshell.db (+ its -wal and -shm files while open) and softshell.lock, which a
// running store holds with flock(LOCK_EX) so that two servers never share a directory.
//
// Deleted geometries: what a deleted geometry's next upload continues from (its next result id,
// its holds' next versions) is kept in a table of its own, written in the delete's transaction,
// for the newest kMaxDeletedGeometries deletes (see there).
//
// Encoding: geometries and requests use the wire's JSON codecs (exact: doubles round-trip bit
// for bit), positions are little-endian f64 (the wire's binary result layout is f32, its JSON
// 2-3 times larger), solve statistics and hold versions a small fixed record; what is restored
// is equal to what was stored, field by field.
//
// Thread-safety: every member function may be called from any thread (one connection, guarded by
// a mutex).

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "softshell/result.h"
#include "softshell/service/metrics.h"
#include "softshell/service/service.h"
#include "softshell/session.h"

struct sqlite3;
struct sqlite3_stmt;

namespace softshell::service::internal {

// One stored geometry and its result history, as load() returns them (upload order).
struct RestoredGeometry {
  GeomId id;
  Geometry geometry;
  // Results 1..dropped_through were dropped (drop_results_through); 0 if none was.
  uint32_t dropped_through = 0;
  std::vector<std::shared_ptr<StoredResult>> results;  // ascending res_id
};

// What a deleted geometry leaves in the store, as load_deleted() returns it.
struct DeletedGeometry {
  GeomId id;
  uint32_t next_res_id = 1;     // the first result id of its next upload
  HoldVersions hold_versions;   // next version per hold id, sorted by hold id
};

class PersistentStore {
 public:
  // Stored schema (softshell_meta.schema_version) this build reads and writes. Version 1 (no
  // deleted_geometries table) is upgraded in place when opened.
  static constexpr int kSchemaVersion = 2;
  // Deleted geometries remembered; past this the oldest delete is forgotten (a later upload of
  // that content starts again at result id 1). A row is ~100 bytes without holds (16-byte id,
  // ids, B-tree overhead), so the table stays under ~2 MB in the common case; 16,384 deletes are
  // more than a day of one every 5 s, far beyond how long a client keeps ids of a deleted upload.
  // The service's in-memory table has the same bound (Service::Impl::deleted).
  static constexpr size_t kMaxDeletedGeometries = 16384;

  // Creates `dir` if missing, takes its lock and opens (or creates) its database. Refuses, with a
  // message naming the directory: a directory another process holds (kUnavailable), a file that
  // is not a softshell store, a corrupt one, a newer or unknown schema (kInvalidArgument), I/O
  // errors (kResourceExhausted when the disk is full, kInternal otherwise).
  static Result<std::unique_ptr<PersistentStore>> open(const std::string& dir);
  ~PersistentStore();
  PersistentStore(const PersistentStore&) = delete;
  PersistentStore& operator=(const PersistentStore&) = delete;

  const std::string& dir() const { return dir_; }

  // Every write is one transaction, in the database when the call returns. Failures (disk full,
  // I/O errors) are kResourceExhausted with the cause; nothing is half-written.
  // `first_res_id` > 1 continues a deleted upload's ids: results 1..first_res_id-1 count as dropped.
  Result<void> save_geometry(const GeomId& id, const Geometry& geometry, uint32_t first_res_id = 1);
  // kNotFound if the geometry was not saved.
  Result<void> save_result(const GeomId& id, const StoredResult& result);
  // The geometry and all its results, and (same transaction) records `deleted` for its next
  // upload, replacing an older record of the id; the oldest records past kMaxDeletedGeometries go.
  Result<void> delete_geometry(const DeletedGeometry& deleted);
  // Drops results 1..res_id of the geometry and remembers that they were (so that ids continue
  // after a restart even when every result was dropped).
  Result<void> drop_results_through(const GeomId& id, uint32_t res_id);

  // Everything stored, geometries in upload order. Refuses a damaged store (kInvalidArgument:
  // a record that does not decode, a geometry whose content does not match its id).
  Result<std::vector<RestoredGeometry>> load();
  // The deleted geometries remembered, oldest delete first (a record may name a geometry that was
  // uploaded again since: its ids continue from it).
  Result<std::vector<DeletedGeometry>> load_deleted();

  // Bytes of the database and its WAL on disk.
  size_t disk_bytes() const;

  // The write calls above (save_*, delete_geometry, drop_results_through), one transaction each:
  // how many committed, how many failed, and how long each took (waiting for the store's lock
  // included: what the caller waited).
  struct WriteStats {
    uint64_t writes = 0;
    uint64_t failures = 0;
    Histogram::Snapshot seconds;
  };
  WriteStats write_stats() const;

 private:
  PersistentStore() = default;
  Result<void> init();
  Result<void> exec(const char* sql);
  Error failure(const std::string& what) const;
  Result<int64_t> seq_of(const GeomId& id);
  // Runs one write and counts it (write_stats).
  template <class Write>
  Result<void> timed(Write&& write);

  std::string dir_;
  std::string db_path_;
  int lock_fd_ = -1;
  mutable std::mutex mu_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* insert_geometry_ = nullptr;
  sqlite3_stmt* insert_result_ = nullptr;
  sqlite3_stmt* find_seq_ = nullptr;
  sqlite3_stmt* delete_results_ = nullptr;
  sqlite3_stmt* delete_geometry_ = nullptr;
  sqlite3_stmt* drop_results_ = nullptr;
  sqlite3_stmt* set_dropped_ = nullptr;
  sqlite3_stmt* insert_deleted_ = nullptr;
  sqlite3_stmt* prune_deleted_ = nullptr;
  std::atomic<uint64_t> writes_{0}, write_failures_{0};
  Histogram write_seconds_;
};

}  // namespace softshell::service::internal
