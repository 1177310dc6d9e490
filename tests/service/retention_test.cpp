// softshell::service: result retention (the newest N per geometry, a byte budget, dropping the
// oldest when the store is full) and deleting geometries (waiters answered, memory returned,
// ids continued by a new upload). Counts, never times.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "server_test_support.h"
#include "service_test_support.h"
#include "softshell/request_validation.h"
#include "softshell/service/service.h"

namespace softshell::service {
namespace {

using test::small_options;
using test::upload_ready;

using test::exact_grid;
using test::exact_material;
using test::pinned_push;
using std::chrono::milliseconds;

uint32_t deform_ok(Service& s, const GeomId& id, int k) {
  auto r = s.deform(id, pinned_push(k)).get();
  EXPECT_TRUE(r) << r.error().message;
  return r ? (*r)->res_id : 0;
}

// A mesh whose precomputation takes long enough to be caught while it runs.
ControlMesh slow_mesh() { return test::make_grid(48, 48); }

TEST(RetentionTest, KeepsTheNewestWithStableIdsGoneForDroppedNotFoundForNeverStored) {
  ServiceOptions o = small_options(2);
  o.retention.keep_results = 3;
  Service s(o);
  const GeomId id = upload_ready(s);
  std::vector<ResultPtr> seen;
  auto sub = s.subscribe(id, [&](const ResultPtr& r) { seen.push_back(r); });
  ASSERT_TRUE(sub);
  for (int k = 1; k <= 10; ++k) EXPECT_EQ(deform_ok(s, id, k), static_cast<uint32_t>(k));

  EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{8, 9, 10}));
  EXPECT_EQ(s.info(id)->results, 3u);
  for (uint32_t k = 1; k <= 7; ++k) {
    auto gone = s.result(id, k);
    ASSERT_FALSE(gone);
    EXPECT_EQ(gone.error().code, ErrorCode::kGone) << k;
    EXPECT_NE(gone.error().message.find("no longer kept"), std::string::npos) << gone.error().message;
    EXPECT_EQ(s.stresses(id, k, StressQuery{}).error().code, ErrorCode::kGone);
  }
  for (uint32_t k : {0u, 11u, 1000u}) EXPECT_EQ(s.result(id, k).error().code, ErrorCode::kNotFound) << k;
  // What is kept is what was stored under that id.
  for (uint32_t k = 8; k <= 10; ++k) {
    EXPECT_EQ(s.result(id, k).value()->res_id, k);
    EXPECT_EQ(s.result(id, k).value()->positions, seen[k - 1]->positions);
  }
  EXPECT_EQ(s.latest_result(id, 0, milliseconds(0)).value()->res_id, 10u);
  // Subscribers got every id in order, retention or not.
  ASSERT_EQ(seen.size(), 10u);
  for (size_t i = 0; i < seen.size(); ++i) EXPECT_EQ(seen[i]->res_id, i + 1);
  const ServiceStats st = s.stats();
  EXPECT_EQ(st.results, 3u);
  EXPECT_EQ(st.results_dropped, 7u);
}

TEST(RetentionTest, ByteBudgetPerGeometryKeepsAtLeastTheNewest) {
  Service probe(small_options(2));
  const GeomId pid = upload_ready(probe);
  const size_t geometry = probe.stats().store_bytes;
  deform_ok(probe, pid, 1);
  const size_t one = probe.stats().store_bytes - geometry;  // one result's bytes

  ServiceOptions o = small_options(2);
  o.retention.keep_results = 0;  // no count limit
  o.retention.bytes_per_geometry = 4 * one + one / 2;
  Service s(o);
  const GeomId id = upload_ready(s);
  for (int k = 1; k <= 12; ++k) deform_ok(s, id, k);
  EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{9, 10, 11, 12}));
  EXPECT_EQ(s.stats().store_bytes, geometry + 4 * one);

  // A budget below one result still keeps the newest.
  o.retention.bytes_per_geometry = 1;
  Service t(o);
  const GeomId tid = upload_ready(t);
  for (int k = 1; k <= 3; ++k) deform_ok(t, tid, k);
  EXPECT_EQ(t.result_ids(tid).value(), (std::vector<uint32_t>{3}));
}

