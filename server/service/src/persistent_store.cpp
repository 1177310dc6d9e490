// PersistentStore: geometries and result histories in SQLite (see persistent_store.h). (About 650
// lines: the record codecs, the schema and its upgrade, and every statement share the one
// connection and its lock; split, each part would need them exported.)
#include "persistent_store.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "softshell/content_id.h"
#include "softshell/wire.h"

namespace softshell::service::internal {

static_assert(std::endian::native == std::endian::little, "the store's records are little-endian");

namespace {

constexpr const char* kDbName = "softshell.db";
constexpr const char* kLockName = "softshell.lock";
// Added in schema version 2 (created by an upgrade of a version-1 store, too). `seq` orders the
// deletes: INSERT OR REPLACE of an id deletes its older row and gives the new one the next seq.
constexpr const char* kDeletedTable =
    "CREATE TABLE deleted_geometries(seq INTEGER PRIMARY KEY AUTOINCREMENT, id BLOB NOT NULL UNIQUE,"
    " next_res_id INTEGER NOT NULL, holds BLOB NOT NULL);";

// A fixed little-endian record (solve statistics, hold versions, positions).
class Writer {
 public:
  template <class T>
  void put(T v) {
    const size_t at = out.size();
    out.resize(at + sizeof v);
    std::memcpy(out.data() + at, &v, sizeof v);
  }
  void put_string(const std::string& s) {
    put(static_cast<uint32_t>(s.size()));
    out += s;
  }
  std::string out;
};

class Reader {
 public:
  explicit Reader(std::string_view in) : in_(in) {}
  template <class T>
  T get() {
    T v{};
    if (in_.size() - at_ < sizeof v) {
      ok_ = false;
      return v;
    }
    std::memcpy(&v, in_.data() + at_, sizeof v);
    at_ += sizeof v;
    return v;
  }
  std::string get_string() {
    const auto n = get<uint32_t>();
    if (!ok_ || in_.size() - at_ < n) {
      ok_ = false;
      return {};
    }
    std::string s(in_.substr(at_, n));
    at_ += n;
    return s;
  }
  bool done() const { return ok_ && at_ == in_.size(); }
  bool ok() const { return ok_; }
  size_t left() const { return in_.size() - at_; }

