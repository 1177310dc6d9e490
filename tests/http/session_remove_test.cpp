// Session::remove_geometry through both sessions (EmbeddedSession: Service::remove; RemoteSession:
// DELETE /geometries/{id} over 127.0.0.1, in both body formats): what was kept goes, waiters and
// followers end with kGone, the id is unknown, and an upload of the same content continues the ids.
#include <gtest/gtest.h>

#include <future>

#include "http_test_support.h"
#include "session_test_support.h"

namespace softshell {
namespace {

using namespace test;

class SessionRemoveTest : public ::testing::TestWithParam<SessionKind> {
 protected:
  TestServer server;
  std::unique_ptr<Session> session = make_session(GetParam(), server);
  GeomId id = upload_ready(*session, server);
};

TEST_P(SessionRemoveTest, RemovedResultsAreGoneAndAnUploadContinuesTheIds) {
  Session& s = *session;
  for (int k = 1; k <= 2; ++k) {
    auto r = s.deform(id, pinned_push(k));
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_EQ(r->res_id, static_cast<uint32_t>(k));
  }
  auto feed = s.subscribe(id, 2);
  ASSERT_TRUE(feed) << feed.error().message;
  // A long poll for a result newer than 2 waits; the delete answers it.
  auto waiting = std::async(std::launch::async, [&] { return s.latest_result(id, 2, std::chrono::seconds(30)); });
  ASSERT_EQ(waiting.wait_for(std::chrono::milliseconds(200)), std::future_status::timeout);

  ASSERT_TRUE(s.remove_geometry(id));
  const auto polled = waiting.get();
  ASSERT_FALSE(polled);
  EXPECT_EQ(polled.error().code, ErrorCode::kGone) << polled.error().message;
  auto ended = (*feed)->next(std::chrono::seconds(10));
  ASSERT_FALSE(ended);
  EXPECT_EQ(ended.error().code, ErrorCode::kGone) << ended.error().message;
  EXPECT_EQ((*feed)->state(), FeedState::kFailed);

  // Gone from the service (not only from this session's view).
  EXPECT_EQ(server.service().info(id).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.geometry_info(id).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.result(id, 1).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.result_ids(id).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(s.deform(id, pinned_push(3)).error().code, ErrorCode::kNotFound);
  const auto again = s.remove_geometry(id);
  ASSERT_FALSE(again);
  EXPECT_EQ(again.error().code, ErrorCode::kNotFound);
  EXPECT_NE(again.error().message.find("no geometry with id " + id.hex()), std::string::npos) << again.error().message;

  // The same content again: a new geometry under the same id whose ids follow the deleted ones.
  auto up = s.upload(exact_grid(), exact_material());
  ASSERT_TRUE(up) << up.error().message;
  EXPECT_TRUE(up->created);
  EXPECT_EQ(up->id, id);
  auto next = s.deform(id, pinned_push(1));
  ASSERT_TRUE(next) << next.error().message;
  EXPECT_EQ(next->res_id, 3u);
  EXPECT_EQ(s.result_ids(id).value(), (std::vector<uint32_t>{3}));
  const auto old = s.result(id, 2);
  ASSERT_FALSE(old);
  EXPECT_EQ(old.error().code, ErrorCode::kGone);
  EXPECT_NE(old.error().message.find("earlier upload of it that was deleted"), std::string::npos) << old.error().message;
  EXPECT_EQ(server.service().stats().geometries_deleted, 1u);
}

TEST_P(SessionRemoveTest, HoldsGoWithTheGeometry) {
  Session& s = *session;
  auto held = s.put_hold(id, "pins", pins());
  ASSERT_TRUE(held) << held.error().message;
  ASSERT_TRUE(s.remove_geometry(id));
  ASSERT_TRUE(s.upload(exact_grid(), exact_material()));
  (void)server.service().wait_until_precomputed(id, std::chrono::seconds(60));
  EXPECT_TRUE(s.holds(id).value().holds.empty());
  // The hold id's version continues too (1 was the deleted upload's).
  auto again = s.put_hold(id, "pins", pins());
  ASSERT_TRUE(again) << again.error().message;
  EXPECT_EQ(version_in(*again, "pins"), 2u);
  EXPECT_EQ(again->result.res_id, 2u);
}

INSTANTIATE_TEST_SUITE_P(Sessions, SessionRemoveTest,
                         ::testing::Values(SessionKind::kEmbedded, SessionKind::kRemoteBinary, SessionKind::kRemoteJson),
                         [](const auto& p) { return std::string(name_of(p.param)); });

// A session that does not implement it (a test double) refuses it rather than pretending.
TEST(SessionRemoveDefaultTest, ASessionWithoutItRefusesWithUnavailable) {
  struct Bare : Session {
    Result<UploadResult> upload(const ControlMesh&, const Material&, std::string_view) override { return fail(); }
    Result<std::vector<GeometryInfo>> geometries() override { return fail(); }
    Result<GeometryInfo> geometry_info(const GeomId&) override { return fail(); }
    Result<Geometry> geometry(const GeomId&) override { return fail(); }
    Result<DeformationResult> deform(const GeomId&, const DeformationRequest&) override { return fail(); }
    std::future<Result<DeformationResult>> deform_async(const GeomId&, const DeformationRequest&) override {
      return {};
    }
    Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return fail(); }
    Result<DeformationResult> result(const GeomId&, uint32_t) override { return fail(); }
    Result<DeformationRequest> result_request(const GeomId&, uint32_t) override { return fail(); }
    Result<std::optional<DeformationResult>> latest_result(const GeomId&, uint32_t,
                                                           std::chrono::milliseconds) override {
      return fail();
    }
    Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return fail(); }
    Result<StressField> stresses(const GeomId&, uint32_t, const StressQuery&) override { return fail(); }
    static Error fail() { return Error{ErrorCode::kInternal, "not used"}; }
  } bare;
  const auto refused = bare.remove_geometry(GeomId{});
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kUnavailable);
}

}  // namespace
}  // namespace softshell
