// Holds over real sockets (PROTOCOL.md version 2): PUT/DELETE/GET in both body formats, 202,
// renewals, 400/404/405/409/415/422, the unsolvable state, leases, 8 concurrent clients and the
// exactness of their combined hold state, and nonlinear holds.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <thread>

#include "http_test_support.h"

namespace softshell {
namespace {

using namespace test;

struct Geo {
  GeomId id;
  std::string base;  // /geometries/<hex>
};

Geo upload_ready(TestServer& server, const ControlMesh& mesh = exact_grid()) {
  auto up = server.service().upload(mesh, exact_material());
  EXPECT_TRUE(up) << up.error().message;
  (void)server.service().wait_until_precomputed(up->id, std::chrono::seconds(30));
  return {up->id, "/geometries/" + up->id.hex()};
}

Reply put(httplib::Client& c, const std::string& path, const std::string& body, const std::string& type,
          const std::string& accept = "") {
  httplib::Headers h;
  if (!accept.empty()) h.emplace("Accept", accept);
  return to_reply(c.Put(path, h, body, type));
}

Reply del(httplib::Client& c, const std::string& path, const std::string& accept = "") {
  httplib::Headers h;
  if (!accept.empty()) h.emplace("Accept", accept);
  return to_reply(c.Delete(path, h));
}

std::string json_of(const DeformationRequest& r) { return wire::encode_request_json(r); }
std::string binary_of(const DeformationRequest& r) { return wire::encode_request_binary(r).value(); }

DeformationRequest pins(int n = 4) {
  DeformationRequest r;
  r.vertex_constraints = pinned_corners(n);
  return r;
}

DeformationRequest push(double fz, int n = 4) {
  DeformationRequest r;
  r.forces.push_back({grid_index(n, n / 2, n / 2), Vec3(0.0, 0.0, fz)});
  return r;
}

uint64_t version_in(const HeldResult& r, const std::string& hold) {
  return r.holds ? version_of(*r.holds, hold) : 0;
}

HeldResult held(const Reply& r) {
  auto decoded = wire::decode_held_result_json(r.body);
  EXPECT_TRUE(decoded) << r.status << " " << r.body.substr(0, 300);
  return decoded ? *decoded : HeldResult{};
}

TEST(HttpHoldsTest, PutInBothFormatsAnswersWithTheResultAndItsVersions) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  // JSON body: the JSON result with the versions map.
  Reply a = put(*c, g.base + "/holds/pins", json_of(pins()), kJson);
  ASSERT_EQ(a.status, 200) << a.body;
  EXPECT_EQ(a.content_type, kJson);
  HeldResult ra = held(a);
  EXPECT_EQ(ra.result.res_id, 1u);
  ASSERT_TRUE(ra.holds);
  EXPECT_EQ(*ra.holds, (HoldVersions{{"pins", 1}}));
  // Binary body: the binary result layout (which has no versions map).
  Reply b = put(*c, g.base + "/holds/push?ttl=30", binary_of(push(-0.25)), kBin);
  ASSERT_EQ(b.status, 200) << b.body;
  EXPECT_EQ(b.content_type, kBin);
  auto rb = wire::decode_result_binary(b.body, 25);
  ASSERT_TRUE(rb) << rb.error().message;
  EXPECT_EQ(rb->res_id, 2u);
  // The same values in the other format are the same contents: a renewal, answered with the
  // newest hold-state result, no new one stored.
  Reply again = put(*c, g.base + "/holds/push?ttl=30", json_of(push(-0.25)), kJson);
  ASSERT_EQ(again.status, 200) << again.body;
  HeldResult rr = held(again);
  EXPECT_EQ(rr.result.res_id, 2u);
  EXPECT_EQ(*rr.holds, (HoldVersions{{"pins", 1}, {"push", 1}}));
  EXPECT_EQ(wire::decode_result_ids_json(get(*c, g.base + "/results").body)->size(), 2u);
  // Accept decides the answer's format.
  Reply c2 = put(*c, g.base + "/holds/push", binary_of(push(-0.5)), kBin, kJson);
  ASSERT_EQ(c2.status, 200);
  EXPECT_EQ(version_in(held(c2), "push"), 2u);
  // Stored hold-state results carry their versions wherever they are read as JSON.
  EXPECT_EQ(version_in(held(get(*c, g.base + "/results/3")), "push"), 2u);
  EXPECT_EQ(version_in(held(get(*c, g.base + "/latest_result?wait=0")), "pins"), 1u);
  auto request = wire::decode_request_json(get(*c, g.base + "/results/3/request").body);
  ASSERT_TRUE(request);
  EXPECT_EQ(request->vertex_constraints.size(), 4u);
  EXPECT_EQ(request->forces.size(), 1u);
  // A POST result has none.
  Reply posted = post(*c, g.base + "/results", json_of(pinned_push(1)), kJson);
  ASSERT_EQ(posted.status, 200);
  EXPECT_FALSE(held(posted).holds);
}

TEST(HttpHoldsTest, WaitZeroIsAcceptedAtOnceWithTheVersion) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  ASSERT_EQ(put(*c, g.base + "/holds/pins", json_of(pins()), kJson).status, 200);
  Reply r = put(*c, g.base + "/holds/push?wait=0", json_of(push(-0.25)), kJson);
  ASSERT_EQ(r.status, 202) << r.body;
  EXPECT_EQ(r.content_type, kJson);
  auto accepted = wire::decode_hold_accepted_json(r.body);
  ASSERT_TRUE(accepted) << r.body;
  EXPECT_EQ(accepted->hold_id, "push");
  EXPECT_EQ(accepted->version, 1u);
  // The result follows through latest_result.
  Reply next = get(*c, g.base + "/latest_result?have=1&wait=10");
  ASSERT_EQ(next.status, 200);
  EXPECT_EQ(version_in(held(next), "push"), 1u);
}