 private:
  std::string_view in_;
  size_t at_ = 0;
  bool ok_ = true;
};

constexpr uint8_t kStatsRecord = 1;  // version of the stats record

std::string encode_stats(const StoredResult& r) {
  Writer w;
  w.put(kStatsRecord);
  const engine::SolveStats& s = r.stats;
  w.put(static_cast<uint8_t>(s.path));
  w.put(static_cast<uint8_t>(s.factor_cache_hit));
  w.put(static_cast<uint8_t>(s.fast_path_rejected));
  w.put(s.constraint_rows);
  w.put(s.reused_rows);
  w.put(s.cached_rows);
  w.put(s.refinement_steps);
  w.put(s.check_ratio);
  w.put(s.factor_ms);
  w.put(s.forward_fraction);
  w.put(s.solve_ms);
  w.put(static_cast<uint8_t>(r.nonlinear.has_value()));
  if (r.nonlinear) {
    const engine::NonlinearStats& n = *r.nonlinear;
    for (int32_t v : {n.iterations, n.evaluations, n.load_steps, n.krylov_iterations, n.factorizations}) w.put(v);
    for (double v : {n.residual, n.check_ratio, n.strain_energy, n.solve_ms, n.evaluate_ms, n.krylov_ms, n.tangent_ms}) {
      w.put(v);
    }
  }
  return std::move(w.out);
}

bool decode_stats(std::string_view blob, StoredResult& r) {
  Reader in(blob);
  if (in.get<uint8_t>() != kStatsRecord) return false;
  engine::SolveStats& s = r.stats;
  const auto path = in.get<uint8_t>();
  if (path > static_cast<uint8_t>(engine::SolvePath::kFallback)) return false;
  s.path = static_cast<engine::SolvePath>(path);
  s.factor_cache_hit = in.get<uint8_t>() != 0;
  s.fast_path_rejected = in.get<uint8_t>() != 0;
  s.constraint_rows = in.get<int32_t>();
  s.reused_rows = in.get<int32_t>();
  s.cached_rows = in.get<int32_t>();
  s.refinement_steps = in.get<int32_t>();
  s.check_ratio = in.get<double>();
  s.factor_ms = in.get<double>();
  s.forward_fraction = in.get<double>();
  s.solve_ms = in.get<double>();
  if (in.get<uint8_t>() != 0) {
    engine::NonlinearStats n;
    for (int32_t* v : {&n.iterations, &n.evaluations, &n.load_steps, &n.krylov_iterations, &n.factorizations}) {
      *v = in.get<int32_t>();
    }
    for (double* v : {&n.residual, &n.check_ratio, &n.strain_energy, &n.solve_ms, &n.evaluate_ms, &n.krylov_ms,
                      &n.tangent_ms}) {
      *v = in.get<double>();
    }
    r.nonlinear = n;
  }
  return in.done();
}

std::string encode_holds(const HoldVersions& holds) {
  Writer w;
  w.put(static_cast<uint32_t>(holds.size()));
  for (const auto& [id, version] : holds) {
    w.put_string(id);
    w.put(version);
  }
  return std::move(w.out);
}

bool decode_holds(std::string_view blob, HoldVersions& holds) {
  Reader in(blob);
  const auto n = in.get<uint32_t>();
  if (!in.ok() || n > in.left() / (sizeof(uint32_t) + sizeof(uint64_t))) return false;
  holds.reserve(n);
  for (uint32_t k = 0; k < n && in.ok(); ++k) {
    std::string id = in.get_string();
    const auto version = in.get<uint64_t>();
    holds.emplace_back(std::move(id), version);
  }
  return in.done();
}

// A 64-bit checksum of a result's record (SQLite has none for row contents): damage inside a
// record is refused instead of restored as a different result. Eight bytes per step.
class Checksum {
 public:
  void add(std::string_view bytes) {
    size_t k = 0;
    for (; k + 8 <= bytes.size(); k += 8) {
      uint64_t w;
      std::memcpy(&w, bytes.data() + k, 8);
      mix(w);
    }
    uint64_t tail = bytes.size();  // the length too, so that moved boundaries change the sum
    std::memcpy(&tail, bytes.data() + k, bytes.size() - k);
    mix(tail ^ (static_cast<uint64_t>(bytes.size()) << 56));
  }
  void add(int64_t v) { mix(static_cast<uint64_t>(v)); }
  int64_t value() const { return static_cast<int64_t>(h_ ^ (h_ >> 29)); }

 private:
  void mix(uint64_t w) {
    h_ ^= w + 0x9e3779b97f4a7c15ULL + (h_ << 6) + (h_ >> 2);
    h_ *= 0xff51afd7ed558ccdULL;
    h_ ^= h_ >> 33;
  }
  uint64_t h_ = 0x6a09e667f3bcc908ULL;
};

int64_t record_checksum(int64_t res_id, int64_t stored_at, std::string_view positions, std::string_view request,
                        std::string_view stats, const std::string_view* holds) {
  Checksum c;
  c.add(res_id);
  c.add(stored_at);
  c.add(positions);
  c.add(request);
  c.add(stats);
  c.add(holds ? int64_t{1} : int64_t{0});
  if (holds) c.add(*holds);
  return c.value();
}

std::string_view column_bytes(sqlite3_stmt* st, int col) {
  const void* p = sqlite3_column_blob(st, col);
  const int n = sqlite3_column_bytes(st, col);
  return p ? std::string_view(static_cast<const char*>(p), static_cast<size_t>(n)) : std::string_view();
}

// Resets a statement (and its bindings) when the scope ends, whatever happened.
struct Reset {
  sqlite3_stmt* st;
  ~Reset() {
    sqlite3_reset(st);
    sqlite3_clear_bindings(st);
  }
};

}  // namespace

Error PersistentStore::failure(const std::string& what) const {
  const int code = db_ ? sqlite3_extended_errcode(db_) : SQLITE_ERROR;
  const std::string cause = db_ ? sqlite3_errmsg(db_) : "no database";
  const int primary = code & 0xff;
  if (primary == SQLITE_CORRUPT || primary == SQLITE_NOTADB) {
    return Error{ErrorCode::kInvalidArgument, db_path_ + " is damaged or not a softshell store (" + cause + ", " +
                                                  what + "); move it away to start with an empty store, or restore "
                                                  "it from a backup"};
  }
  const ErrorCode ec =
      primary == SQLITE_FULL || primary == SQLITE_IOERR || primary == SQLITE_READONLY || primary == SQLITE_CANTOPEN
          ? ErrorCode::kResourceExhausted
          : ErrorCode::kInternal;
  return Error{ec, "the data directory " + dir_ + " could not be " + what + ": " + cause};
}

Result<void> PersistentStore::exec(const char* sql) {
  char* message = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
    sqlite3_free(message);
    return failure("used");
  }
  return {};
}

