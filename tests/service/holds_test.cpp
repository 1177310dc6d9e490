// Holds (PROTOCOL.md version 2) in softshell::service, without HTTP: the hold state, versions,
// renewals, 409/422, releases and the unsolvable state, leases, the coalescing solver loop,
// exactness of the combined solve, the shared history, subscriptions, memory and shutdown.
// (One file of ~600 lines: one case per behaviour of the holds API, sharing the helpers above them.)
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <map>
#include <set>
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
using test::grid_index;
using std::chrono::milliseconds;

DeformationRequest pins(int n = 4) {
  DeformationRequest r;
  r.vertex_constraints = test::pinned_corners(n);
  return r;
}

DeformationRequest push(double fz, int n = 4) {
  DeformationRequest r;
  r.forces.push_back({grid_index(n, n / 2, n / 2), Vec3(0.0, 0.0, fz)});
  return r;
}

DeformationRequest lift(int index, double dz) {
  DeformationRequest r;
  r.vertex_constraints.push_back({index, kAxisZ, Vec3(0.0, 0.0, dz)});
  return r;
}

DeformationRequest grab(SurfacePoint p, Vec3 d) {
  DeformationRequest r;
  r.limit_constraints.push_back({p, d, std::nullopt, std::nullopt});
  return r;
}

// The outcome of a change (fails the test if it does not come within 30 s).
Result<HoldOutcome> outcome(const HoldTicket& t) {
  if (t.outcome.wait_for(std::chrono::seconds(30)) != std::future_status::ready) {
    ADD_FAILURE() << "hold " << t.hold_id << " version " << t.version << " was not answered";
    return Error{ErrorCode::kUnavailable, "timeout"};
  }
  return t.outcome.get();
}

// PUT and wait for its result.
ResultPtr put(Service& s, const GeomId& id, const std::string& hold, DeformationRequest r, HoldOptions o = {}) {
  auto t = s.put_hold(id, hold, std::move(r), o);
  EXPECT_TRUE(t) << t.error().message;
  if (!t) return nullptr;
  auto out = outcome(*t);
  EXPECT_TRUE(out) << out.error().message;
  return out ? out->result : nullptr;
}

uint64_t version_in(const StoredResult& r, const std::string& hold) {
  return r.holds ? version_of(*r.holds, hold) : 0;
}

TEST(HoldsTest, HoldStateIsTheSolveOfAllHoldsTogether) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  const ResultPtr first = put(s, id, "pins", pins());
  ASSERT_TRUE(first);
  EXPECT_EQ(first->res_id, 1u);
  ASSERT_TRUE(first->holds);
  EXPECT_EQ(*first->holds, (HoldVersions{{"pins", 1}}));
  for (size_t i = 0; i < first->positions.size(); ++i) {
    EXPECT_EQ(first->positions[i], exact_grid().positions()[i]);  // pinned and unloaded: at rest
  }

  const ResultPtr both = put(s, id, "push", push(-0.25));
  ASSERT_TRUE(both);
  EXPECT_EQ(both->res_id, 2u);
  EXPECT_EQ(*both->holds, (HoldVersions{{"pins", 1}, {"push", 1}}));
  // The same as one request with both contributions, solved alone.
  auto alone = s.deform(id, test::pinned_push(1)).get();
  ASSERT_TRUE(alone) << alone.error().message;
  EXPECT_FALSE((*alone)->holds);
  ASSERT_EQ(both->positions.size(), (*alone)->positions.size());
  double moved = 0.0;
  for (size_t i = 0; i < both->positions.size(); ++i) {
    EXPECT_LT((both->positions[i] - (*alone)->positions[i]).norm(), 1e-12);
    moved = std::max(moved, (both->positions[i] - exact_grid().positions()[i]).norm());
  }
  EXPECT_GT(moved, 1e-3);
  // Loads add up: two pushes of -0.125 are one of -0.25.
  ASSERT_TRUE(put(s, id, "push", push(-0.125)));
  const ResultPtr halves = put(s, id, "push2", push(-0.125));
  ASSERT_TRUE(halves);
  for (size_t i = 0; i < halves->positions.size(); ++i) {
    EXPECT_LT((halves->positions[i] - both->positions[i]).norm(), 1e-12);
  }
  // The stored request is the hold state as one request.
  EXPECT_EQ(halves->request.vertex_constraints.size(), 4u);
  EXPECT_EQ(halves->request.forces.size(), 2u);
}