TEST(HttpHoldsTest, BadRequestsGetTheirStatus) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  const std::string body = json_of(pins());
  DeformationRequest nonlinear_pins = pins();
  nonlinear_pins.model = DeformationModel::kNonlinear;
  auto status = [&](const Reply& r) { return r.status; };
  EXPECT_EQ(status(put(*c, g.base + "/holds/a!b", body, kJson)), 400);
  EXPECT_EQ(status(put(*c, g.base + "/holds/" + std::string(65, 'h'), body, kJson)), 400);
  EXPECT_EQ(status(put(*c, g.base + "/holds/" + std::string(64, 'h') + "?wait=0", body, kJson)), 202);
  for (const char* q : {"ttl=0", "ttl=601", "ttl=-1", "ttl=abc", "wait=-1", "wait=x", "model=quadratic"}) {
    Reply r = put(*c, g.base + "/holds/x?" + std::string(q), body, kJson);
    EXPECT_EQ(r.status, 400) << q << " " << r.body;
    EXPECT_EQ(error_code(r), "invalid_argument") << q;
  }
  EXPECT_EQ(status(put(*c, g.base + "/holds/x?model=linear", json_of(nonlinear_pins), kJson)), 400);  // contradicts
  EXPECT_EQ(status(put(*c, g.base + "/holds/x?model=linear&wait=0", body, kJson)), 202);
  EXPECT_EQ(status(put(*c, g.base + "/holds/x", "{\"vertex_constraints\": [{\"index\": 99}]}", kJson)), 400);
  EXPECT_EQ(status(put(*c, g.base + "/holds/x", "{\"nonsense\": 1}", kJson)), 400);
  EXPECT_EQ(status(put(*c, g.base + "/holds/x", "\x01\x02", kBin)), 400);
  EXPECT_EQ(status(put(*c, g.base + "/holds/x", body, "text/plain")), 415);
  EXPECT_EQ(status(put(*c, "/geometries/" + std::string(32, '0') + "/holds/x", body, kJson)), 404);
  EXPECT_EQ(status(put(*c, "/geometries/xyz/holds/x", body, kJson)), 400);
  EXPECT_EQ(status(del(*c, g.base + "/holds/nobody")), 404);
  EXPECT_EQ(status(get(*c, g.base + "/holds/nobody")), 404);
  EXPECT_EQ(status(get(*c, "/geometries/" + std::string(32, '0') + "/holds")), 404);
  Reply method = post(*c, g.base + "/holds/x", body, kJson);
  EXPECT_EQ(method.status, 405);
  EXPECT_NE(method.body.find("\"method_not_allowed\""), std::string::npos) << method.body;
  EXPECT_NE(method.body.find("PUT"), std::string::npos) << method.body;
}