Result<std::unique_ptr<PersistentStore>> PersistentStore::open(const std::string& dir) {
  if (dir.empty()) return Error{ErrorCode::kInvalidArgument, "the data directory is empty"};
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir, ec)) {
    return Error{ErrorCode::kInvalidArgument,
                 "the data directory " + dir + " cannot be created or is not a directory" +
                     (ec ? ": " + ec.message() : std::string())};
  }
  std::unique_ptr<PersistentStore> store(new PersistentStore());
  store->dir_ = dir;
  store->db_path_ = (std::filesystem::path(dir) / kDbName).string();

  // The lock: held as long as this object lives (released by the kernel if the process dies).
  const std::string lock_path = (std::filesystem::path(dir) / kLockName).string();
  store->lock_fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (store->lock_fd_ < 0) {
    return Error{ErrorCode::kInvalidArgument, "cannot open " + lock_path + ": " + std::strerror(errno)};
  }
  if (::flock(store->lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char pid[32] = {};
    const ssize_t n = ::pread(store->lock_fd_, pid, sizeof pid - 1, 0);
    const std::string holder = n > 0 ? " (process " + std::string(pid, static_cast<size_t>(n)) + ")" : "";
    if (err == EWOULDBLOCK) {
      return Error{ErrorCode::kUnavailable, "the data directory " + dir + " is in use by another softshell server" +
                                                holder + "; each server needs a directory of its own"};
    }
    return Error{ErrorCode::kInvalidArgument, "cannot lock " + lock_path + ": " + std::strerror(err)};
  }
  const std::string pid = std::to_string(::getpid());
  if (::ftruncate(store->lock_fd_, 0) == 0) {
    [[maybe_unused]] const ssize_t written = ::pwrite(store->lock_fd_, pid.data(), pid.size(), 0);
  }

  if (auto ok = store->init(); !ok) return ok.error();
  return store;
}