TEST(HoldsTest, RenewalKeepsTheVersionAndStoresNothing) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  const ResultPtr r = put(s, id, "push", push(-0.25));
  ASSERT_TRUE(r);
  const auto before = s.stats();
  auto again = s.put_hold(id, "push", push(-0.25), {std::chrono::seconds(120)});
  ASSERT_TRUE(again);
  EXPECT_TRUE(again->renewal);
  EXPECT_EQ(again->version, 1u);
  auto o = outcome(*again);
  ASSERT_TRUE(o);
  EXPECT_EQ(o->result, r);  // answered at once with the newest hold-state result
  EXPECT_EQ(s.result_ids(id)->size(), 2u);
  EXPECT_EQ(s.stats().hold_solves, before.hold_solves);
  EXPECT_EQ(s.stats().hold_renewals, before.hold_renewals + 1);
  // The lease was renewed with the new ttl.
  auto list = s.holds(id);
  ASSERT_TRUE(list);
  ASSERT_EQ(list->holds.size(), 2u);
  EXPECT_EQ(list->holds[1].hold_id, "push");
  EXPECT_GT(list->holds[1].expires_in, 100.0);
  EXPECT_LE(list->holds[0].expires_in, 10.0);
  // Another body is a new version.
  auto changed = s.put_hold(id, "push", push(-0.5));
  ASSERT_TRUE(changed);
  EXPECT_FALSE(changed->renewal);
  EXPECT_EQ(changed->version, 2u);
  auto o2 = outcome(*changed);
  ASSERT_TRUE(o2 && o2->result);
  EXPECT_EQ(version_in(*o2->result, "push"), 2u);
  EXPECT_EQ(o2->result->res_id, 3u);
}

TEST(HoldsTest, ListAndReadShowNewestVersionsAndState) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  auto empty = s.holds(id);
  ASSERT_TRUE(empty);
  EXPECT_TRUE(empty->holds.empty());
  EXPECT_EQ(empty->res_id, 0u);
  EXPECT_EQ(empty->state, HoldStateStatus::kSolved);
  ASSERT_TRUE(put(s, id, "pins", pins(), {std::chrono::seconds(30)}));
  ASSERT_TRUE(put(s, id, "b-hand", push(-0.1)));
  ASSERT_TRUE(put(s, id, "b-hand", push(-0.2)));
  auto list = s.holds(id);
  ASSERT_TRUE(list);
  ASSERT_EQ(list->holds.size(), 2u);
  EXPECT_EQ(list->holds[0].hold_id, "b-hand");  // sorted by id
  EXPECT_EQ(list->holds[0].version, 2u);
  EXPECT_EQ(list->holds[1].hold_id, "pins");
  EXPECT_EQ(list->holds[1].version, 1u);
  EXPECT_GT(list->holds[1].expires_in, 20.0);
  EXPECT_LE(list->holds[1].expires_in, 30.0);
  EXPECT_EQ(list->res_id, 3u);
  EXPECT_EQ(list->state, HoldStateStatus::kSolved);
  auto one = s.hold(id, "b-hand");
  ASSERT_TRUE(one);
  EXPECT_EQ(one->info.version, 2u);
  ASSERT_EQ(one->request.forces.size(), 1u);
  EXPECT_EQ(one->request.forces[0].force.z(), -0.2);
  EXPECT_EQ(s.hold(id, "nobody").error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.hold(id, "bad id").error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.holds(GeomId{}).error().code, ErrorCode::kNotFound);
}