TEST(HttpHoldsTest, ConflictsAndUndeterminedStatesAreRefusedAndTheHoldKeepsItsContents) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  ASSERT_EQ(put(*c, g.base + "/holds/pins", json_of(pins()), kJson).status, 200);
  DeformationRequest lift;
  lift.vertex_constraints.push_back({grid_index(4, 0, 0), kAxisZ, Vec3(0, 0, 0.1)});
  Reply conflict = put(*c, g.base + "/holds/lift", json_of(lift), kJson);
  EXPECT_EQ(conflict.status, 409) << conflict.body;
  EXPECT_EQ(error_code(conflict), "conflict");
  EXPECT_NE(conflict.body.find("'pins'"), std::string::npos) << conflict.body;
  EXPECT_EQ(get(*c, g.base + "/holds/lift").status, 404);

  DeformationRequest free_load = push(-0.25);
  Reply alone = put(*c, g.base + "/holds/hand", json_of(free_load), kJson);
  ASSERT_EQ(alone.status, 200);  // pinned by the other hold
  // Releasing the pins leaves the load free: released, 409, state unsolvable, nothing stored.
  Reply release = del(*c, g.base + "/holds/pins");
  EXPECT_EQ(release.status, 409) << release.body;
  EXPECT_EQ(error_code(release), "conflict");
  auto list = wire::decode_hold_list_json(get(*c, g.base + "/holds").body);
  ASSERT_TRUE(list);
  EXPECT_EQ(list->state, HoldStateStatus::kUnsolvable);
  EXPECT_FALSE(list->message.empty());
  ASSERT_EQ(list->holds.size(), 1u);
  EXPECT_EQ(list->holds[0].hold_id, "hand");
  EXPECT_EQ(list->res_id, 2u);
  // A change that leaves it undetermined: 422, the hold keeps version 1.
  Reply still = put(*c, g.base + "/holds/hand", json_of(push(-0.5)), kJson);
  EXPECT_EQ(still.status, 422) << still.body;
  auto one = wire::decode_hold_json(get(*c, g.base + "/holds/hand").body);
  ASSERT_TRUE(one);
  EXPECT_EQ(one->info.version, 1u);
  EXPECT_EQ(one->request.forces[0].force.z(), -0.25);
  // Pinning again: solved, and the DELETE of the last holds returns to rest.
  Reply fixed = put(*c, g.base + "/holds/pins", json_of(pins()), kJson);
  ASSERT_EQ(fixed.status, 200) << fixed.body;
  EXPECT_EQ(held(fixed).result.res_id, 3u);
  EXPECT_EQ(wire::decode_hold_list_json(get(*c, g.base + "/holds").body)->state, HoldStateStatus::kSolved);
  Reply r1 = del(*c, g.base + "/holds/hand");
  ASSERT_EQ(r1.status, 200) << r1.body;
  EXPECT_EQ(*held(r1).holds, (HoldVersions{{"pins", 2}}));
  Reply r2 = del(*c, g.base + "/holds/pins", kBin);
  ASSERT_EQ(r2.status, 200);
  auto rest = wire::decode_result_binary(r2.body, 25);
  ASSERT_TRUE(rest);
  EXPECT_EQ(rest->res_id, 5u);
  for (size_t i = 0; i < rest->positions.size(); ++i) {
    EXPECT_LT((rest->positions[i] - exact_grid().positions()[i]).norm(), 1e-7);  // f32 of the rest shape
  }
}