Result<void> PersistentStore::init() {
  if (sqlite3_open_v2(db_path_.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                      nullptr) != SQLITE_OK) {
    return failure("opened");
  }
  sqlite3_extended_result_codes(db_, 1);
  // Reading the schema is the first access to the file: a file that is not a database fails here.
  if (auto ok = exec("PRAGMA journal_mode=WAL"); !ok) return ok;
  if (auto ok = exec("PRAGMA synchronous=NORMAL"); !ok) return ok;

  // What is in the file: nothing (a new store), a softshell store, or something else.
  auto scalar = [&](const char* sql, std::string& out) -> bool {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, sql, -1, &st, nullptr) != SQLITE_OK) return false;
    const int rc = sqlite3_step(st);
    const bool ok = rc == SQLITE_ROW || rc == SQLITE_DONE;
    if (rc == SQLITE_ROW && sqlite3_column_text(st, 0)) out = reinterpret_cast<const char*>(sqlite3_column_text(st, 0));
    sqlite3_finalize(st);
    return ok;
  };
  std::string tables;
  if (!scalar("SELECT count(*) FROM sqlite_schema", tables)) return failure("read");
  std::string integrity;
  if (!scalar("PRAGMA quick_check", integrity)) return failure("checked");
  if (integrity != "ok") {
    return Error{ErrorCode::kInvalidArgument, db_path_ + " is damaged (SQLite's check says: " + integrity +
                                                  "); move it away to start with an empty store, or restore it "
                                                  "from a backup"};
  }
  if (tables == "0") {
    const std::string schema =
        "BEGIN;"
        "CREATE TABLE softshell_meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);"
        "INSERT INTO softshell_meta VALUES('application', 'softshell'), ('schema_version', '" +
        std::to_string(kSchemaVersion) +
        "');"
        "CREATE TABLE geometries(seq INTEGER PRIMARY KEY AUTOINCREMENT, id BLOB NOT NULL UNIQUE,"
        " name_space TEXT NOT NULL, geometry TEXT NOT NULL, dropped_through INTEGER NOT NULL DEFAULT 0);"
        "CREATE TABLE results(geom_seq INTEGER NOT NULL, res_id INTEGER NOT NULL, stored_at_ns INTEGER NOT NULL,"
        " positions BLOB NOT NULL, request TEXT NOT NULL, stats BLOB NOT NULL, holds BLOB, checksum INTEGER NOT NULL,"
        " PRIMARY KEY(geom_seq, res_id)) WITHOUT ROWID;" +
        std::string(kDeletedTable) + "COMMIT;";
    if (auto ok = exec(schema.c_str()); !ok) return ok;
  } else {
    std::string application, version;
    const bool has_meta = scalar("SELECT value FROM softshell_meta WHERE key = 'application'", application);
    if (!has_meta || application != "softshell") {
      return Error{ErrorCode::kInvalidArgument,
                   db_path_ + " is an SQLite database but not a softshell store; use another --data-dir"};
    }
    if (!scalar("SELECT value FROM softshell_meta WHERE key = 'schema_version'", version)) return failure("read");
    if (version == "1") {  // the same tables but the deleted geometries' one
      const std::string upgrade = "BEGIN;" + std::string(kDeletedTable) +
                                  "UPDATE softshell_meta SET value = '2' WHERE key = 'schema_version'; COMMIT;";
      if (auto ok = exec(upgrade.c_str()); !ok) {
        (void)exec("ROLLBACK");
        return ok;
      }
      version = "2";
    }
    if (version != std::to_string(kSchemaVersion)) {
      const bool newer = !version.empty() && version.find_first_not_of("0123456789") == std::string::npos &&
                         version.size() < 9 && std::stoi(version) > kSchemaVersion;
      return Error{ErrorCode::kInvalidArgument,
                   db_path_ + (newer ? " was written by a newer softshell (store schema version " + version +
                                           "; this build reads version " + std::to_string(kSchemaVersion) +
                                           "): run that version, or start this one on another --data-dir"
                                     : " has an unknown store schema version '" + version + "' (this build reads " +
                                           std::to_string(kSchemaVersion) + ")")};
    }
  }

  const std::pair<sqlite3_stmt**, const char*> statements[] = {
      {&insert_geometry_, "INSERT INTO geometries(id, name_space, geometry, dropped_through) VALUES(?1, ?2, ?3, ?4)"},
      {&insert_result_,
       "INSERT INTO results(geom_seq, res_id, stored_at_ns, positions, request, stats, holds, checksum) "
       "VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)"},
      {&find_seq_, "SELECT seq FROM geometries WHERE id = ?1"},
      {&delete_results_, "DELETE FROM results WHERE geom_seq = ?1"},
      {&delete_geometry_, "DELETE FROM geometries WHERE seq = ?1"},
      {&drop_results_, "DELETE FROM results WHERE geom_seq = ?1 AND res_id <= ?2"},
      {&set_dropped_, "UPDATE geometries SET dropped_through = max(dropped_through, ?2) WHERE seq = ?1"},
      {&insert_deleted_, "INSERT OR REPLACE INTO deleted_geometries(id, next_res_id, holds) VALUES(?1, ?2, ?3)"},
      // Keeps the newest ?1 rows (by seq); a no-op while there are no more.
      {&prune_deleted_,
       "DELETE FROM deleted_geometries WHERE seq <= (SELECT seq FROM deleted_geometries ORDER BY seq DESC "
       "LIMIT 1 OFFSET ?1)"},
  };
  for (const auto& [st, sql] : statements) {
    if (sqlite3_prepare_v3(db_, sql, -1, SQLITE_PREPARE_PERSISTENT, st, nullptr) != SQLITE_OK) {
      return failure("prepared (is it a softshell store?)");
    }
  }
  return {};
}

PersistentStore::~PersistentStore() {
  for (sqlite3_stmt* st : {insert_geometry_, insert_result_, find_seq_, delete_results_, delete_geometry_,
                           drop_results_, set_dropped_, insert_deleted_, prune_deleted_}) {
    sqlite3_finalize(st);
  }
  if (db_) sqlite3_close(db_);  // checkpoints the WAL into the database
  if (lock_fd_ >= 0) ::close(lock_fd_);  // releases the lock
}

