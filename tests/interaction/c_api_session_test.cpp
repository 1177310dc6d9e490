// The session half of the C ABI (upload, blocking and asynchronous deformation, latest result,
// destroying running operations) against a scripted test double, plus the bridge used by the
// embedded server library. The whole-session test through a real server is c_api_session_test.c.

#include <atomic>
#include <cmath>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "scripted_session.h"
#include "softshell/softshell_c.h"
#include "softshell/softshell_c_bridge.h"

namespace softshell {
namespace {

ss_mesh* grid_mesh() {
  const double xyz[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const int32_t sizes[] = {4};
  const int32_t indices[] = {0, 1, 2, 3};
  ss_mesh* mesh = nullptr;
  EXPECT_EQ(ss_mesh_create(xyz, 4, sizes, 1, indices, 4, &mesh), SS_OK);
  return mesh;
}

TEST(CApiSession, AsynchronousDeformationNeverBlocks) {
  auto scripted = std::make_shared<test::ScriptedSession>();
  ss_session* session = c_api::wrap_session(scripted);
  ss_mesh* mesh = grid_mesh();
  const ss_material material{6.9e10, 0.33, 0.001, 2700};
  ss_geom_id id{};
  int32_t created = -1;
  ASSERT_EQ(ss_session_upload(session, mesh, &material, "ns", &id, &created), SS_OK);
  EXPECT_EQ(created, 1);
  EXPECT_EQ(id.bytes[0], 1);

  ss_request* request = nullptr;
  ASSERT_EQ(ss_request_create(&request), SS_OK);
  const ss_vec3 d{0, 0, 0.1};
  ASSERT_EQ(ss_request_add_vertex_constraint(request, 2, 4, &d), SS_OK);
  ss_deformation* op = nullptr;
  ASSERT_EQ(ss_session_deform_begin(session, &id, request, &op), SS_OK);
  ss_request_destroy(request);  // the operation copied it
  ASSERT_EQ(scripted->calls(), 1u);
  EXPECT_EQ(scripted->request(0).vertex_constraints.at(0).index, 2);

  int32_t ready = -1;
  ASSERT_EQ(ss_deformation_poll(op, &ready), SS_OK);
  EXPECT_EQ(ready, 0);
  ASSERT_EQ(ss_deformation_wait(op, 1, &ready), SS_OK);
  EXPECT_EQ(ready, 0);
  uint32_t res_id = 0;
  int32_t count = -1;
  double xyz[12];
  EXPECT_EQ(ss_deformation_read(op, &res_id, xyz, 4, &count), SS_NOT_READY);
  EXPECT_NE(std::strstr(ss_last_error_message(), "still running"), nullptr);

  scripted->finish(0);
  ASSERT_EQ(ss_deformation_poll(op, &ready), SS_OK);
  EXPECT_EQ(ready, 1);
  ASSERT_EQ(ss_deformation_read(op, &res_id, nullptr, 0, &count), SS_OK);  // size query
  EXPECT_EQ(count, 4);
  EXPECT_EQ(ss_deformation_read(op, &res_id, xyz, 3, &count), SS_BUFFER_TOO_SMALL);
  ASSERT_EQ(ss_deformation_read(op, &res_id, xyz, 4, &count), SS_OK);
  EXPECT_EQ(res_id, 1u);
  EXPECT_EQ(xyz[9], 3.0);  // position 3 = (3, 0, 0)
  ASSERT_EQ(ss_deformation_read(op, &res_id, xyz, 4, &count), SS_OK);  // repeatable
  ss_deformation_destroy(op);

  // A failed request reports its own status and message.
  ASSERT_EQ(ss_request_create(&request), SS_OK);
  ASSERT_EQ(ss_session_deform_begin(session, &id, request, &op), SS_OK);
  scripted->finish(1, false);
  EXPECT_EQ(ss_deformation_read(op, &res_id, xyz, 4, &count), SS_UNPROCESSABLE);
  EXPECT_NE(std::strstr(ss_last_error_message(), "rigid-body"), nullptr);
  ss_deformation_destroy(op);

  // Latest result: the newest one after `have`, none when up to date.
  int32_t has_new = -1;
  ASSERT_EQ(ss_session_latest_result(session, &id, 0, 0, &has_new, &res_id, xyz, 4, &count), SS_OK);
  EXPECT_EQ(has_new, 1);
  EXPECT_EQ(res_id, 1u);
  ASSERT_EQ(ss_session_latest_result(session, &id, 1, 0, &has_new, &res_id, xyz, 4, &count), SS_OK);
  EXPECT_EQ(has_new, 0);

  // Blocking deform.
  ASSERT_EQ(ss_session_deform(session, &id, request, &res_id, xyz, 4, &count), SS_OK);
  EXPECT_EQ(res_id, 3u);
  EXPECT_EQ(xyz[4], 2.0);  // position 1 = (1, 2, 0) for call 2

  // Destroying a running operation and then the session does not block; the request still
  // completes later without touching freed memory.
  ASSERT_EQ(ss_session_deform_begin(session, &id, request, &op), SS_OK);
  ss_deformation_destroy(op);
  ss_session_destroy(session);
  scripted->finish(3);
  // A later begin (on another session) purges finished orphans.
  ss_session* other = c_api::wrap_session(scripted);
  ASSERT_EQ(ss_session_deform_begin(other, &id, request, &op), SS_OK);
  scripted->finish(4);
  ss_deformation_destroy(op);
  ss_session_destroy(other);

  // Bad arguments.
  EXPECT_EQ(ss_session_upload(nullptr, mesh, &material, nullptr, &id, nullptr), SS_INVALID_ARGUMENT);
  EXPECT_EQ(ss_deformation_wait(nullptr, 0, &ready), SS_INVALID_ARGUMENT);
  ss_request_destroy(request);
  ss_mesh_destroy(mesh);
}

TEST(CApiSession, GuardMapsEveryFailureToAStatus) {
  EXPECT_EQ(c_api::guard("f", [] {}), SS_OK);
  EXPECT_STREQ(ss_last_error_message(), "");
  EXPECT_EQ(c_api::guard("f", [] { throw Exception(ErrorCode::kNotFound, "no such geometry"); }), SS_NOT_FOUND);
  EXPECT_STREQ(ss_last_error_message(), "f: no such geometry");
  EXPECT_EQ(c_api::guard("g", [] { throw std::bad_alloc(); }), SS_RESOURCE_EXHAUSTED);
  EXPECT_EQ(c_api::guard("h", [] { throw std::runtime_error("boom"); }), SS_INTERNAL);
  EXPECT_NE(std::strstr(ss_last_error_message(), "boom"), nullptr);
  EXPECT_EQ(c_api::guard("i", [] { throw 42; }), SS_INTERNAL);
  EXPECT_THROW(c_api::wrap_session(nullptr), Exception);
  // The message is per thread.
  std::string other;
  std::thread([&] { other = ss_last_error_message(); }).join();
  EXPECT_EQ(other, "");
}

// Operations destroyed while running finish in the background; a failure nobody read is logged.
TEST(CApiSession, FailuresOfDestroyedOperationsAreLogged) {
  static std::mutex mutex;
  static std::vector<std::string> logged;
  auto on_log = [](int32_t level, const char* message, void*) {
    std::lock_guard lock(mutex);
    if (level == SS_LOG_WARNING) logged.emplace_back(message);
  };
  ASSERT_EQ(ss_set_log_callback(on_log, nullptr, SS_LOG_DEBUG), SS_OK);
  auto scripted = std::make_shared<test::ScriptedSession>();
  ss_session* session = c_api::wrap_session(scripted);
  ss_request* request = nullptr;
  ASSERT_EQ(ss_request_create(&request), SS_OK);
  const ss_geom_id id{};
  ss_deformation* op = nullptr;
  ASSERT_EQ(ss_session_deform_begin(session, &id, request, &op), SS_OK);
  ss_deformation_destroy(op);  // still running: adopted
  scripted->finish(0, false);
  ASSERT_EQ(ss_session_deform_begin(session, &id, request, &op), SS_OK);  // purges the finished orphan
  scripted->finish(1);
  ss_deformation_destroy(op);
  ss_request_destroy(request);
  ss_session_destroy(session);
  ASSERT_EQ(ss_set_log_callback(nullptr, nullptr, SS_LOG_OFF), SS_OK);
  std::lock_guard lock(mutex);
  ASSERT_EQ(logged.size(), 1u);
  EXPECT_NE(logged[0].find("destroyed before it was read failed"), std::string::npos) << logged[0];
  EXPECT_NE(logged[0].find("rigid-body"), std::string::npos) << logged[0];
}

// The handle table from several threads at once (also run under ThreadSanitizer): handles made,
// used and destroyed concurrently, one shared handle read by all, and one destroyed while the
// others use it: every call answers SS_OK or "destroyed", none crashes or sees another's object.
TEST(CApiSession, HandlesAcrossThreads) {
  ss_mesh* shared = grid_mesh();
  ss_request* doomed = nullptr;
  ASSERT_EQ(ss_request_create(&doomed), SS_OK);
  std::atomic<int> bad{0};
  std::atomic<bool> destroyed{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      const ss_vec3 d{0, 0, double(t)};
      for (int k = 0; k < 500; ++k) {
        ss_request* mine = nullptr;
        if (ss_request_create(&mine) != SS_OK) ++bad;
        for (int c = 0; c <= k % 3; ++c) {
          if (ss_request_add_vertex_constraint(mine, t, 4, &d) != SS_OK) ++bad;
        }
        int32_t vertex_constraints = -1;
        if (ss_request_counts(mine, &vertex_constraints, nullptr, nullptr, nullptr, nullptr) != SS_OK ||
            vertex_constraints != k % 3 + 1) {
          ++bad;
        }
        int32_t nv = 0, nf = 0;
        if (ss_mesh_counts(shared, &nv, &nf) != SS_OK || nv != 4 || nf != 1) ++bad;
        const ss_status s = ss_request_counts(doomed, &vertex_constraints, nullptr, nullptr, nullptr, nullptr);
        if (s != SS_OK && !(s == SS_INVALID_ARGUMENT && destroyed && std::strstr(ss_last_error_message(), "destroyed"))) {
          ++bad;
        }
        if (t == 0 && k == 250) {
          destroyed = true;
          ss_request_destroy(doomed);
        }
        ss_request_destroy(mine);
        if (ss_request_counts(mine, &vertex_constraints, nullptr, nullptr, nullptr, nullptr) != SS_INVALID_ARGUMENT) ++bad;
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(bad.load(), 0);
  EXPECT_EQ(ss_request_clear(doomed), SS_INVALID_ARGUMENT);
  ss_mesh_destroy(shared);
}

}  // namespace
}  // namespace softshell