TEST(HoldsTest, BadChangesAreRefusedAtOnce) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  auto code = [](const Result<HoldTicket>& r) { return r ? ErrorCode::kOk : r.error().code; };
  EXPECT_EQ(code(s.put_hold(id, "", pins())), ErrorCode::kInvalidArgument);
  EXPECT_EQ(code(s.put_hold(id, std::string(65, 'a'), pins())), ErrorCode::kInvalidArgument);
  EXPECT_EQ(code(s.put_hold(id, "a/b", pins())), ErrorCode::kInvalidArgument);
  EXPECT_EQ(code(s.put_hold(id, std::string(64, 'a'), pins())), ErrorCode::kOk);
  EXPECT_EQ(code(s.put_hold(id, "x", pins(), {milliseconds(0)})), ErrorCode::kInvalidArgument);
  EXPECT_EQ(code(s.put_hold(id, "x", pins(), {std::chrono::seconds(601)})), ErrorCode::kInvalidArgument);
  EXPECT_EQ(code(s.put_hold(id, "x", lift(25, 0.0))), ErrorCode::kInvalidArgument);  // index out of range
  EXPECT_EQ(code(s.put_hold(id, "x", grab({99, 0, 0.5, 0.5}, Vec3::Zero()))), ErrorCode::kInvalidArgument);
  EXPECT_EQ(code(s.put_hold(GeomId{}, "x", pins())), ErrorCode::kNotFound);
  EXPECT_EQ(code(s.release_hold(id, "nobody")), ErrorCode::kNotFound);
  EXPECT_FALSE(s.hold(id, "x"));  // nothing was created by the refusals
}

TEST(HoldsTest, ContradictingHoldIsAConflictNamingTheOthersAndKeepsItsContents) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  const int corner = grid_index(4, 0, 0);
  // A new hold that lifts a pinned corner: 409 naming "pins"; it is not created.
  auto t = s.put_hold(id, "lifter", lift(corner, 0.1));
  ASSERT_TRUE(t);
  auto o = outcome(*t);
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::kConflict);
  EXPECT_NE(o.error().message.find("'pins'"), std::string::npos) << o.error().message;
  EXPECT_NE(o.error().message.find("not created"), std::string::npos) << o.error().message;
  EXPECT_EQ(s.hold(id, "lifter").error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.result_ids(id)->size(), 1u);  // nothing stored for a refused change

  // An existing hold whose new version contradicts another keeps its previous contents.
  ASSERT_TRUE(put(s, id, "mid", lift(grid_index(4, 2, 2), 0.05)));
  auto bad = s.put_hold(id, "mid", [&] {
    DeformationRequest r = lift(grid_index(4, 2, 2), 0.05);
    r.vertex_constraints.push_back({corner, kAxisZ, Vec3(0, 0, -0.2)});
    return r;
  }());
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->version, 2u);
  auto ob = outcome(*bad);
  ASSERT_FALSE(ob);
  EXPECT_EQ(ob.error().code, ErrorCode::kConflict);
  EXPECT_NE(ob.error().message.find("keeps its previous contents (version 1)"), std::string::npos) << ob.error().message;
  auto kept = s.hold(id, "mid");
  ASSERT_TRUE(kept);
  EXPECT_EQ(kept->info.version, 1u);
  EXPECT_EQ(kept->request.vertex_constraints.size(), 1u);
  // The refused version number is not reused.
  auto next = s.put_hold(id, "mid", lift(grid_index(4, 2, 2), 0.06));
  ASSERT_TRUE(next);
  EXPECT_EQ(next->version, 3u);
  ASSERT_TRUE(outcome(*next));
}

TEST(HoldsTest, ConflictAmongSeveralHoldsNamesASmallestSet) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  const int a = grid_index(4, 1, 2), b = grid_index(4, 3, 2);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  ASSERT_TRUE(put(s, id, "left", lift(a, 0.1)));
  ASSERT_TRUE(put(s, id, "right", lift(b, 0.1)));
  // u_a,z - u_b,z = 0.05 contradicts "left" and "right" together, neither alone, and not "pins".
  DeformationRequest tie;
  tie.lagrange_constraints.push_back({{a, b}, {Vec3(0, 0, 1), Vec3(0, 0, -1)}, Vec3(0, 0, 0.05)});
  auto t = s.put_hold(id, "tie", tie);
  ASSERT_TRUE(t);
  auto o = outcome(*t);
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::kConflict) << o.error().message;
  EXPECT_NE(o.error().message.find("'left'"), std::string::npos) << o.error().message;
  EXPECT_NE(o.error().message.find("'right'"), std::string::npos) << o.error().message;
  EXPECT_EQ(o.error().message.find("'pins'"), std::string::npos) << o.error().message;
  // The consistent version of the same tie is accepted (the refused version 1 is not reused).
  tie.lagrange_constraints[0].values = Vec3::Zero();
  const ResultPtr r = put(s, id, "tie", tie);
  ASSERT_TRUE(r);
  EXPECT_EQ(version_in(*r, "tie"), 2u);
}