template <class Write>
Result<void> PersistentStore::timed(Write&& write) {
  const auto start = std::chrono::steady_clock::now();
  Result<void> done = write();
  write_seconds_.observe(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  (done ? writes_ : write_failures_).fetch_add(1, std::memory_order_relaxed);
  return done;
}

PersistentStore::WriteStats PersistentStore::write_stats() const {
  return WriteStats{writes_.load(std::memory_order_relaxed), write_failures_.load(std::memory_order_relaxed),
                    write_seconds_.snapshot()};
}

Result<int64_t> PersistentStore::seq_of(const GeomId& id) {
  Reset reset{find_seq_};
  sqlite3_bind_blob(find_seq_, 1, id.bytes.data(), static_cast<int>(id.bytes.size()), SQLITE_STATIC);
  const int rc = sqlite3_step(find_seq_);
  if (rc == SQLITE_ROW) return sqlite3_column_int64(find_seq_, 0);
  if (rc == SQLITE_DONE) return Error{ErrorCode::kNotFound, "geometry " + id.hex() + " is not in the store"};
  return failure("read");
}

Result<void> PersistentStore::save_geometry(const GeomId& id, const Geometry& geometry, uint32_t first_res_id) {
  return timed([&]() -> Result<void> {
    const std::string body = wire::encode_geometry_json(geometry.mesh, geometry.material);
    std::lock_guard lock(mu_);
    Reset reset{insert_geometry_};
    sqlite3_bind_blob(insert_geometry_, 1, id.bytes.data(), static_cast<int>(id.bytes.size()), SQLITE_STATIC);
    sqlite3_bind_text(insert_geometry_, 2, geometry.name_space.data(), static_cast<int>(geometry.name_space.size()),
                      SQLITE_STATIC);
    sqlite3_bind_text(insert_geometry_, 3, body.data(), static_cast<int>(body.size()), SQLITE_STATIC);
    sqlite3_bind_int64(insert_geometry_, 4, first_res_id > 0 ? int64_t{first_res_id} - 1 : 0);
    if (sqlite3_step(insert_geometry_) != SQLITE_DONE) return failure("written (geometry " + id.hex() + ")");
    return {};
  });
}

Result<void> PersistentStore::save_result(const GeomId& id, const StoredResult& result) {
  return timed([&]() -> Result<void> {
    const std::string request = wire::encode_request_json(result.request);
    const std::string stats = encode_stats(result);
    const std::string holds = result.holds ? encode_holds(*result.holds) : std::string();
    const int64_t stored_at =
        std::chrono::duration_cast<std::chrono::nanoseconds>(result.stored_at.time_since_epoch()).count();
    std::lock_guard lock(mu_);
    auto seq = seq_of(id);
    if (!seq) return seq.error();
    Reset reset{insert_result_};
    sqlite3_stmt* st = insert_result_;
    sqlite3_bind_int64(st, 1, *seq);
    sqlite3_bind_int64(st, 2, result.res_id);
    sqlite3_bind_int64(st, 3, stored_at);
    sqlite3_bind_blob64(st, 4, result.positions.data(), result.positions.size() * sizeof(Vec3), SQLITE_STATIC);
    sqlite3_bind_text64(st, 5, request.data(), request.size(), SQLITE_STATIC, SQLITE_UTF8);
    sqlite3_bind_blob(st, 6, stats.data(), static_cast<int>(stats.size()), SQLITE_STATIC);
    if (result.holds) sqlite3_bind_blob64(st, 7, holds.data(), holds.size(), SQLITE_STATIC);
    const std::string_view holds_view(holds);
    const std::string_view positions(reinterpret_cast<const char*>(result.positions.data()),
                                     result.positions.size() * sizeof(Vec3));
    sqlite3_bind_int64(st, 8, record_checksum(result.res_id, stored_at, positions, request, stats,
                                              result.holds ? &holds_view : nullptr));
    if (sqlite3_step(st) != SQLITE_DONE) {
      return failure("written (result " + std::to_string(result.res_id) + " of geometry " + id.hex() + ")");
    }
    return {};
  });
}

Result<void> PersistentStore::delete_geometry(const DeletedGeometry& deleted) {
  return timed([&]() -> Result<void> {
    const GeomId& id = deleted.id;
    const std::string holds = encode_holds(deleted.hold_versions);
    std::lock_guard lock(mu_);
    auto seq = seq_of(id);
    if (!seq && seq.error().code != ErrorCode::kNotFound) return seq.error();
    if (auto ok = exec("BEGIN"); !ok) return ok;
    bool ok = true;
    if (seq) {
      for (sqlite3_stmt* st : {delete_results_, delete_geometry_}) {
        Reset reset{st};
        sqlite3_bind_int64(st, 1, *seq);
        ok = ok && sqlite3_step(st) == SQLITE_DONE;
      }
    }
    if (ok) {
      Reset reset{insert_deleted_};
      sqlite3_bind_blob(insert_deleted_, 1, id.bytes.data(), static_cast<int>(id.bytes.size()), SQLITE_STATIC);
      sqlite3_bind_int64(insert_deleted_, 2, deleted.next_res_id);
      sqlite3_bind_blob(insert_deleted_, 3, holds.data(), static_cast<int>(holds.size()), SQLITE_STATIC);
      ok = sqlite3_step(insert_deleted_) == SQLITE_DONE;
    }
    if (ok) {
      Reset reset{prune_deleted_};
      sqlite3_bind_int64(prune_deleted_, 1, static_cast<int64_t>(kMaxDeletedGeometries));
      ok = sqlite3_step(prune_deleted_) == SQLITE_DONE;
    }
    if (!ok) {
      Error err = failure("written (deleting geometry " + id.hex() + ")");
      (void)exec("ROLLBACK");
      return err;
    }
    return exec("COMMIT");
  });
}

Result<void> PersistentStore::drop_results_through(const GeomId& id, uint32_t res_id) {
  return timed([&]() -> Result<void> {
    std::lock_guard lock(mu_);
    auto seq = seq_of(id);
    if (!seq) return seq.error();
    if (auto ok = exec("BEGIN"); !ok) return ok;
    bool ok = true;
    for (sqlite3_stmt* st : {drop_results_, set_dropped_}) {
      Reset reset{st};
      sqlite3_bind_int64(st, 1, *seq);
      sqlite3_bind_int64(st, 2, res_id);
      ok = ok && sqlite3_step(st) == SQLITE_DONE;
    }
    if (!ok) {
      Error err = failure("written (dropping results of geometry " + id.hex() + ")");
      (void)exec("ROLLBACK");
      return err;
    }
    return exec("COMMIT");
  });
}

Result<std::vector<RestoredGeometry>> PersistentStore::load() {
  std::lock_guard lock(mu_);
  auto damaged = [&](const std::string& what) -> Error {
    return Error{ErrorCode::kInvalidArgument, db_path_ + " is damaged: " + what +
                                                  "; move it away to start with an empty store, or restore it "
                                                  "from a backup"};
  };
  using Statement = std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)>;
  auto prepare = [&](const char* sql) {
    sqlite3_stmt* st = nullptr;
    sqlite3_prepare_v2(db_, sql, -1, &st, nullptr);
    return Statement(st, &sqlite3_finalize);
  };

  std::vector<RestoredGeometry> out;
  std::vector<int64_t> seqs;
  Statement geometries = prepare("SELECT seq, id, name_space, geometry, dropped_through FROM geometries ORDER BY seq");
  if (!geometries) return failure("read");
  sqlite3_stmt* st = geometries.get();
  int rc = 0;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    RestoredGeometry g;
    const std::string_view id = column_bytes(st, 1);
    if (id.size() != g.id.bytes.size()) return damaged("a geometry id is " + std::to_string(id.size()) + " bytes long");
    std::memcpy(g.id.bytes.data(), id.data(), id.size());
    auto decoded = wire::decode_geometry_json(column_bytes(st, 3));
    if (!decoded) return damaged("geometry " + g.id.hex() + " does not decode (" + decoded.error().message + ")");
    g.geometry = std::move(*decoded);
    g.geometry.name_space = std::string(column_bytes(st, 2));
    if (geometry_id(g.geometry.mesh, g.geometry.material, g.geometry.name_space) != g.id) {
      return damaged("geometry " + g.id.hex() + " does not match its content id");
    }
    const int64_t dropped = sqlite3_column_int64(st, 4);
    if (dropped < 0 || dropped > UINT32_MAX) return damaged("geometry " + g.id.hex() + " has a bad result count");
    g.dropped_through = static_cast<uint32_t>(dropped);
    seqs.push_back(sqlite3_column_int64(st, 0));
    out.push_back(std::move(g));
  }
  if (rc != SQLITE_DONE) return failure("read");

  Statement results = prepare(
      "SELECT res_id, stored_at_ns, positions, request, stats, holds, checksum FROM results "
      "WHERE geom_seq = ?1 ORDER BY res_id");
  if (!results) return failure("read");
  st = results.get();
  for (size_t k = 0; k < out.size(); ++k) {
    RestoredGeometry& g = out[k];
    const auto vertices = static_cast<size_t>(g.geometry.mesh.num_vertices());
    sqlite3_reset(st);
    sqlite3_bind_int64(st, 1, seqs[k]);
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
      const int64_t res_id = sqlite3_column_int64(st, 0);
      const std::string what = "result " + std::to_string(res_id) + " of geometry " + g.id.hex();
      if (res_id <= 0 || res_id > UINT32_MAX) return damaged("a result id of geometry " + g.id.hex() + " is out of range");
      const std::string_view positions = column_bytes(st, 2), holds = column_bytes(st, 5);
      const bool has_holds = sqlite3_column_type(st, 5) != SQLITE_NULL;
      if (record_checksum(res_id, sqlite3_column_int64(st, 1), positions, column_bytes(st, 3), column_bytes(st, 4),
                          has_holds ? &holds : nullptr) != sqlite3_column_int64(st, 6)) {
        return damaged(what + " does not match its checksum");
      }
      auto r = std::make_shared<StoredResult>();
      r->res_id = static_cast<uint32_t>(res_id);
      r->stored_at = std::chrono::system_clock::time_point(std::chrono::duration_cast<std::chrono::system_clock::duration>(
          std::chrono::nanoseconds(sqlite3_column_int64(st, 1))));
      if (positions.size() != vertices * sizeof(Vec3)) {
        return damaged(what + " has " + std::to_string(positions.size()) + " bytes of positions, not " +
                       std::to_string(vertices * sizeof(Vec3)));
      }
      r->positions.resize(vertices);
      if (vertices) std::memcpy(static_cast<void*>(r->positions.data()), positions.data(), positions.size());
      for (const Vec3& p : r->positions) {
        if (!p.allFinite()) return damaged(what + " has a non-finite position");
      }
      auto request = wire::decode_request_json(column_bytes(st, 3));
      if (!request) return damaged(what + ": its request does not decode (" + request.error().message + ")");
      r->request = std::move(*request);
      if (!decode_stats(column_bytes(st, 4), *r)) return damaged(what + ": its solve statistics do not decode");
      if (has_holds) {
        HoldVersions versions;
        if (!decode_holds(holds, versions)) return damaged(what + ": its hold versions do not decode");
        r->holds = std::move(versions);
      }
      g.results.push_back(std::move(r));
    }
    if (rc != SQLITE_DONE) return failure("read");
  }
  return out;
}