TEST(HttpHoldsTest, ListAndOneHoldLayouts) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  ASSERT_EQ(put(*c, g.base + "/holds/pins?ttl=20", json_of(pins()), kJson).status, 200);
  ASSERT_EQ(put(*c, g.base + "/holds/push?ttl=0.5&wait=0", json_of(push(-0.25)), kJson).status, 202);
  Reply list = get(*c, g.base + "/holds");
  ASSERT_EQ(list.status, 200);
  EXPECT_EQ(list.content_type, kJson);
  auto decoded = wire::decode_hold_list_json(list.body);
  ASSERT_TRUE(decoded) << list.body;
  ASSERT_EQ(decoded->holds.size(), 2u);
  EXPECT_EQ(decoded->holds[0].hold_id, "pins");
  EXPECT_GT(decoded->holds[0].expires_in, 15.0);
  EXPECT_LE(decoded->holds[0].expires_in, 20.0);
  EXPECT_LE(decoded->holds[1].expires_in, 0.5);
  Reply one = get(*c, g.base + "/holds/pins");
  ASSERT_EQ(one.status, 200);
  auto hold = wire::decode_hold_json(one.body);
  ASSERT_TRUE(hold) << one.body;
  EXPECT_EQ(hold->info.hold_id, "pins");
  EXPECT_EQ(hold->info.version, 1u);
  EXPECT_EQ(hold->request.vertex_constraints.size(), 4u);
  // The short lease lapses: the hold is gone and the object solved again without it.
  Reply after = get(*c, g.base + "/latest_result?have=2&wait=10");
  ASSERT_EQ(after.status, 200) << after.body;
  EXPECT_EQ(*held(after).holds, (HoldVersions{{"pins", 1}}));
  EXPECT_EQ(get(*c, g.base + "/holds/push").status, 404);
}

// A nonlinear hold over HTTP: `?model=nonlinear` with a binary body (or the JSON field) makes the
// hold state nonlinear; the JSON answer says so with Newton's iterations and residual, and is the
// nonlinear solve of all holds together (the same as POSTing them as one request). Releasing it
// returns the state to the linear model; a nonlinear hold that cannot be solved is a 422.
TEST(HttpHoldsTest, NonlinearHoldMakesTheHoldStateNonlinear) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  ASSERT_EQ(put(*c, g.base + "/holds/pins", json_of(pins()), kJson).status, 200);
  DeformationRequest grab;  // the centre lifted by 0.3 (a vertex constraint: the binary layout has it)
  grab.vertex_constraints.push_back({grid_index(4, 2, 2), kAxisZ, Vec3(0.0, 0.0, 0.3)});
  Reply a = put(*c, g.base + "/holds/grab?model=nonlinear", binary_of(grab), kBin, kJson);
  ASSERT_EQ(a.status, 200) << a.body;
  EXPECT_NE(a.body.find("\"model\":\"nonlinear\""), std::string::npos) << a.body.substr(0, 300);
  const HeldResult ra = held(a);
  EXPECT_EQ(ra.result.model, DeformationModel::kNonlinear);
  EXPECT_GE(ra.result.iterations, 1);
  EXPECT_LT(ra.result.residual, 1e-8);
  EXPECT_EQ(*ra.holds, (HoldVersions{{"grab", 1}, {"pins", 1}}));
  auto detail = wire::decode_hold_json(get(*c, g.base + "/holds/grab").body);
  ASSERT_TRUE(detail);
  EXPECT_EQ(detail->request.model, DeformationModel::kNonlinear);

  // The same as both holds as one nonlinear request, solved alone; far from the linear answer
  // (a pull of 0.3 on a plate of 1 is well past the linear range).
  DeformationRequest both = pins();
  both.vertex_constraints.push_back(grab.vertex_constraints[0]);
  both.model = DeformationModel::kNonlinear;
  Reply alone = post(*c, g.base + "/results", json_of(both), kJson);
  ASSERT_EQ(alone.status, 200) << alone.body;
  both.model = DeformationModel::kLinear;
  Reply linear = post(*c, g.base + "/results", json_of(both), kJson);
  ASSERT_EQ(linear.status, 200) << linear.body;
  const DeformationResult r_alone = wire::decode_result_json(alone.body, 25).value();
  const DeformationResult r_linear = wire::decode_result_json(linear.body, 25).value();
  double same = 0.0, apart = 0.0;
  for (size_t i = 0; i < 25; ++i) {
    same = std::max(same, (ra.result.positions[i] - r_alone.positions[i]).norm());
    apart = std::max(apart, (ra.result.positions[i] - r_linear.positions[i]).norm());
  }
  EXPECT_LT(same, 1e-6);
  EXPECT_GT(apart, 1e-2);

  // The JSON field works the same; the drag step starts from the previous nonlinear state.
  grab.vertex_constraints[0].displacement = Vec3(0.0, 0.0, 0.31);
  grab.model = DeformationModel::kNonlinear;
  Reply b = put(*c, g.base + "/holds/grab", json_of(grab), kJson);
  ASSERT_EQ(b.status, 200) << b.body;
  const HeldResult rb = held(b);
  EXPECT_EQ(rb.result.model, DeformationModel::kNonlinear);
  EXPECT_LT(rb.result.iterations, ra.result.iterations);

  // Released: the state is linear again (pins alone: the rest shape, the version 1 layout).
  Reply released = del(*c, g.base + "/holds/grab");
  ASSERT_EQ(released.status, 200) << released.body;
  EXPECT_EQ(released.body.find("\"model\""), std::string::npos) << released.body.substr(0, 300);
  const HeldResult rr = held(released);
  for (size_t i = 0; i < 25; ++i) EXPECT_EQ(rr.result.positions[i], exact_grid().positions()[i]);

  // An undetermined nonlinear hold state (a free plate pushed) is a 422 and creates nothing.
  const Geo free = upload_ready(server, exact_grid(2));
  DeformationRequest shove;
  shove.forces.push_back({4, Vec3(0.0, 0.0, 1.0)});
  Reply refused = put(*c, free.base + "/holds/shove?model=nonlinear", json_of(shove), kJson);
  EXPECT_EQ(refused.status, 422) << refused.body;
  EXPECT_EQ(get(*c, free.base + "/holds/shove").status, 404);
}