TEST(HoldsTest, UndeterminedOrSelfContradictingHoldIsUnprocessable) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  // A load alone leaves the object free.
  auto t = s.put_hold(id, "push", push(-0.25));
  ASSERT_TRUE(t);
  auto o = outcome(*t);
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(o.error().message.find("rigid-body motion"), std::string::npos) << o.error().message;
  EXPECT_FALSE(s.hold(id, "push"));
  // A refused first hold changes nothing: no result (not even the rest shape) is stored.
  EXPECT_TRUE(s.result_ids(id).value().empty());
  EXPECT_EQ(s.holds(id).value().res_id, 0u);
  // Constraints of one hold that cannot hold together.
  ASSERT_TRUE(put(s, id, "pins", pins()));
  DeformationRequest self = lift(grid_index(4, 2, 2), 0.1);
  self.vertex_constraints.push_back({grid_index(4, 2, 2), kAxisZ, Vec3(0, 0, 0.2)});
  auto t2 = s.put_hold(id, "self", self);
  ASSERT_TRUE(t2);
  auto o2 = outcome(*t2);
  ASSERT_FALSE(o2);
  EXPECT_EQ(o2.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(o2.error().message.find("contradicts itself"), std::string::npos) << o2.error().message;
  EXPECT_EQ(s.stats().hold_rejections, 2u);
}

TEST(HoldsTest, ReleaseThatLeavesTheRestUnsolvableIsAConflictUntilFixed) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  ASSERT_TRUE(put(s, id, "push", push(-0.25)));
  auto t = s.release_hold(id, "pins");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->version, 1u);
  auto o = outcome(*t);
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::kConflict);
  EXPECT_NE(o.error().message.find("released"), std::string::npos) << o.error().message;
  EXPECT_EQ(s.hold(id, "pins").error().code, ErrorCode::kNotFound);  // released all the same
  EXPECT_EQ(s.result_ids(id)->size(), 2u);                            // no result stored
  auto list = s.holds(id);
  ASSERT_TRUE(list);
  EXPECT_EQ(list->state, HoldStateStatus::kUnsolvable);
  EXPECT_NE(list->message.find("rigid-body motion"), std::string::npos) << list->message;
  EXPECT_EQ(list->res_id, 2u);
  EXPECT_EQ(s.stats().hold_states_unsolvable, 1u);
  // A change that does not fix it is refused (422); renewing the remaining hold gives no result.
  auto still = s.put_hold(id, "push", push(-0.5));
  ASSERT_TRUE(still);
  EXPECT_EQ(outcome(*still).error().code, ErrorCode::kUnprocessable);
  auto renew = s.put_hold(id, "push", push(-0.25));
  ASSERT_TRUE(renew && renew->renewal);
  auto ro = outcome(*renew);
  ASSERT_TRUE(ro);
  EXPECT_FALSE(ro->result);
  // Pinning again makes it solvable.
  const ResultPtr fixed = put(s, id, "pins", pins());
  ASSERT_TRUE(fixed);
  EXPECT_EQ(fixed->res_id, 3u);
  // (An id used again continues its versions.)
  EXPECT_EQ(*fixed->holds, (HoldVersions{{"pins", 2}, {"push", 1}}));
  EXPECT_EQ(s.holds(id)->state, HoldStateStatus::kSolved);
  EXPECT_EQ(s.holds(id)->message, "");
}

TEST(HoldsTest, LastReleaseStoresTheRestShape) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  ASSERT_TRUE(put(s, id, "push", push(-0.25)));
  auto t1 = s.release_hold(id, "push");
  ASSERT_TRUE(t1);
  auto o1 = outcome(*t1);
  ASSERT_TRUE(o1 && o1->result);
  EXPECT_EQ(*o1->result->holds, (HoldVersions{{"pins", 1}}));
  auto t2 = s.release_hold(id, "pins");
  ASSERT_TRUE(t2);
  auto o2 = outcome(*t2);
  ASSERT_TRUE(o2 && o2->result) << (o2 ? "" : o2.error().message);
  EXPECT_EQ(o2->result->res_id, 4u);
  ASSERT_TRUE(o2->result->holds);
  EXPECT_TRUE(o2->result->holds->empty());
  EXPECT_EQ(o2->result->positions, exact_grid().positions());
  EXPECT_TRUE(s.holds(id)->holds.empty());
}