Result<std::vector<DeletedGeometry>> PersistentStore::load_deleted() {
  std::lock_guard lock(mu_);
  sqlite3_stmt* raw = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT id, next_res_id, holds FROM deleted_geometries ORDER BY seq", -1, &raw,
                         nullptr) != SQLITE_OK) {
    return failure("read");
  }
  std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)> st(raw, &sqlite3_finalize);
  auto damaged = [&](const std::string& what) -> Error {
    return Error{ErrorCode::kInvalidArgument, db_path_ + " is damaged: " + what +
                                                  "; move it away to start with an empty store, or restore it "
                                                  "from a backup"};
  };
  std::vector<DeletedGeometry> out;
  int rc = 0;
  while ((rc = sqlite3_step(raw)) == SQLITE_ROW) {
    DeletedGeometry d;
    const std::string_view id = column_bytes(raw, 0);
    if (id.size() != d.id.bytes.size()) {
      return damaged("a deleted geometry's id is " + std::to_string(id.size()) + " bytes long");
    }
    std::memcpy(d.id.bytes.data(), id.data(), id.size());
    const int64_t next = sqlite3_column_int64(raw, 1);
    if (next < 1 || next > UINT32_MAX) return damaged("deleted geometry " + d.id.hex() + " has a bad next result id");
    d.next_res_id = static_cast<uint32_t>(next);
    if (!decode_holds(column_bytes(raw, 2), d.hold_versions)) {
      return damaged("deleted geometry " + d.id.hex() + ": its hold versions do not decode");
    }
    out.push_back(std::move(d));
  }
  if (rc != SQLITE_DONE) return failure("read");
  return out;
}

size_t PersistentStore::disk_bytes() const {
  size_t bytes = 0;
  for (const char* suffix : {"", "-wal"}) {
    std::error_code ec;
    const auto n = std::filesystem::file_size(db_path_ + suffix, ec);
    if (!ec) bytes += static_cast<size_t>(n);
  }
  return bytes;
}

}  // namespace softshell::service::internal
