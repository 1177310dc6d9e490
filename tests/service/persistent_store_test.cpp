// The persistent store (ServiceOptions::data_dir): PersistentStore on its own (round trips,
// deletion and retention hooks, refusals of damaged and foreign files, the directory lock) and a
// Service restored from a directory. (Over 600 lines: the store's tests and the service's tests on
// a directory share its fixtures, the geometry and full-result builders and the field-by-field
// comparison.)
#include "persistent_store.h"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/resource.h>

#include <cstring>
#include <filesystem>
#include <fstream>

#include "server_test_support.h"
#include "temp_dir.h"
#include "softshell/content_id.h"
#include "softshell/service/service.h"
#include "softshell/wire.h"

namespace softshell::service {
namespace {

using internal::PersistentStore;
using internal::RestoredGeometry;
using test::exact_grid;
using test::exact_material;
using test::pinned_push;
namespace fs = std::filesystem;

using test::TempDir;

// The store's database file in `dir`.
std::string db_of(const TempDir& dir) { return (fs::path(dir.path) / "softshell.db").string(); }

Geometry grid_geometry(std::string ns = "") {
  ControlMesh mesh = exact_grid();
  mesh.creases().push_back({0, 1, 2.5});  // tags must come back too
  return Geometry{std::move(mesh), exact_material(), std::move(ns)};
}

GeomId id_of(const Geometry& g) { return geometry_id(g.mesh, g.material, g.name_space); }

// A result with every field set to something that is not its default.
StoredResult full_result(uint32_t res_id, int vertices) {
  StoredResult r;
  r.res_id = res_id;
  for (int i = 0; i < vertices; ++i) r.positions.emplace_back(0.1 * i + 1.0 / 3.0, -i * 1e-300, 1e300 / (i + 1));
  r.request = pinned_push(static_cast<int>(res_id));
  r.request.lagrange_constraints.push_back({{1, 2}, {Vec3(1, 0, 0), Vec3(-1, 0, 0)}, Vec3(0.125, 0, 0)});
  r.request.surface_forces.push_back({{0, 0, 0.5, 0.25}, Vec3(0, 0, 1.0 / 7.0)});
  r.request.pressure = 2.0 / 3.0;
  r.stats.path = engine::SolvePath::kFallback;
  r.stats.factor_cache_hit = true;
  r.stats.constraint_rows = 7;
  r.stats.reused_rows = 3;
  r.stats.cached_rows = 4;
  r.stats.fast_path_rejected = true;
  r.stats.check_ratio = 0.1;
  r.stats.factor_ms = 1.5;
  r.stats.refinement_steps = 2;
  r.stats.forward_fraction = 0.3;
  r.stats.solve_ms = 2.5;
  if (res_id % 2 == 0) {
    engine::NonlinearStats n;
    n.iterations = 5;
    n.evaluations = 6;
    n.load_steps = 2;
    n.krylov_iterations = 40;
    n.factorizations = 3;
    n.residual = 1e-9;
    n.check_ratio = 0.5;
    n.strain_energy = 12.25;
    n.solve_ms = 9;
    n.evaluate_ms = 1;
    n.krylov_ms = 2;
    n.tangent_ms = 3;
    r.nonlinear = n;
    r.request.model = DeformationModel::kNonlinear;
  } else {
    r.holds = HoldVersions{{"left hand", 3}, {"right", 12}};
  }
  r.stored_at = std::chrono::system_clock::time_point(std::chrono::system_clock::duration(1764651234567890123 / 1000 * 1000));
  return r;
}

void expect_same(const StoredResult& a, const StoredResult& b) {
  EXPECT_EQ(a.res_id, b.res_id);
  ASSERT_EQ(a.positions.size(), b.positions.size());
  for (size_t i = 0; i < a.positions.size(); ++i) EXPECT_EQ(a.positions[i], b.positions[i]) << i;  // bit for bit
  EXPECT_EQ(wire::encode_request_json(a.request), wire::encode_request_json(b.request));
  EXPECT_EQ(wire::encode_result_json(a.to_result()), wire::encode_result_json(b.to_result()));
  EXPECT_EQ(a.stats.path, b.stats.path);
  EXPECT_EQ(a.stats.factor_cache_hit, b.stats.factor_cache_hit);
  EXPECT_EQ(a.stats.constraint_rows, b.stats.constraint_rows);
  EXPECT_EQ(a.stats.reused_rows, b.stats.reused_rows);
  EXPECT_EQ(a.stats.cached_rows, b.stats.cached_rows);
  EXPECT_EQ(a.stats.fast_path_rejected, b.stats.fast_path_rejected);
  EXPECT_EQ(a.stats.check_ratio, b.stats.check_ratio);
  EXPECT_EQ(a.stats.factor_ms, b.stats.factor_ms);
  EXPECT_EQ(a.stats.refinement_steps, b.stats.refinement_steps);
  EXPECT_EQ(a.stats.forward_fraction, b.stats.forward_fraction);
  EXPECT_EQ(a.stats.solve_ms, b.stats.solve_ms);
  ASSERT_EQ(a.nonlinear.has_value(), b.nonlinear.has_value());
  if (a.nonlinear) {
    EXPECT_EQ(a.nonlinear->iterations, b.nonlinear->iterations);
    EXPECT_EQ(a.nonlinear->evaluations, b.nonlinear->evaluations);
    EXPECT_EQ(a.nonlinear->load_steps, b.nonlinear->load_steps);
    EXPECT_EQ(a.nonlinear->krylov_iterations, b.nonlinear->krylov_iterations);
    EXPECT_EQ(a.nonlinear->factorizations, b.nonlinear->factorizations);
    EXPECT_EQ(a.nonlinear->residual, b.nonlinear->residual);
    EXPECT_EQ(a.nonlinear->check_ratio, b.nonlinear->check_ratio);
    EXPECT_EQ(a.nonlinear->strain_energy, b.nonlinear->strain_energy);
    EXPECT_EQ(a.nonlinear->solve_ms, b.nonlinear->solve_ms);
    EXPECT_EQ(a.nonlinear->evaluate_ms, b.nonlinear->evaluate_ms);
    EXPECT_EQ(a.nonlinear->krylov_ms, b.nonlinear->krylov_ms);
    EXPECT_EQ(a.nonlinear->tangent_ms, b.nonlinear->tangent_ms);
  }
  EXPECT_EQ(a.holds, b.holds);
  EXPECT_EQ(a.stored_at, b.stored_at);
}

std::unique_ptr<PersistentStore> open_ok(const std::string& dir) {
  auto s = PersistentStore::open(dir);
  EXPECT_TRUE(s) << s.error().message;
  return s ? std::move(*s) : nullptr;
}

TEST(PersistentStoreTest, RestoresGeometriesAndResultsFieldByField) {
  TempDir dir("softshell-store");
  const Geometry a = grid_geometry("team a"), b = grid_geometry("team b");
  const int nv = a.mesh.num_vertices();
  std::vector<StoredResult> saved;
  {
    auto store = open_ok(dir.path);
    ASSERT_TRUE(store);
    ASSERT_TRUE(store->save_geometry(id_of(a), a));
    ASSERT_TRUE(store->save_geometry(id_of(b), b));
    for (uint32_t k = 1; k <= 4; ++k) {
      saved.push_back(full_result(k, nv));
      ASSERT_TRUE(store->save_result(id_of(a), saved.back()));
    }
    EXPECT_FALSE(store->save_result(id_of(a), saved.back())) << "a result id is stored once";
    const Geometry unknown = grid_geometry("nobody");
    EXPECT_EQ(store->save_result(id_of(unknown), saved.back()).error().code, ErrorCode::kNotFound);
  }
  auto store = open_ok(dir.path);
  ASSERT_TRUE(store);
  auto loaded = store->load();
  ASSERT_TRUE(loaded) << loaded.error().message;
  ASSERT_EQ(loaded->size(), 2u);
  EXPECT_EQ((*loaded)[0].id, id_of(a));  // upload order
  EXPECT_EQ((*loaded)[1].id, id_of(b));
  EXPECT_EQ((*loaded)[0].geometry.name_space, "team a");
  EXPECT_EQ(wire::encode_geometry_json((*loaded)[0].geometry.mesh, (*loaded)[0].geometry.material),
            wire::encode_geometry_json(a.mesh, a.material));
  EXPECT_EQ((*loaded)[0].geometry.mesh.creases().size(), 1u);
  EXPECT_TRUE((*loaded)[1].results.empty());
  ASSERT_EQ((*loaded)[0].results.size(), saved.size());
  for (size_t k = 0; k < saved.size(); ++k) expect_same(saved[k], *(*loaded)[0].results[k]);
}

TEST(PersistentStoreTest, DeleteAndDropKeepIdsGoingForward) {
  TempDir dir("softshell-store");
  const Geometry a = grid_geometry("a"), b = grid_geometry("b");
  const int nv = a.mesh.num_vertices();
  {
    auto store = open_ok(dir.path);
    ASSERT_TRUE(store->save_geometry(id_of(a), a));
    ASSERT_TRUE(store->save_geometry(id_of(b), b));
    for (uint32_t k = 1; k <= 5; ++k) {
      ASSERT_TRUE(store->save_result(id_of(a), full_result(k, nv)));
      ASSERT_TRUE(store->save_result(id_of(b), full_result(k, nv)));
    }
    ASSERT_TRUE(store->drop_results_through(id_of(a), 3));
    ASSERT_TRUE(store->drop_results_through(id_of(a), 2));  // never goes back
    ASSERT_TRUE(store->drop_results_through(id_of(b), 5));  // every result dropped
    EXPECT_EQ(store->drop_results_through(id_of(grid_geometry("c")), 1).error().code, ErrorCode::kNotFound);
  }
  {
    auto store = open_ok(dir.path);
    auto loaded = store->load().value();
    ASSERT_EQ(loaded.size(), 2u);
    EXPECT_EQ(loaded[0].dropped_through, 3u);
    ASSERT_EQ(loaded[0].results.size(), 2u);
    EXPECT_EQ(loaded[0].results[0]->res_id, 4u);
    EXPECT_EQ(loaded[0].results[1]->res_id, 5u);
    EXPECT_EQ(loaded[1].dropped_through, 5u);
    EXPECT_TRUE(loaded[1].results.empty());

    ASSERT_TRUE(store->delete_geometry({id_of(a), 6, {}}));
    ASSERT_TRUE(store->delete_geometry({id_of(a), 6, {}}));  // already gone: only its record again
    ASSERT_TRUE(store->save_geometry(id_of(a), a));  // the id is reusable, its history starts afresh
    ASSERT_TRUE(store->save_result(id_of(a), full_result(1, nv)));
  }
  auto loaded = open_ok(dir.path)->load().value();
  ASSERT_EQ(loaded.size(), 2u);
  EXPECT_EQ(loaded[0].id, id_of(b));  // a was uploaded again after b
  EXPECT_EQ(loaded[1].id, id_of(a));
  EXPECT_EQ(loaded[1].dropped_through, 0u);
  ASSERT_EQ(loaded[1].results.size(), 1u);
  EXPECT_EQ(loaded[1].results[0]->res_id, 1u);
}

// A delete's record (next result id, hold versions) is in the store once the call returns and
// comes back at load_deleted; an upload continuing it starts after its ids; the newest
// kMaxDeletedGeometries records are kept, a deleted id again moves to the newest.
TEST(PersistentStoreTest, RemembersDeletedGeometriesBounded) {
  TempDir dir("softshell-store");
  const Geometry a = grid_geometry("a");
  const int nv = a.mesh.num_vertices();
  const HoldVersions holds{{"grab", 4}, {"pin", 2}};
  {
    auto store = open_ok(dir.path);
    ASSERT_TRUE(store->save_geometry(id_of(a), a));
    for (uint32_t k = 1; k <= 3; ++k) ASSERT_TRUE(store->save_result(id_of(a), full_result(k, nv)));
    ASSERT_TRUE(store->delete_geometry({id_of(a), 4, holds}));
  }
  {
    auto store = open_ok(dir.path);
    EXPECT_TRUE(store->load().value().empty());
    const auto deleted = store->load_deleted().value();
    ASSERT_EQ(deleted.size(), 1u);
    EXPECT_EQ(deleted[0].id, id_of(a));
    EXPECT_EQ(deleted[0].next_res_id, 4u);
    EXPECT_EQ(deleted[0].hold_versions, holds);
    // Uploaded again: results 1..3 count as dropped, 4 follows.
    ASSERT_TRUE(store->save_geometry(id_of(a), a, 4));
    ASSERT_TRUE(store->save_result(id_of(a), full_result(4, nv)));
  }
  {
    auto store = open_ok(dir.path);
    const auto loaded = store->load().value();
    ASSERT_EQ(loaded.size(), 1u);
    EXPECT_EQ(loaded[0].dropped_through, 3u);
    ASSERT_EQ(loaded[0].results.size(), 1u);
    EXPECT_EQ(loaded[0].results[0]->res_id, 4u);
    EXPECT_EQ(store->load_deleted().value().size(), 1u);  // kept: the new upload's life began there

    // The bound: one more than it keeps, then `a` again (it moves to the newest).
    constexpr size_t kMax = PersistentStore::kMaxDeletedGeometries;
    std::vector<GeomId> ids(kMax + 1);
    for (size_t k = 0; k < ids.size(); ++k) {
      std::memcpy(ids[k].bytes.data(), &k, sizeof k);
      ASSERT_TRUE(store->delete_geometry({ids[k], static_cast<uint32_t>(k + 2), {}}));
    }
    ASSERT_TRUE(store->delete_geometry({id_of(a), 5, {}}));
    const auto deleted = store->load_deleted().value();
    ASSERT_EQ(deleted.size(), kMax);
    EXPECT_EQ(deleted.front().id, ids[2]);  // ids[0], and a's old record, were the oldest
    EXPECT_EQ(deleted.front().next_res_id, 4u);
    EXPECT_EQ(deleted[kMax - 2].id, ids[kMax]);
    EXPECT_EQ(deleted.back().id, id_of(a));
    EXPECT_EQ(deleted.back().next_res_id, 5u);
    EXPECT_TRUE(store->load().value().empty());
  }
}

// A store of schema version 1 (before deleted geometries were kept) opens and is upgraded.
TEST(PersistentStoreTest, UpgradesAVersion1Store) {
  TempDir dir("softshell-store");
  const Geometry a = grid_geometry();
  {
    auto store = open_ok(dir.path);
    ASSERT_TRUE(store->save_geometry(id_of(a), a));
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(db_of(dir).c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db,
                         "DROP TABLE deleted_geometries;"
                         "UPDATE softshell_meta SET value = '1' WHERE key = 'schema_version'",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  {
    auto store = open_ok(dir.path);
    EXPECT_EQ(store->load().value().size(), 1u);
    EXPECT_TRUE(store->load_deleted().value().empty());
    ASSERT_TRUE(store->delete_geometry({id_of(a), 1, {}}));
  }
  auto store = open_ok(dir.path);
  EXPECT_EQ(store->load_deleted().value().size(), 1u);
}

TEST(PersistentStoreTest, ADirectoryIsHeldByOneStoreAtATime) {
  TempDir dir("softshell-store");
  auto first = open_ok(dir.path);
  auto second = PersistentStore::open(dir.path);
  ASSERT_FALSE(second);
  EXPECT_EQ(second.error().code, ErrorCode::kUnavailable);
  EXPECT_NE(second.error().message.find("in use by another softshell server (process " + std::to_string(getpid())),
            std::string::npos)
      << second.error().message;
  first.reset();
  EXPECT_TRUE(open_ok(dir.path));  // released with the store
}

TEST(PersistentStoreTest, CreatesAMissingDirectoryAndRefusesAFile) {
  TempDir dir("softshell-store");
  const std::string nested = dir.path + "/a/b";
  EXPECT_TRUE(open_ok(nested));
  std::ofstream(dir.path + "/file") << "x";
  auto refused = PersistentStore::open(dir.path + "/file");
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("is not a directory"), std::string::npos) << refused.error().message;
}

void expect_refused(const TempDir& dir, const std::string& says) {
  auto refused = PersistentStore::open(dir.path);
  if (refused) {
    auto loaded = (*refused)->load();  // damage in a record shows when it is read
    ASSERT_FALSE(loaded) << "a damaged store was accepted";
    EXPECT_NE(loaded.error().message.find(says), std::string::npos) << loaded.error().message;
    return;
  }
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument) << refused.error().message;
  EXPECT_NE(refused.error().message.find(says), std::string::npos) << refused.error().message;
  EXPECT_NE(refused.error().message.find(db_of(dir)), std::string::npos) << "names the file";
}

TEST(PersistentStoreTest, RefusesAFileThatIsNotADatabase) {
  TempDir dir("softshell-store");
  std::ofstream(db_of(dir)) << std::string(8192, 'x');
  expect_refused(dir, "not a softshell store");
}

TEST(PersistentStoreTest, RefusesAnotherApplicationsDatabase) {
  TempDir dir("softshell-store");
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(db_of(dir).c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "CREATE TABLE notes(text TEXT); INSERT INTO notes VALUES('hi');", nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  expect_refused(dir, "is an SQLite database but not a softshell store");
}

TEST(PersistentStoreTest, RefusesANewerOrUnknownSchema) {
  TempDir dir("softshell-store");
  open_ok(dir.path).reset();
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(db_of(dir).c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE softshell_meta SET value = '3' WHERE key = 'schema_version'", nullptr, nullptr,
                         nullptr),
            SQLITE_OK);
  expect_refused(dir, "was written by a newer softshell (store schema version 3; this build reads version 2)");
  ASSERT_EQ(sqlite3_exec(db, "UPDATE softshell_meta SET value = 'x' WHERE key = 'schema_version'", nullptr, nullptr,
                         nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  expect_refused(dir, "unknown store schema version 'x'");
}

// Damage at every part of a store file: the open or the load is refused with a message, or (damage
// in slack space) everything loads exactly as saved; never a different result, never a crash.
TEST(PersistentStoreTest, RefusesADamagedFileWherever) {
  TempDir dir("softshell-store");
  const Geometry a = grid_geometry();
  std::vector<StoredResult> saved;
  {
    auto store = open_ok(dir.path);
    ASSERT_TRUE(store->save_geometry(id_of(a), a));
    for (uint32_t k = 1; k <= 40; ++k) {
      saved.push_back(full_result(k, a.mesh.num_vertices()));
      ASSERT_TRUE(store->save_result(id_of(a), saved.back()));
    }
  }  // closed: the WAL is checkpointed into the database
  ASSERT_FALSE(fs::exists(db_of(dir) + "-wal"));
  std::string original(static_cast<size_t>(fs::file_size(db_of(dir))), '\0');
  {
    std::ifstream in(db_of(dir), std::ios::binary);
    in.read(original.data(), static_cast<std::streamsize>(original.size()));
  }
  ASSERT_GT(original.size(), 8192u);
  int refused = 0, places = 0;
  for (size_t at = 0; at < original.size(); at += 4096 / 4 + 13) {
    std::string damaged = original;
    for (size_t k = at; k < std::min(damaged.size(), at + 64); ++k) damaged[k] = static_cast<char>(damaged[k] ^ 0x5a);
    std::ofstream(db_of(dir), std::ios::binary | std::ios::trunc) << damaged;
    ++places;
    auto store = PersistentStore::open(dir.path);
    if (!store) {
      EXPECT_FALSE(store.error().message.empty());
      ++refused;
      continue;
    }
    auto loaded = (*store)->load();
    if (!loaded) {
      EXPECT_NE(loaded.error().message.find(db_of(dir)), std::string::npos) << loaded.error().message;
      ++refused;
      continue;
    }
    // Accepted: then the damage hit slack (free space inside pages), and everything is as saved.
    ASSERT_EQ(loaded->size(), 1u) << "damage at byte " << at;
    ASSERT_EQ((*loaded)[0].results.size(), saved.size()) << "damage at byte " << at;
    for (size_t k = 0; k < saved.size(); ++k) expect_same(saved[k], *(*loaded)[0].results[k]);
  }
  std::cout << "[ damage ] " << refused << " of " << places << " damaged places refused, the rest hit slack\n";
  EXPECT_GT(refused, places / 10) << refused << " of " << places;  // the records are damaged often enough
}

// What a write costs (printed, not asserted: the machine is shared): results the size of
// spot_quadrangulated's (2,930 control points, about 70 KB each).
TEST(PersistentStoreTest, WriteCostPerResult) {
  TempDir dir("softshell-store");
  Geometry g{test::make_grid(53, 54), exact_material(), ""};  // 2,970 control points
  const GeomId id = id_of(g);
  auto store = open_ok(dir.path);
  ASSERT_TRUE(store->save_geometry(id, g));
  constexpr uint32_t kResults = 200;
  std::vector<StoredResult> results;
  for (uint32_t k = 1; k <= kResults; ++k) results.push_back(full_result(k, g.mesh.num_vertices()));
  const auto start = std::chrono::steady_clock::now();
  for (const StoredResult& r : results) ASSERT_TRUE(store->save_result(id, r));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "[ write ] " << g.mesh.num_vertices() << " control points: " << 1e6 * seconds / kResults
            << " us per result, " << store->disk_bytes() / kResults << " bytes on disk per result\n";
  auto loaded = store->load().value();
  ASSERT_EQ(loaded.at(0).results.size(), kResults);
  expect_same(results.back(), *loaded[0].results.back());
}

// --- the service on a data directory ------------------------------------------------------------

ServiceOptions on(const TempDir& dir) {
  ServiceOptions o;
  o.precompute_threads = 1;
  o.solve_threads = 2;
  o.store_bytes = size_t{256} << 20;
  o.cache_bytes = size_t{64} << 20;
  o.data_dir = dir.path;
  return o;
}

TEST(PersistentServiceTest, RestoresGeometriesAndHistoriesAndContinuesIds) {
  TempDir dir("softshell-store");
  GeomId id, other;
  std::vector<std::string> bodies;
  {
    Service s(on(dir));
    id = s.upload(exact_grid(), exact_material(), "ns").value().id;
    other = s.upload(exact_grid(8), exact_material()).value().id;
    for (int k = 1; k <= 5; ++k) {
      auto r = s.deform(id, pinned_push(k)).get();
      ASSERT_TRUE(r) << r.error().message;
      EXPECT_EQ((*r)->res_id, static_cast<uint32_t>(k));
      bodies.push_back(wire::encode_result_json((*r)->to_result()) + wire::encode_request_json((*r)->request));
    }
    EXPECT_TRUE(Service::create(on(dir)).error().message.find("in use by another softshell server") !=
                std::string::npos);
  }
  Service s(on(dir));
  const auto list = s.geometries();
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].id, id);
  EXPECT_EQ(list[0].name_space, "ns");
  EXPECT_EQ(list[0].results, 5u);
  EXPECT_EQ(list[1].id, other);
  EXPECT_EQ(s.result_ids(id).value().size(), 5u);
  for (uint32_t k = 1; k <= 5; ++k) {
    const ResultPtr r = s.result(id, k).value();
    EXPECT_EQ(wire::encode_result_json(r->to_result()) + wire::encode_request_json(r->request), bodies[k - 1]);
  }
  EXPECT_EQ(s.latest_result(id, 0, std::chrono::milliseconds(0)).value()->res_id, 5u);
  // Precomputed again in the background; the next result continues the ids.
  auto next = s.deform(id, pinned_push(6)).get();
  ASSERT_TRUE(next) << next.error().message;
  EXPECT_EQ((*next)->res_id, 6u);
  EXPECT_EQ(s.wait_until_precomputed(other, std::chrono::milliseconds(30000)).value().status, GeometryStatus::kReady);
  // Stresses of a restored result need the rebuilt model: they are served.
  EXPECT_TRUE(s.stresses(id, 2, StressQuery{1, {}, 0.0}));
  EXPECT_EQ(s.stats().results, 6u);
}

// Retention and delete reach the data directory: results retention dropped stay dropped (410)
// after a restart and the kept ones come back; a deleted geometry does not come back.
TEST(PersistentServiceTest, RetentionAndDeletesSurviveARestart) {
  TempDir dir("softshell-store");
  ServiceOptions o = on(dir);
  o.retention.keep_results = 3;
  GeomId kept, deleted;
  {
    Service s(o);
    kept = s.upload(exact_grid(), exact_material()).value().id;
    deleted = s.upload(exact_grid(5), exact_material()).value().id;
    for (int k = 1; k <= 7; ++k) ASSERT_TRUE(s.deform(kept, pinned_push(k)).get());
    ASSERT_TRUE(s.deform(deleted, pinned_push(1, 5)).get());
    ASSERT_TRUE(s.remove(deleted));
  }
  Service s(o);
  const auto list = s.geometries();
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0].id, kept);
  EXPECT_EQ(s.result_ids(kept).value(), (std::vector<uint32_t>{5, 6, 7}));
  EXPECT_EQ(s.result(kept, 4).error().code, ErrorCode::kGone);
  EXPECT_EQ(s.result(kept, 8).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.result(kept, 6).value()->res_id, 6u);
  auto next = s.deform(kept, pinned_push(1)).get();
  ASSERT_TRUE(next) << next.error().message;
  EXPECT_EQ((*next)->res_id, 8u);
  EXPECT_EQ(s.result_ids(kept).value(), (std::vector<uint32_t>{6, 7, 8}));
  EXPECT_EQ(s.info(deleted).error().code, ErrorCode::kNotFound);
}