TEST(RetentionTest, FullStoreDropsTheGeometrysOldestInsteadOfRefusing) {
  // Room for the geometry and three heavy results (their requests make them ~0.6 MB each).
  DeformationRequest heavy = pinned_push(1);
  heavy.forces.assign(20000, PointForce{test::grid_index(4, 2, 2), Vec3(0, 0, -1e-5)});
  Service probe(small_options(2));
  const GeomId pid = upload_ready(probe);
  const size_t geometry_bytes = probe.stats().store_bytes;
  ASSERT_TRUE(probe.deform(pid, heavy).get());
  const size_t result_bytes = probe.stats().store_bytes - geometry_bytes;

  ServiceOptions o = small_options(2);
  o.store_bytes = geometry_bytes + 3 * result_bytes + result_bytes / 2;
  Service s(o);
  const GeomId id = upload_ready(s);
  for (uint32_t k = 1; k <= 10; ++k) {
    auto r = s.deform(id, heavy).get();
    ASSERT_TRUE(r) << k << ": " << r.error().message;
    EXPECT_EQ((*r)->res_id, k);
    EXPECT_LE(s.stats().store_bytes, o.store_bytes);
  }
  EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{8, 9, 10}));
  EXPECT_EQ(s.result(id, 7).error().code, ErrorCode::kGone);
  EXPECT_EQ(s.stats().refused_no_memory, 0u);

  // A result larger than everything droppable is still refused, and the newest stays.
  DeformationRequest huge = pinned_push(1);
  huge.forces.assign(RequestLimits::kMinElementLimit, PointForce{test::grid_index(4, 2, 2), Vec3(0, 0, -1e-6)});  // ~3.3 results
  auto refused = s.deform(id, huge).get();
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kResourceExhausted);
  EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{8, 9, 10}));  // nothing dropped for nothing
  EXPECT_EQ(s.latest_result(id, 0, milliseconds(0)).value()->res_id, 10u);
}

TEST(RetentionTest, ALongRunStaysWithinTheBound) {
  ServiceOptions o = small_options(2);
  o.retention.keep_results = 5;
  Service s(o);
  const GeomId id = upload_ready(s);
  const size_t geometry = s.stats().store_bytes;
  deform_ok(s, id, 1);
  const size_t one = s.stats().store_bytes - geometry;
  size_t peak = 0;
  for (int k = 2; k <= 2000; ++k) {
    deform_ok(s, id, k % 7 + 1);
    peak = std::max(peak, s.stats().store_bytes);
  }
  EXPECT_LE(peak, geometry + 5 * one);
  EXPECT_EQ(s.stats().results, 5u);
  EXPECT_EQ(s.stats().results_dropped, 1995u);
  EXPECT_EQ(s.result_ids(id)->front(), 1996u);
}

TEST(DeleteTest, UnknownGeometryIsNotFound) {
  Service s(small_options(2));
  EXPECT_EQ(s.remove(GeomId{}).error().code, ErrorCode::kNotFound);
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(s.remove(id));
  EXPECT_EQ(s.remove(id).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.info(id).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.result(id, 1).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.deform(id, pinned_push(1)).get().error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.put_hold(id, "h", pinned_push(1)).error().code, ErrorCode::kNotFound);
  EXPECT_TRUE(s.geometries().empty());
  EXPECT_EQ(s.stats().geometries_deleted, 1u);
}

