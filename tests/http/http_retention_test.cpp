// DELETE /geometries/{id} and result retention over real sockets (127.0.0.1, ephemeral ports):
// 204 and 404, everyone waiting on a deleted geometry answered 410 (a deformation waiting for the
// precomputation, a long poll, a hold change, an event stream), a new upload after a delete, and
// 410 for a result the retention policy dropped against 404 for one never stored.
#include <gtest/gtest.h>

#include <cctype>
#include <thread>

#include "http_test_support.h"
#include "sse_client.h"

namespace softshell {
namespace {

using namespace test;
using std::chrono::milliseconds;

Reply del(httplib::Client& c, const std::string& path) { return to_reply(c.Delete(path)); }

// A top-level string or number field of a small JSON answer ("" if absent).
std::string field(const std::string& body, const std::string& name) {
  const std::string key = "\"" + name + "\":";
  const size_t at = body.find(key);
  if (at == std::string::npos) return "";
  size_t b = at + key.size();
  if (b < body.size() && body[b] == '"') {
    const size_t e = body.find('"', b + 1);
    return body.substr(b + 1, e - b - 1);
  }
  size_t e = b;
  while (e < body.size() && std::isdigit(static_cast<unsigned char>(body[e]))) ++e;
  return body.substr(b, e - b);
}

std::string upload_json(httplib::Client& c, const ControlMesh& mesh, int expect_status = 201) {
  Reply up = post(c, "/geometries", wire::encode_geometry_json(mesh, exact_material()), kJson);
  EXPECT_EQ(up.status, expect_status) << up.body;
  return field(up.body, "geom_id");
}

uint32_t res_id_of(const Reply& r) {
  const std::string v = field(r.body, "res_id");
  return v.empty() ? 0 : static_cast<uint32_t>(std::stoul(v));
}

TEST(HttpDeleteTest, Answers204ThenTheGeometryIsUnknown) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_json(*c, exact_grid());
  ASSERT_FALSE(id.empty());
  const std::string base = "/geometries/" + id;
  ASSERT_EQ(server.service().wait_until_precomputed(GeomId::from_hex(id).value(), std::chrono::seconds(30))->status,
            GeometryStatus::kReady);
  EXPECT_EQ(post(*c, base + "/results", wire::encode_request_json(pinned_push(1)), kJson).status, 200);

