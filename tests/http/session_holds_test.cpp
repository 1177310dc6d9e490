// Holds through both sessions (EmbeddedSession on the service, RemoteSession over 127.0.0.1 in
// both body formats): put/renew/replace/release, leases, 409/422 with the server's messages,
// several clients' holds combined, the asynchronous put, and HoldLease.
#include <gtest/gtest.h>

#include <thread>

#include "http_test_support.h"
#include "session_test_support.h"
#include "softshell/hold_lease.h"

namespace softshell {
namespace {

using namespace test;

class SessionHoldsTest : public ::testing::TestWithParam<SessionKind> {
 protected:
  TestServer server;
  std::unique_ptr<Session> session = make_session(GetParam(), server);
  GeomId id = upload_ready(*session, server);
};

TEST_P(SessionHoldsTest, PutRenewReplaceRelease) {
  Session& s = *session;
  auto a = s.put_hold(id, "pins", pins());
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_EQ(a->result.res_id, 1u);
  ASSERT_TRUE(a->holds);
  EXPECT_EQ(*a->holds, (HoldVersions{{"pins", 1}}));

  auto b = s.put_hold(id, "push", push(-0.25), std::chrono::seconds(30));
  ASSERT_TRUE(b) << b.error().message;
  EXPECT_EQ(b->result.res_id, 2u);
  EXPECT_EQ(*b->holds, (HoldVersions{{"pins", 1}, {"push", 1}}));
  // Pulling down at the centre moves it down.
  const int centre = grid_index(4, 2, 2);
  EXPECT_LT(b->result.positions[centre].z(), -1e-6);

  // The same contents only renew: no new version, no new result.
  auto renewed = s.put_hold(id, "push", push(-0.25), std::chrono::seconds(30));
  ASSERT_TRUE(renewed) << renewed.error().message;
  EXPECT_EQ(renewed->result.res_id, 2u);
  EXPECT_EQ(s.result_ids(id).value().size(), 2u);

  // New contents: version 2, a new result, twice the displacement (linear).
  auto replaced = s.put_hold(id, "push", push(-0.5), std::chrono::seconds(30));
  ASSERT_TRUE(replaced) << replaced.error().message;
  EXPECT_EQ(replaced->result.res_id, 3u);
  EXPECT_EQ(version_in(*replaced, "push"), 2u);
  const Vec3 rest = exact_grid().positions()[centre];
  EXPECT_NEAR(replaced->result.positions[centre].z() - rest.z(), 2 * (b->result.positions[centre].z() - rest.z()), 1e-9);

  auto list = s.holds(id);
  ASSERT_TRUE(list) << list.error().message;
  ASSERT_EQ(list->holds.size(), 2u);
  EXPECT_EQ(list->holds[0].hold_id, "pins");
  EXPECT_EQ(list->holds[1].hold_id, "push");
  EXPECT_EQ(list->holds[1].version, 2u);
  EXPECT_GT(list->holds[1].expires_in, 20.0);
  EXPECT_EQ(list->res_id, 3u);
  EXPECT_EQ(list->state, HoldStateStatus::kSolved);
  auto one = s.hold(id, "push");
  ASSERT_TRUE(one) << one.error().message;
  EXPECT_EQ(one->info.version, 2u);
  ASSERT_EQ(one->request.forces.size(), 1u);
  EXPECT_EQ(one->request.forces[0].force.z(), -0.5);

  auto released = s.release_hold(id, "push");
  ASSERT_TRUE(released) << released.error().message;
  EXPECT_EQ(released->result.res_id, 4u);
  EXPECT_EQ(*released->holds, (HoldVersions{{"pins", 1}}));
  // With no hold left the object is at rest, and that is a result too.
  auto last = s.release_hold(id, "pins");
  ASSERT_TRUE(last) << last.error().message;
  EXPECT_EQ(last->result.res_id, 5u);
  ASSERT_TRUE(last->holds);
  EXPECT_TRUE(last->holds->empty());
  for (size_t i = 0; i < last->result.positions.size(); ++i) {
    EXPECT_LT((last->result.positions[i] - exact_grid().positions()[i]).norm(), 1e-7);
  }
  auto again = s.release_hold(id, "pins");
  ASSERT_FALSE(again);
  EXPECT_EQ(again.error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.hold(id, "pins").error().code, ErrorCode::kNotFound);
}

// DeformationRequest::model reaches the hold state through every session (the remote one sends
// such a request as JSON, the layout that carries the field), and the answer says how it was
// solved; the nonlinear answer is the nonlinear solve of the combined holds.
TEST_P(SessionHoldsTest, NonlinearHoldsThroughTheSession) {
  Session& s = *session;
  ASSERT_TRUE(s.put_hold(id, "pins", pins()));
  DeformationRequest pull = push(-0.25);
  pull.model = DeformationModel::kNonlinear;
  auto held = s.put_hold(id, "push", pull);
  ASSERT_TRUE(held) << held.error().message;
  EXPECT_EQ(held->result.model, DeformationModel::kNonlinear);
  EXPECT_GE(held->result.iterations, 1);
  EXPECT_LT(held->result.residual, 1e-8);
  DeformationRequest both = pinned_push(1);
  both.model = DeformationModel::kNonlinear;
  auto alone = s.deform(id, both);
  ASSERT_TRUE(alone) << alone.error().message;
  for (size_t i = 0; i < alone->positions.size(); ++i) {
    EXPECT_LT((held->result.positions[i] - alone->positions[i]).norm(), 1e-6) << i;
  }
  auto detail = s.hold(id, "push");
  ASSERT_TRUE(detail) << detail.error().message;
  EXPECT_EQ(detail->request.model, DeformationModel::kNonlinear);
  auto linear = s.put_hold(id, "push", push(-0.25));
  ASSERT_TRUE(linear) << linear.error().message;
  EXPECT_EQ(linear->result.model, DeformationModel::kLinear);
}

TEST_P(SessionHoldsTest, RefusalsCarryTheServersMessage) {
  Session& s = *session;
  // Alone, a load leaves the sheet free to move: 422, and no hold is created.
  auto alone = s.put_hold(id, "hand", push(-0.25));
  ASSERT_FALSE(alone);
  EXPECT_EQ(alone.error().code, ErrorCode::kUnprocessable);
  EXPECT_FALSE(alone.error().message.empty());
  EXPECT_EQ(s.hold(id, "hand").error().code, ErrorCode::kNotFound);

  ASSERT_TRUE(s.put_hold(id, "pins", pins()));
  DeformationRequest lift;
  lift.vertex_constraints.push_back({grid_index(4, 0, 0), kAxisZ, Vec3(0, 0, 0.1)});
  auto conflict = s.put_hold(id, "lift", lift);
  ASSERT_FALSE(conflict);
  EXPECT_EQ(conflict.error().code, ErrorCode::kConflict);
  EXPECT_NE(conflict.error().message.find("'pins'"), std::string::npos) << conflict.error().message;
  EXPECT_EQ(s.hold(id, "lift").error().code, ErrorCode::kNotFound);

  ASSERT_TRUE(s.put_hold(id, "hand", push(-0.25)));
  const uint64_t hand_version = s.hold(id, "hand").value().info.version;  // (the refused PUT used a number)
  // Releasing the pins leaves the load free: released all the same, 409, unsolvable.
  auto release = s.release_hold(id, "pins");
  ASSERT_FALSE(release);
  EXPECT_EQ(release.error().code, ErrorCode::kConflict);
  EXPECT_FALSE(release.error().message.empty());
  auto list = s.holds(id).value();
  EXPECT_EQ(list.state, HoldStateStatus::kUnsolvable);
  EXPECT_FALSE(list.message.empty());
  ASSERT_EQ(list.holds.size(), 1u);
  // A change that stays undetermined is refused and the hold keeps its contents.
  auto still = s.put_hold(id, "hand", push(-0.5));
  ASSERT_FALSE(still);
  EXPECT_EQ(still.error().code, ErrorCode::kUnprocessable);
  auto kept = s.hold(id, "hand").value();
  EXPECT_EQ(kept.info.version, hand_version);
  EXPECT_EQ(kept.request.forces[0].force.z(), -0.25);

  // Bad arguments: the same checks as the server's.
  EXPECT_EQ(s.put_hold(id, "a!b", pins()).error().code, ErrorCode::kInvalidArgument);
  auto ttl = s.put_hold(id, "pins", pins(), std::chrono::seconds(601));
  ASSERT_FALSE(ttl);
  EXPECT_EQ(ttl.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(ttl.error().message.find("ttl"), std::string::npos) << ttl.error().message;
  EXPECT_EQ(s.put_hold(GeomId{}, "pins", pins()).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.holds(GeomId{}).error().code, ErrorCode::kNotFound);
}

TEST_P(SessionHoldsTest, AShortLeaseLapses) {
  Session& s = *session;
  ASSERT_TRUE(s.put_hold(id, "pins", pins(), std::chrono::seconds(30)));
  ASSERT_TRUE(s.put_hold(id, "push", push(-0.25), std::chrono::milliseconds(300)));
  // The lapse is solved again without the hold and stored as result 3.
  auto after = s.latest_result(id, 2, std::chrono::seconds(20));
  ASSERT_TRUE(after) << after.error().message;
  ASSERT_TRUE(*after);
  EXPECT_EQ(s.hold(id, "push").error().code, ErrorCode::kNotFound);
  auto list = s.holds(id).value();
  ASSERT_EQ(list.holds.size(), 1u);
  EXPECT_EQ(list.holds[0].hold_id, "pins");
}

TEST_P(SessionHoldsTest, AsynchronousPutsAnswerWithoutBlocking) {
  Session& s = *session;
  auto first = s.put_hold_async(id, "pins", pins());
  auto answer = first.get();
  ASSERT_TRUE(answer) << answer.error().message;
  EXPECT_EQ(version_in(*answer, "pins"), 1u);
  auto conflict = s.put_hold_async(id, "lift", [] {
    DeformationRequest lift;
    lift.vertex_constraints.push_back({grid_index(4, 4, 4), kAxisZ, Vec3(0, 0, 0.1)});
    return lift;
  }());
  auto refused = conflict.get();
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kConflict);
  // A renewal (answered at once) and a change.
  auto renewal = s.put_hold_async(id, "pins", pins()).get();
  ASSERT_TRUE(renewal) << renewal.error().message;
  EXPECT_EQ(renewal->result.res_id, 1u);
  auto change = s.put_hold_async(id, "push", push(-0.25)).get();
  ASSERT_TRUE(change) << change.error().message;
  EXPECT_EQ(change->result.res_id, 2u);
}

// Several clients, each its own session and hold, updating at once: every answer includes its
// own version, and the newest result includes every client's last version.
TEST_P(SessionHoldsTest, SeveralClientsHoldsAreCombined) {
  constexpr int kClients = 4, kUpdates = 6;
  ASSERT_TRUE(session->put_hold(id, "pins", pins(), std::chrono::seconds(60)));
  std::vector<std::unique_ptr<Session>> clients;
  for (int c = 0; c < kClients; ++c) clients.push_back(make_session(GetParam(), server));
  std::vector<std::thread> threads;
  std::vector<std::string> failures(kClients);
  for (int c = 0; c < kClients; ++c) {
    threads.emplace_back([&, c] {
      const std::string hold = "hand-" + std::to_string(c);
      // Each client pushes at its own interior control point.
      const int point = grid_index(4, 1 + c % 3, 1 + c / 3);
      for (int k = 1; k <= kUpdates; ++k) {
        DeformationRequest r;
        r.forces.push_back({point, Vec3(0, 0, -0.125 * k)});
        auto answer = clients[c]->put_hold_async(id, hold, r, std::chrono::seconds(60)).get();
        if (!answer) {
          failures[c] = answer.error().message;
          return;
        }
        if (version_in(*answer, hold) < static_cast<uint64_t>(k)) {
          failures[c] = "answer " + std::to_string(k) + " has version " + std::to_string(version_in(*answer, hold));
          return;
        }
      }
    });
  }
  for (auto& t : threads) t.join();
  for (int c = 0; c < kClients; ++c) EXPECT_EQ(failures[c], "") << "client " << c;
  auto newest = session->latest_result(id, 0, std::chrono::milliseconds(0)).value();
  ASSERT_TRUE(newest);
  auto list = session->holds(id).value();
  EXPECT_EQ(list.res_id, newest->res_id);
  ASSERT_EQ(list.holds.size(), static_cast<size_t>(kClients + 1));
  for (int c = 0; c < kClients; ++c) EXPECT_EQ(list.holds[c].version, static_cast<uint64_t>(kUpdates));
  // The newest result is the solve of every client's last push together (linear superposition
  // of the same request sent alone).
  DeformationRequest all = pins();
  for (int c = 0; c < kClients; ++c) all.forces.push_back({grid_index(4, 1 + c % 3, 1 + c / 3), Vec3(0, 0, -0.125 * kUpdates)});
  auto alone = session->deform(id, all);
  ASSERT_TRUE(alone) << alone.error().message;
  const double tol = GetParam() == SessionKind::kRemoteBinary ? 1e-6 : 1e-9;  // binary bodies are f32
  for (size_t i = 0; i < alone->positions.size(); ++i) {
    EXPECT_LT((alone->positions[i] - newest->positions[i]).norm(), tol) << "control point " << i;
  }
}

TEST_P(SessionHoldsTest, HoldLeaseRenewsUpdatesAndReleases) {
  Session& s = *session;
  ASSERT_TRUE(s.put_hold(id, "pins", pins(), std::chrono::seconds(60)));
  {
    HoldLeaseOptions options;
    options.ttl = std::chrono::seconds(1);
    HoldLease lease(s, id, "hand", push(-0.25), options);
    // Outlives its 1 s lease by renewing it (no new version).
    std::this_thread::sleep_for(std::chrono::milliseconds(2500));
    auto held = s.hold(id, "hand");
    ASSERT_TRUE(held) << held.error().message;
    EXPECT_EQ(held->info.version, 1u);
    EXPECT_EQ(lease.version(), 1u);
    EXPECT_GE(lease.puts(), 3u);  // the first put and renewals (the period is a third of the lease)
    EXPECT_FALSE(lease.error());
    auto answer = lease.poll();
    ASSERT_TRUE(answer);
    EXPECT_EQ(version_in(*answer, "hand"), 1u);
    EXPECT_FALSE(lease.poll());

    // A refused update leaves the hold as it was, and the lease keeps renewing that.
    DeformationRequest lift;
    lift.vertex_constraints.push_back({grid_index(4, 0, 0), kAxisZ, Vec3(0, 0, 0.1)});
    lease.update(lift);
    for (int i = 0; i < 200 && !lease.error(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_TRUE(lease.error());
    EXPECT_EQ(lease.error()->code, ErrorCode::kConflict);
    EXPECT_EQ(s.hold(id, "hand").value().request.forces[0].force.z(), -0.25);
    // An accepted update: a newer version (the refused change used a number too), renewed on.
    lease.update(push(-0.5));
    for (int i = 0; i < 500 && lease.version() < 2; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    EXPECT_GE(lease.version(), 2u);
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));
    EXPECT_EQ(s.hold(id, "hand").value().info.version, lease.version());
    EXPECT_EQ(s.hold(id, "hand").value().request.forces[0].force.z(), -0.5);
  }
  // Released on destruction, at once.
  EXPECT_EQ(s.hold(id, "hand").error().code, ErrorCode::kNotFound);
  auto list = s.holds(id).value();
  ASSERT_EQ(list.holds.size(), 1u);
  EXPECT_EQ(list.holds[0].hold_id, "pins");
}

TEST_P(SessionHoldsTest, HoldLeaseReportsARefusedFirstPut) {
  HoldLease lease(*session, id, "hand", push(-0.25));  // nothing pins the sheet: 422
  for (int i = 0; i < 500 && !lease.error(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(lease.error());
  EXPECT_EQ(lease.error()->code, ErrorCode::kUnprocessable);
  EXPECT_EQ(lease.version(), 0u);
  auto released = lease.release();  // nothing to release
  ASSERT_FALSE(released);
  EXPECT_EQ(released.error().code, ErrorCode::kNotFound);
  EXPECT_THROW(HoldLease(*session, id, "x", pins(), HoldLeaseOptions{std::chrono::milliseconds(0)}), Exception);
}

INSTANTIATE_TEST_SUITE_P(Sessions, SessionHoldsTest,
                         ::testing::Values(SessionKind::kEmbedded, SessionKind::kRemoteBinary, SessionKind::kRemoteJson),
                         [](const auto& p) { return std::string(name_of(p.param)); });

}  // namespace
}  // namespace softshell