TEST(HoldsTest, LapsedLeaseReleasesTheHoldAndTheObjectIsSolvedAgain) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins(), {std::chrono::seconds(60)}));
  ASSERT_TRUE(put(s, id, "push", push(-0.25), {milliseconds(200)}));
  const auto start = std::chrono::steady_clock::now();
  // Waits for the next result (the lease's release) without polling the clock.
  auto next = s.latest_result(id, 2, milliseconds(10000));
  ASSERT_TRUE(next && *next);
  EXPECT_GE(test::seconds_since(start), 0.15);
  EXPECT_EQ((*next)->res_id, 3u);
  EXPECT_EQ(*(*next)->holds, (HoldVersions{{"pins", 1}}));
  EXPECT_EQ((*next)->positions, exact_grid().positions());
  EXPECT_FALSE(s.hold(id, "push"));
  EXPECT_EQ(s.stats().leases_expired, 1u);
  // A renewed lease does not lapse.
  ASSERT_TRUE(put(s, id, "push", push(-0.25), {milliseconds(300)}));
  for (int i = 0; i < 6; ++i) {
    std::this_thread::sleep_for(milliseconds(100));
    auto renew = s.put_hold(id, "push", push(-0.25), {milliseconds(300)});
    ASSERT_TRUE(renew && renew->renewal);
  }
  EXPECT_TRUE(s.hold(id, "push"));
  EXPECT_EQ(s.stats().leases_expired, 1u);
}

TEST(HoldsTest, ChangesMadeDuringOneSolveAreMergedIntoTheNext) {
  // Changes made while the geometry precomputes all wait for the first solve: one solve takes
  // them all (a refused one among them included) and answers every accepted one.
  Service s(small_options());
  const ControlMesh mesh = test::make_grid(48, 48);
  auto up = s.upload(mesh, exact_material());
  ASSERT_TRUE(up);
  std::vector<HoldTicket> tickets;
  auto add = [&](const std::string& hold, DeformationRequest r) {
    auto t = s.put_hold(up->id, hold, std::move(r));
    ASSERT_TRUE(t) << t.error().message;
    tickets.push_back(*t);
  };
  add("pins", pins(48));
  for (int k = 0; k < 6; ++k) add("hand-" + std::to_string(k), lift(grid_index(48, 8 + 5 * k, 24), 0.01 * (k + 1)));
  add("hand-0", lift(grid_index(48, 8, 24), 0.05));                 // newer version of hand-0
  add("bad", lift(grid_index(48, 0, 0), 0.1));                      // contradicts "pins"
  ASSERT_EQ(s.info(up->id)->status, GeometryStatus::kPrecomputing)  // (else the test proves nothing)
      << "the precomputation finished before the changes were made";
  for (size_t i = 0; i + 1 < tickets.size(); ++i) {
    auto o = outcome(tickets[i]);
    ASSERT_TRUE(o) << tickets[i].hold_id << ": " << o.error().message;
    ASSERT_TRUE(o->result);
    EXPECT_EQ(o->result->res_id, 1u);
    EXPECT_GE(version_in(*o->result, tickets[i].hold_id), tickets[i].version);
  }
  EXPECT_EQ(outcome(tickets.back()).error().code, ErrorCode::kConflict);
  const auto stats = s.stats();
  EXPECT_EQ(stats.hold_solves, 1u);
  // hand-0's first version was still queued when its second came: replaced, not solved.
  EXPECT_EQ(stats.hold_changes_superseded, 1u);
  EXPECT_EQ(stats.hold_changes_solved, tickets.size() - 1);
  EXPECT_EQ(s.result_ids(up->id)->size(), 1u);
  auto r = s.result(up->id, 1);
  ASSERT_TRUE(r);
  EXPECT_EQ(version_in(**r, "hand-0"), 2u);
  EXPECT_EQ(version_in(**r, "bad"), 0u);
  EXPECT_EQ((*r)->holds->size(), 7u);
}