  Reply gone = del(*c, base);
  EXPECT_EQ(gone.status, 204);
  EXPECT_TRUE(gone.body.empty());
  Reply again = del(*c, base);
  EXPECT_EQ(again.status, 404);
  EXPECT_EQ(error_code(again), "not_found");
  EXPECT_EQ(get(*c, base + "/status").status, 404);
  EXPECT_EQ(get(*c, base + "/results/1").status, 404);
  EXPECT_EQ(get(*c, "/geometries").body.find(id), std::string::npos);
  EXPECT_EQ(del(*c, "/geometries/not-an-id").status, 400);
}

TEST(HttpDeleteTest, ReleasesEveryoneWaitingWith410) {
  service::ServiceOptions so = test_service_options();
  so.precompute_jobs = 1;
  TestServer server(so);
  auto c = server.client();
  // Precomputing long enough for everyone to line up (the delete cancels it).
  const ControlMesh slow = make_grid(48, 48);
  const std::string id = upload_json(*c, slow);
  const GeomId gid = GeomId::from_hex(id).value();
  const std::string base = "/geometries/" + id;

  Reply deformed, polled, held;
  std::thread poster([&] {
    auto pc = server.client(60);
    deformed = post(*pc, base + "/results", wire::encode_request_json(pinned_push(1, 48)), kJson);
  });
  std::thread poller([&] {
    auto lc = server.client(60);
    polled = get(*lc, base + "/latest_result?have=0&wait=50");
  });
  std::thread holder([&] {
    auto hc = server.client(60);
    held = to_reply(hc->Put(base + "/holds/hand?wait=50", wire::encode_request_json(pinned_push(1, 48)), kJson));
  });
  SseClient stream(server.port(), base + "/events");
  ASSERT_TRUE(stream.read_head(milliseconds(10000)));
  EXPECT_EQ(stream.parser().status(), 200);
  for (;;) {  // everyone in place (counts, not time)
    const auto st = server.service().stats();
    if (st.pending_solves >= 1 && st.waiters >= 1 && st.hold_changes_pending >= 1 && server.http().event_streams() == 1) break;
    std::this_thread::sleep_for(milliseconds(5));
  }
  ASSERT_EQ(server.service().info(gid)->status, GeometryStatus::kPrecomputing);

  EXPECT_EQ(del(*c, base).status, 204);
  poster.join();
  poller.join();
  holder.join();
  for (const Reply* r : {&deformed, &polled, &held}) {
    EXPECT_EQ(r->status, 410) << r->body;
    EXPECT_EQ(error_code(*r), "gone");
    EXPECT_NE(r->body.find("was deleted"), std::string::npos) << r->body;
  }
  auto ended = stream.next_result(milliseconds(10000));
  ASSERT_TRUE(ended);
  EXPECT_EQ(ended->event, "deleted");
  const Error why = wire::decode_error_json(ended->data, 410);
  EXPECT_EQ(why.code, ErrorCode::kGone);
  EXPECT_NE(why.message.find(id), std::string::npos) << ended->data;
  EXPECT_TRUE(stream.read_to_end(milliseconds(10000)));  // the end of the chunked body, then closed
  for (;;) {  // the stream's follower leaves once it is closed
    if (server.http().event_streams() == 0) break;
    std::this_thread::sleep_for(milliseconds(5));
  }
  // A new stream of the deleted id is a 404.
  SseClient late(server.port(), base + "/events");
  ASSERT_TRUE(late.read_head(milliseconds(10000)));
  EXPECT_EQ(late.parser().status(), 404);
}

TEST(HttpDeleteTest, AReuploadIsANewGeometryWhoseIdsContinue) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_json(*c, exact_grid());
  const GeomId gid = GeomId::from_hex(id).value();
  const std::string base = "/geometries/" + id;
  ASSERT_EQ(server.service().wait_until_precomputed(gid, std::chrono::seconds(30))->status, GeometryStatus::kReady);
  for (uint32_t k = 1; k <= 2; ++k) {
    EXPECT_EQ(res_id_of(post(*c, base + "/results", wire::encode_request_json(pinned_push(static_cast<int>(k))), kJson)), k);
  }
  EXPECT_EQ(del(*c, base).status, 204);
  EXPECT_EQ(upload_json(*c, exact_grid(), 201), id);  // created again
  ASSERT_EQ(server.service().wait_until_precomputed(gid, std::chrono::seconds(30))->status, GeometryStatus::kReady);
  Reply list = get(*c, base + "/results");
  EXPECT_EQ(list.body, "{\"res_ids\":[]}");
  EXPECT_EQ(res_id_of(post(*c, base + "/results", wire::encode_request_json(pinned_push(3)), kJson)), 3u);
  Reply old = get(*c, base + "/results/1");
  EXPECT_EQ(old.status, 410);
  EXPECT_EQ(error_code(old), "gone");
  EXPECT_EQ(get(*c, base + "/results/4").status, 404);
}

TEST(HttpRetentionTest, DroppedResultsAre410NeverStoredAre404) {
  service::ServiceOptions so = test_service_options();
  so.retention.keep_results = 2;
  TestServer server(so);
  auto c = server.client();
  const std::string id = upload_json(*c, exact_grid());
  const std::string base = "/geometries/" + id;
  ASSERT_EQ(server.service().wait_until_precomputed(GeomId::from_hex(id).value(), std::chrono::seconds(30))->status,
            GeometryStatus::kReady);
  for (uint32_t k = 1; k <= 5; ++k) {
    EXPECT_EQ(res_id_of(post(*c, base + "/results", wire::encode_request_json(pinned_push(static_cast<int>(k))), kJson)), k);
  }
  EXPECT_EQ(get(*c, base + "/results").body, "{\"res_ids\":[4,5]}");
  for (const std::string& path : {base + "/results/1", base + "/results/3/request", base + "/results/2/stresses?level=1"}) {
    Reply r = get(*c, path);
    EXPECT_EQ(r.status, 410) << path << ": " << r.body;
    EXPECT_EQ(error_code(r), "gone") << path;
    EXPECT_NE(r.body.find("no longer kept"), std::string::npos) << r.body;
  }
  EXPECT_EQ(get(*c, base + "/results/5").status, 200);
  EXPECT_EQ(get(*c, base + "/results/4/request").status, 200);
  for (const std::string& path : {base + "/results/0", base + "/results/6", base + "/results/6/request"}) {
    Reply r = get(*c, path);
    EXPECT_EQ(r.status, 404) << path;
  }
  // The newest is what a long poll from an old id gets.
  EXPECT_EQ(res_id_of(get(*c, base + "/latest_result?have=1")), 5u);
  EXPECT_NE(get(*c, "/metrics").body.find("softshell_results_dropped_total 3"), std::string::npos);
}

}  // namespace
}  // namespace softshell