TEST(DeleteTest, ReleasesEveryoneWaitingWithGone) {
  ServiceOptions o = small_options(2);
  o.precompute_jobs = 1;
  Service s(o);
  const size_t empty = s.stats().store_bytes;
  // A precomputing geometry: requests and hold changes wait for it.
  auto slow = s.upload(slow_mesh(), exact_material());
  ASSERT_TRUE(slow);
  const GeomId id = slow->id;
  ASSERT_EQ(s.info(id)->status, GeometryStatus::kPrecomputing);
  auto pending = s.deform(id, pinned_push(1, 48));
  auto hold = s.put_hold(id, "hand", pinned_push(1, 48));
  ASSERT_TRUE(hold) << hold.error().message;
  std::atomic<int> ended{0};
  std::string ended_message;
  auto sub = s.subscribe(id, [](const ResultPtr&) {}, 1, [&](const Error& e) {
    EXPECT_EQ(e.code, ErrorCode::kGone);
    ended_message = e.message;
    ended.fetch_add(1);
  });
  ASSERT_TRUE(sub);
  std::vector<std::thread> waiters;
  std::atomic<int> gone{0};
  for (int i = 0; i < 4; ++i) {
    waiters.emplace_back([&] {
      auto r = s.latest_result(id, 0, milliseconds(60000));
      if (!r && r.error().code == ErrorCode::kGone) gone.fetch_add(1);
    });
  }
  waiters.emplace_back([&] {
    // (kNotFound if it only starts after the delete)
    auto r = s.wait_until_precomputed(id, milliseconds(60000));
    if (!r && (r.error().code == ErrorCode::kGone || r.error().code == ErrorCode::kNotFound)) gone.fetch_add(1);
  });
  while (s.stats().waiters < 4) std::this_thread::yield();

  ASSERT_TRUE(s.remove(id));
  for (auto& t : waiters) t.join();
  EXPECT_EQ(gone.load(), 5);
  auto answer = pending.get();
  ASSERT_FALSE(answer);
  EXPECT_EQ(answer.error().code, ErrorCode::kGone);
  EXPECT_NE(answer.error().message.find("was deleted"), std::string::npos) << answer.error().message;
  ASSERT_EQ(hold->outcome.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  EXPECT_EQ(hold->outcome.get().error().code, ErrorCode::kGone);
  EXPECT_EQ(ended.load(), 1);
  EXPECT_NE(ended_message.find(id.hex()), std::string::npos);
  // The cancelled precomputation gives nothing back to the budget later: what is left is the
  // subscription's follower and the tombstone (a few hundred bytes).
  sub->reset();
  EXPECT_LT(s.stats().store_bytes - empty, size_t{1024});
  const ServiceStats st = s.stats();
  EXPECT_EQ(st.geometries, 0u);
  EXPECT_EQ(st.holds, 0u);
  EXPECT_EQ(st.pending_solves, 0u);
}

TEST(DeleteTest, ReturnsTheMemoryAndAReuploadContinuesTheIds) {
  Service s(small_options(2));
  const size_t empty = s.stats().store_bytes;
  const GeomId id = upload_ready(s);
  for (int k = 1; k <= 3; ++k) deform_ok(s, id, k);
  auto put = s.put_hold(id, "hand", pinned_push(2));
  ASSERT_TRUE(put);
  ASSERT_EQ(put->outcome.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  ASSERT_TRUE(put->outcome.get());  // result 4
  EXPECT_GT(s.stats().cache.entries, 0u);
  ASSERT_GT(s.stats().store_bytes, empty);

  ASSERT_TRUE(s.remove(id));
  EXPECT_LT(s.stats().store_bytes - empty, size_t{1024});  // the tombstone
  EXPECT_EQ(s.stats().results, 0u);
  EXPECT_EQ(s.stats().cache.entries, 0u);  // the factors went with the model

  // The same content again: a new geometry (precomputed again), ids after the deleted ones.
  auto again = s.upload(exact_grid(), exact_material());
  ASSERT_TRUE(again);
  EXPECT_TRUE(again->created);
  EXPECT_EQ(again->id, id);
  ASSERT_EQ(s.wait_until_precomputed(id, milliseconds(30000))->status, GeometryStatus::kReady);
  EXPECT_EQ(s.info(id)->results, 0u);
  EXPECT_TRUE(s.result_ids(id)->empty());
  EXPECT_FALSE(s.latest_result(id, 0, milliseconds(0)).value());
  EXPECT_EQ(s.holds(id)->holds.size(), 0u);
  EXPECT_EQ(deform_ok(s, id, 5), 5u);
  auto old = s.result(id, 2);
  ASSERT_FALSE(old);
  EXPECT_EQ(old.error().code, ErrorCode::kGone);
  EXPECT_NE(old.error().message.find("earlier upload"), std::string::npos) << old.error().message;
  EXPECT_EQ(s.result(id, 6).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{5}));
  // A client that had result 4 of the old upload sees the new one as newer.
  EXPECT_EQ(s.latest_result(id, 4, milliseconds(0)).value()->res_id, 5u);
  // Hold versions continue too.
  auto put2 = s.put_hold(id, "hand", pinned_push(3));
  ASSERT_TRUE(put2);
  EXPECT_EQ(put2->version, 2u);
  ASSERT_EQ(put2->outcome.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  EXPECT_EQ(put2->outcome.get().value().result->res_id, 6u);
}

TEST(DeleteTest, ASolveRunningDuringTheDeleteIsDiscarded) {
  // Many solves queued on one worker; the delete comes while they run: each is answered (a
  // result stored before the delete, or kGone/kNotFound after it), none is stored afterwards.
  ServiceOptions o = small_options(2);
  o.solve_threads = 1;
  Service s(o);
  const size_t empty = s.stats().store_bytes;
  const GeomId id = upload_ready(s, exact_grid(16));
  std::vector<std::future<Result<ResultPtr>>> futures;
  for (int k = 1; k <= 40; ++k) futures.push_back(s.deform(id, pinned_push(k, 16)));
  ASSERT_TRUE(futures.front().get());  // at least one solved before the delete
  ASSERT_TRUE(s.remove(id));
  int ok = 1, gone = 0;
  for (size_t i = 1; i < futures.size(); ++i) {
    auto r = futures[i].get();
    if (r) ++ok;
    else if (r.error().code == ErrorCode::kGone) ++gone;
    else ADD_FAILURE() << r.error().message;
  }
  EXPECT_EQ(ok + gone, 40);
  EXPECT_LT(s.stats().store_bytes - empty, size_t{1024});
  EXPECT_EQ(s.stats().cache.entries, 0u);
}

}  // namespace
}  // namespace softshell::service