// A client that PUTs faster than the solves (here: while the geometry precomputes) never grows
// the queue: each PUT replaces its hold's queued change, every PUT is answered by the one result,
// which includes the newest version, and the versions superseded take no memory.
TEST(HoldsTest, QueuedChangesOfOneHoldAreReplacedNotQueued) {
  Service s(small_options());
  const ControlMesh mesh = test::make_grid(48, 48);
  auto up = s.upload(mesh, exact_material());
  ASSERT_TRUE(up);
  std::vector<HoldTicket> tickets;
  auto add = [&](const std::string& hold, DeformationRequest r) {
    auto t = s.put_hold(up->id, hold, std::move(r));
    ASSERT_TRUE(t) << t.error().message;
    tickets.push_back(*t);
  };
  add("pins", pins(48));
  constexpr int kPuts = 200;
  for (int k = 1; k <= kPuts; ++k) add("hand", lift(grid_index(48, 24, 24), 1e-4 * k));
  ASSERT_EQ(s.info(up->id)->status, GeometryStatus::kPrecomputing)  // (else the test proves nothing)
      << "the precomputation finished before the changes were made";
  EXPECT_EQ(s.stats().hold_changes_pending, 2u);  // one per hold, not 201
  for (const auto& t : tickets) {
    auto o = outcome(t);
    ASSERT_TRUE(o) << t.hold_id << " v" << t.version << ": " << o.error().message;
    ASSERT_TRUE(o->result);
    EXPECT_EQ(o->result->res_id, 1u);
    EXPECT_EQ(version_in(*o->result, "hand"), static_cast<uint64_t>(kPuts));
  }
  const auto stats = s.stats();
  EXPECT_EQ(stats.hold_changes_superseded, static_cast<uint64_t>(kPuts - 1));
  EXPECT_EQ(stats.hold_changes_solved, 2u);
  EXPECT_EQ(stats.hold_solves, 1u);
  // The newest version is the one in force.
  auto r = s.result(up->id, 1);
  ASSERT_TRUE(r);
  EXPECT_NEAR((**r).positions[static_cast<size_t>(grid_index(48, 24, 24))].z() - mesh.positions()[static_cast<size_t>(grid_index(48, 24, 24))].z(),
              1e-4 * kPuts, 1e-12);
}