// A deleted geometry's continuation survives a restart: uploaded again on the restarted service,
// its ids (and hold versions) continue after the deleted upload's, whose ids are kGone; and after
// a second restart, with the new upload restored, still so.
TEST(PersistentServiceTest, IdsOfADeletedGeometryContinueAfterARestart) {
  TempDir dir("softshell-store");
  GeomId id;
  {
    Service s(on(dir));
    id = s.upload(exact_grid(), exact_material()).value().id;
    for (int k = 1; k <= 2; ++k) ASSERT_TRUE(s.deform(id, pinned_push(k)).get());
    auto held = s.put_hold(id, "push", pinned_push(3));  // result 3, and version 1 of "push"
    ASSERT_TRUE(held) << held.error().message;
    EXPECT_EQ(held->version, 1u);
    ASSERT_TRUE(held->outcome.get());
    ASSERT_TRUE(s.remove(id));
  }
  {
    Service s(on(dir));
    EXPECT_EQ(s.info(id).error().code, ErrorCode::kNotFound);
    ASSERT_TRUE(s.upload(exact_grid(), exact_material()).value().created);
    auto r = s.deform(id, pinned_push(4)).get();
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_EQ((*r)->res_id, 4u);
    auto held = s.put_hold(id, "push", pinned_push(3));
    ASSERT_TRUE(held) << held.error().message;
    EXPECT_EQ(held->version, 2u);
    ASSERT_TRUE(held->outcome.get());  // result 5
    ASSERT_TRUE(s.release_hold(id, "push").value().outcome.get());  // result 6
    EXPECT_EQ(s.result(id, 3).error().code, ErrorCode::kGone);
    EXPECT_NE(s.result(id, 3).error().message.find("earlier upload of it that was deleted"), std::string::npos);
  }
  {
    Service s(on(dir));
    EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{4, 5, 6}));
    EXPECT_NE(s.result(id, 2).error().message.find("earlier upload of it that was deleted"), std::string::npos);
    auto held = s.put_hold(id, "push", pinned_push(3));  // the deleted life's version 1 is not reused
    ASSERT_TRUE(held) << held.error().message;
    EXPECT_EQ(held->version, 3u);
    ASSERT_TRUE(held->outcome.get());  // result 7
    ASSERT_TRUE(s.remove(id));  // a second delete replaces the first's record
  }
  Service s(on(dir));
  ASSERT_TRUE(s.upload(exact_grid(), exact_material()));
  auto r = s.deform(id, pinned_push(6)).get();
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ((*r)->res_id, 8u);
  EXPECT_EQ(s.put_hold(id, "push", pinned_push(3)).value().version, 4u);
}