TEST(HttpHoldsTest, EightClientsUpdatingTheirOwnHolds) {
  TestServer server;
  const ControlMesh mesh = make_grid(8, 8);
  const Geo g = upload_ready(server, mesh);
  auto evaluator = LimitEvaluator::create(mesh).value();
  {
    auto c = server.client();
    ASSERT_EQ(put(*c, g.base + "/holds/pins", json_of(pins(8)), kJson).status, 200);
  }
  constexpr int kClients = 8, kEach = 12;
  // Each client grabs its own limit point and moves it a little further each time.
  auto point = [](int client) { return SurfacePoint{9 + 8 * (client / 4) + 2 * (client % 4), 0, 0.4, 0.6}; };
  auto target = [](int client, int k) { return Vec3(0.0, 0.001 * client, 0.002 * k); };
  std::vector<uint64_t> last(kClients, 0);
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int client = 0; client < kClients; ++client) {
    threads.emplace_back([&, client] {
      auto c = server.client();
      const std::string hold = "hand-" + std::to_string(client);
      for (int k = 1; k <= kEach; ++k) {
        DeformationRequest r;
        r.limit_constraints.push_back({point(client), target(client, k), std::nullopt, std::nullopt});
        Reply reply = put(*c, g.base + "/holds/" + hold, json_of(r), kJson);
        if (reply.status != 200) {
          failures.fetch_add(1);
          ADD_FAILURE() << hold << ": " << reply.status << " " << reply.body;
          continue;
        }
        HeldResult result = held(reply);
        const uint64_t mine = version_in(result, hold);
        if (mine < static_cast<uint64_t>(k)) {  // its version k, or a newer one
          failures.fetch_add(1);
          ADD_FAILURE() << hold << " version " << k << " answered with version " << mine;
        }
        last[static_cast<size_t>(client)] = static_cast<uint64_t>(k);
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  auto c = server.client();
  auto ids = wire::decode_result_ids_json(get(*c, g.base + "/results").body).value();
  for (size_t i = 0; i < ids.size(); ++i) EXPECT_EQ(ids[i], i + 1);
  HeldResult newest = held(get(*c, g.base + "/results/" + std::to_string(ids.back())));
  for (int client = 0; client < kClients; ++client) {
    EXPECT_EQ(version_in(newest, "hand-" + std::to_string(client)), last[static_cast<size_t>(client)]);
  }
  // The combined state meets every client's grab exactly.
  for (int client = 0; client < kClients; ++client) {
    const SurfacePoint p = point(client);
    const Vec3 moved = limit_point(evaluator, newest.result.positions, p) - limit_point(evaluator, mesh.positions(), p);
    EXPECT_LT((moved - target(client, kEach)).norm(), 1e-10) << "client " << client;
  }
  const auto stats = server.service().stats();
  EXPECT_EQ(stats.hold_changes_solved, static_cast<uint64_t>(1 + kClients * kEach));
  // Merged: fewer stored results than changes, once the clients overlapped at all.
  EXPECT_LE(ids.size(), stats.hold_changes_solved);
}

}  // namespace
}  // namespace softshell