TEST(HoldsTest, ConcurrentClientsEachGetTheirVersionAndTheNewestHasAll) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  constexpr int kClients = 8, kEach = 15;
  std::vector<uint64_t> last(kClients, 0);
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int c = 0; c < kClients; ++c) {
    threads.emplace_back([&, c] {
      const std::string hold = "client-" + std::to_string(c);
      for (int k = 1; k <= kEach; ++k) {
        DeformationRequest r;
        r.forces.push_back({grid_index(4, 1 + c % 3, 1 + c / 3), Vec3(0, 0, -0.01 * k)});
        auto t = s.put_hold(id, hold, r);
        if (!t) {
          failures.fetch_add(1);
          continue;
        }
        auto o = outcome(*t);
        if (!o || !o->result || version_in(*o->result, hold) < t->version) {
          failures.fetch_add(1);
          ADD_FAILURE() << hold << " version " << t->version << " answered without it";
          continue;
        }
        last[static_cast<size_t>(c)] = t->version;
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  const auto ids = s.result_ids(id).value();
  for (size_t i = 0; i < ids.size(); ++i) EXPECT_EQ(ids[i], i + 1);  // contiguous
  const auto newest = s.result(id, ids.back()).value();
  for (int c = 0; c < kClients; ++c) {
    EXPECT_EQ(version_in(*newest, "client-" + std::to_string(c)), last[static_cast<size_t>(c)]);
  }
  EXPECT_EQ(s.stats().hold_changes_solved, static_cast<uint64_t>(1 + kClients * kEach));
}

TEST(HoldsTest, HoldStateMeetsEveryHoldsConstraintsExactly) {
  Service s(small_options());
  const ControlMesh mesh = test::make_grid(8, 8);
  const GeomId id = upload_ready(s, mesh);
  auto evaluator = LimitEvaluator::create(mesh).value();
  const SurfacePoint pa{18, 0, 0.3, 0.6}, pb{45, 0, 0.7, 0.2};
  const Vec3 da(0.0, 0.0, 0.02), db(0.0, 0.01, -0.015);
  ASSERT_TRUE(put(s, id, "pins", pins(8)));
  ASSERT_TRUE(put(s, id, "hand-a", grab(pa, da)));
  ASSERT_TRUE(put(s, id, "hand-b", grab(pb, db)));
  const ResultPtr r = put(s, id, "load", push(-0.3, 8));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->holds->size(), 4u);
  const auto rest = mesh.positions();
  auto moved = [&](const SurfacePoint& p) -> Vec3 {
    return test::limit_point(evaluator, r->positions, p) - test::limit_point(evaluator, rest, p);
  };
  EXPECT_LT((moved(pa) - da).norm(), 1e-10);
  EXPECT_LT((moved(pb) - db).norm(), 1e-10);
  for (const auto& c : test::pinned_corners(8)) {
    EXPECT_EQ(r->positions[static_cast<size_t>(c.index)], rest[static_cast<size_t>(c.index)]);
  }
}

TEST(HoldsTest, HoldResultsAndDeformResultsShareOneHistory) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  ASSERT_TRUE(s.deform(id, test::pinned_push(2)).get());
  ASSERT_TRUE(put(s, id, "push", push(-0.25)));
  ASSERT_TRUE(s.deform(id, test::pinned_push(3)).get());
  const auto ids = s.result_ids(id).value();
  EXPECT_EQ(ids, (std::vector<uint32_t>{1, 2, 3, 4}));
  EXPECT_TRUE(s.result(id, 1).value()->holds);
  EXPECT_FALSE(s.result(id, 2).value()->holds);
  EXPECT_TRUE(s.result(id, 3).value()->holds);
  EXPECT_FALSE(s.result(id, 4).value()->holds);
  // The hold list names the newest hold-state result, not the newest result.
  EXPECT_EQ(s.holds(id)->res_id, 3u);
}

TEST(HoldsTest, SubscriptionsSeeEveryResultInOrderAndCountAgainstTheBudget) {
  ServiceOptions o = small_options();
  o.follower_bytes = 1 << 20;
  Service s(o);
  const GeomId id = upload_ready(s);
  std::mutex mu;
  std::vector<uint32_t> seen;
  const size_t before = s.stats().store_bytes;
  auto sub = s.subscribe(id, [&](const ResultPtr& r) {
    std::lock_guard lock(mu);
    seen.push_back(r->res_id);
  }, 3);
  ASSERT_TRUE(sub) << sub.error().message;
  EXPECT_EQ(s.stats().followers, 3u);
  EXPECT_EQ(s.stats().store_bytes, before + 3 * o.follower_bytes);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  ASSERT_TRUE(s.deform(id, test::pinned_push(1)).get());
  ASSERT_TRUE(put(s, id, "push", push(-0.25)));
  {
    std::lock_guard lock(mu);
    EXPECT_EQ(seen, (std::vector<uint32_t>{1, 2, 3}));
  }
  const size_t with = s.stats().store_bytes;
  ASSERT_TRUE((*sub)->set_followers(1));
  EXPECT_EQ(s.stats().store_bytes, with - 2 * o.follower_bytes);
  sub->reset();
  EXPECT_EQ(s.stats().followers, 0u);
  EXPECT_EQ(s.stats().store_bytes, with - 3 * o.follower_bytes);
  ASSERT_TRUE(s.deform(id, test::pinned_push(2)).get());
  {
    std::lock_guard lock(mu);
    EXPECT_EQ(seen.size(), 3u);  // no call after the subscription ended
  }
  // Followers that do not fit are refused.
  ServiceOptions tight = small_options();
  tight.follower_bytes = size_t{300} << 20;
  Service t(tight);
  const GeomId tid = upload_ready(t);
  auto refused = t.subscribe(tid, [](const ResultPtr&) {});
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kResourceExhausted);
  EXPECT_EQ(t.subscribe(GeomId{}, [](const ResultPtr&) {}).error().code, ErrorCode::kNotFound);
}