TEST(PersistentServiceTest, RefusesToStartWhenTheStoreDoesNotFitTheBudget) {
  TempDir dir("softshell-store");
  {
    Service s(on(dir));
    const GeomId id = s.upload(exact_grid(8), exact_material()).value().id;
    for (int k = 1; k <= 20; ++k) ASSERT_TRUE(s.deform(id, pinned_push(k, 8)).get());
  }
  ServiceOptions small = on(dir);
  small.store_bytes = 4096;
  auto refused = Service::create(small);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kResourceExhausted);
  EXPECT_NE(refused.error().message.find("holds 1 geometries and 20 results"), std::string::npos)
      << refused.error().message;
  EXPECT_NE(refused.error().message.find("--store-mb"), std::string::npos);
  // Nothing was lost by the refusal.
  Service s(on(dir));
  EXPECT_EQ(s.geometries().at(0).results, 20u);
}

// A write that fails (here: the file size limit, as a full disk would) answers 507 naming the
// data directory, keeps nothing and uses up no id; once the disk has room again ids continue.
TEST(PersistentServiceTest, AFailedWriteIsA507AndUsesUpNoId) {
  TempDir dir("softshell-store");
  Service s(on(dir));
  const GeomId id = s.upload(exact_grid(), exact_material()).value().id;
  ASSERT_TRUE(s.deform(id, pinned_push(1)).get());
  ASSERT_TRUE(s.deform(id, pinned_push(2)).get());

  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  const auto old_handler = signal(SIGXFSZ, SIG_IGN);  // write() fails with EFBIG instead
  rlimit full = saved;
  full.rlim_cur = static_cast<rlim_t>(fs::file_size(db_of(dir) + "-wal"));
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &full), 0);
  auto refused = s.deform(id, pinned_push(3)).get();
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &saved), 0);
  signal(SIGXFSZ, old_handler);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kResourceExhausted);  // 507
  EXPECT_NE(refused.error().message.find("the data directory " + dir.path + " could not be written"),
            std::string::npos)
      << refused.error().message;
  EXPECT_EQ(s.result_ids(id).value().size(), 2u);

  auto next = s.deform(id, pinned_push(4)).get();
  ASSERT_TRUE(next) << next.error().message;
  EXPECT_EQ((*next)->res_id, 3u);
}

TEST(PersistentServiceTest, WithoutADataDirectoryNothingIsWritten) {
  TempDir dir("softshell-store");
  {
    ServiceOptions o = on(dir);
    o.data_dir.clear();
    Service s(o);
    ASSERT_TRUE(s.upload(exact_grid(), exact_material()));
  }
  EXPECT_TRUE(fs::is_empty(dir.path));
}

}  // namespace
}  // namespace softshell::service