TEST(HoldsTest, HoldsCountAgainstTheMemoryBudget) {
  Service s(small_options());
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  const size_t before = s.stats().store_bytes;
  DeformationRequest big = push(-1e-6);
  big.forces.assign(50000, PointForce{grid_index(4, 2, 2), Vec3(0, 0, -1e-6)});
  auto t = s.put_hold(id, "big", big);
  ASSERT_TRUE(t);
  ASSERT_TRUE(outcome(*t));
  const size_t with = s.stats().store_bytes;
  EXPECT_GT(with, before + 50000 * sizeof(PointForce));  // the hold, and the result's request
  const size_t result_bytes = s.result(id, 2).value()->request.forces.size() * sizeof(PointForce);
  auto r = s.release_hold(id, "big");
  ASSERT_TRUE(r);
  ASSERT_TRUE(outcome(*r));
  // The hold's own bytes are returned; the stored results keep theirs.
  EXPECT_LT(s.stats().store_bytes, with);
  EXPECT_GT(s.stats().store_bytes, before + result_bytes);

  ServiceOptions tight = small_options();
  Service probe(tight);
  const GeomId pid = upload_ready(probe);
  tight.store_bytes = probe.stats().store_bytes + (size_t{1} << 20);
  Service small(tight);
  const GeomId sid = upload_ready(small);
  big.forces.assign(RequestLimits::kMinElementLimit, PointForce{grid_index(4, 2, 2), Vec3(0, 0, -1e-6)});
  auto refused = small.put_hold(sid, "big", big);  // 2 MiB of forces
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kResourceExhausted);
  EXPECT_FALSE(small.hold(sid, "big"));
  (void)pid;
}

// The number of live holds per geometry is bounded (each solve combines all of them): one more
// new hold is a conflict that says so, while the holds there keep changing and a release makes room.
TEST(HoldsTest, LiveHoldsPerGeometryAreBounded) {
  ServiceOptions o = small_options();
  o.max_holds_per_geometry = 3;
  Service s(o);
  const GeomId id = upload_ready(s);
  ASSERT_TRUE(put(s, id, "pins", pins()));
  ASSERT_TRUE(put(s, id, "push-a", push(-0.25)));
  ASSERT_TRUE(put(s, id, "push-b", push(-0.5)));
  auto refused = s.put_hold(id, "push-c", push(-0.75));
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kConflict);
  EXPECT_NE(refused.error().message.find("already has 3 live holds"), std::string::npos) << refused.error().message;
  EXPECT_NE(refused.error().message.find("'push-c' was not created"), std::string::npos) << refused.error().message;
  EXPECT_FALSE(s.hold(id, "push-c"));
  EXPECT_EQ(s.holds(id).value().holds.size(), 3u);
  // An existing hold still changes.
  const ResultPtr changed = put(s, id, "push-b", push(-1.0));
  ASSERT_TRUE(changed);
  EXPECT_EQ(version_in(*changed, "push-b"), 2u);
  // A release makes room for a new one.
  auto released = s.release_hold(id, "push-a");
  ASSERT_TRUE(released);
  ASSERT_TRUE(outcome(*released));
  const ResultPtr added = put(s, id, "push-c", push(-0.75));
  ASSERT_TRUE(added);
  EXPECT_EQ(*added->holds, (HoldVersions{{"pins", 1}, {"push-b", 2}, {"push-c", 1}}));
}

TEST(HoldsTest, ShutdownAnswersChangesThatWait) {
  auto s = std::make_unique<Service>(small_options());
  auto up = s->upload(test::make_grid(48, 48), exact_material());
  ASSERT_TRUE(up);
  auto t = s->put_hold(up->id, "pins", pins(48));
  ASSERT_TRUE(t);
  s->shutdown();
  auto o = outcome(*t);
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::kUnavailable);
  EXPECT_EQ(s->put_hold(up->id, "pins", pins(48)).error().code, ErrorCode::kUnavailable);
  EXPECT_EQ(s->release_hold(up->id, "pins").error().code, ErrorCode::kUnavailable);
  s.reset();  // and destruction with holds and their leases still there
}

TEST(HoldsTest, HoldCreatedAndReleasedBeforeItsSolveLeavesNoTrace) {
  Service s(small_options());
  auto up = s.upload(test::make_grid(48, 48), exact_material());
  ASSERT_TRUE(up);
  auto pin = s.put_hold(up->id, "pins", pins(48));
  auto brief = s.put_hold(up->id, "brief", push(-0.1, 48));
  ASSERT_TRUE(pin && brief);
  auto gone = s.release_hold(up->id, "brief");
  ASSERT_TRUE(gone);
  auto op = outcome(*pin), ob = outcome(*brief), og = outcome(*gone);
  ASSERT_TRUE(op && ob && og);
  ASSERT_TRUE(op->result);
  EXPECT_EQ(op->result, og->result);
  EXPECT_EQ(*op->result->holds, (HoldVersions{{"pins", 1}}));
  EXPECT_EQ(s.result_ids(up->id)->size(), 1u);
}

}  // namespace
}  // namespace softshell::service
