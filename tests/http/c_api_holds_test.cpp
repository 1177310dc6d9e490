// The C ABI's holds and subscriptions (softshell_c.h), through an embedded session (wrapped) and a
// remote one (ss_session_create_remote): asynchronous puts polled to the answer, refusals with
// the server's message, releases, and a polled subscription that keeps a result that did not fit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <thread>

#include "session_test_support.h"
#include "softshell/softshell_c.h"
#include "softshell/softshell_c_bridge.h"

namespace softshell {
namespace {

using namespace test;

struct CRequest {
  ss_request* r = nullptr;
  CRequest() { EXPECT_EQ(ss_request_create(&r), SS_OK); }
  ~CRequest() { ss_request_destroy(r); }
};

void add_pins(ss_request* r) {
  const ss_vec3 zero{0, 0, 0};
  for (const auto& c : pinned_corners(4)) ASSERT_EQ(ss_request_add_vertex_constraint(r, c.index, 7, &zero), SS_OK);
}

// Polls a put until it is answered (the frame loop's way).
void poll_until_ready(ss_hold_put* op) {
  int32_t ready = 0;
  for (int i = 0; i < 4000 && !ready; ++i) {
    ASSERT_EQ(ss_hold_put_poll(op, &ready), SS_OK);
    if (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(ready, 1);
}

class CApiHoldsTest : public ::testing::TestWithParam<SessionKind> {
 protected:
  void SetUp() override {
    if (GetParam() == SessionKind::kEmbedded) {
      session = c_api::wrap_session(std::make_shared<EmbeddedSession>(server.service_ptr()));
    } else {
      ss_remote_options o;
      ss_remote_options_default(&o);
      o.binary = GetParam() == SessionKind::kRemoteBinary ? 1 : 0;
      ASSERT_EQ(ss_session_create_remote(server.url().c_str(), &o, &session), SS_OK) << ss_last_error_message();
    }
    RemoteSession uploader(server.url());
    const GeomId g = upload_ready(uploader, server);
    std::memcpy(id.bytes, g.bytes.data(), 16);
  }
  void TearDown() override { ss_session_destroy(session); }

  TestServer server;
  ss_session* session = nullptr;
  ss_geom_id id{};
};

TEST_P(CApiHoldsTest, PutPollReadReleaseAndSubscribe) {
  ss_subscription* sub = nullptr;
  ASSERT_EQ(ss_session_subscribe(session, &id, 0, &sub), SS_OK) << ss_last_error_message();
  int32_t state = -1;
  ASSERT_EQ(ss_subscription_state(sub, &state), SS_OK);
  EXPECT_EQ(state, SS_FEED_LIVE);

  CRequest pins;
  add_pins(pins.r);
  ss_hold_put* op = nullptr;
  ASSERT_EQ(ss_session_put_hold_begin(session, &id, "pins", pins.r, 10000, &op), SS_OK) << ss_last_error_message();
  poll_until_ready(op);
  uint32_t res_id = 0;
  uint64_t version = 0;
  std::vector<double> xyz(3 * 25);
  int32_t count = 0;
  ASSERT_EQ(ss_hold_put_read(op, &res_id, &version, xyz.data(), 25, &count), SS_OK) << ss_last_error_message();
  EXPECT_EQ(res_id, 1u);
  EXPECT_EQ(version, 1u);
  EXPECT_EQ(count, 25);
  ss_hold_put_destroy(op);

  // The subscription has it; a buffer too small keeps it for the next poll.
  int32_t has_new = 0;
  for (int i = 0; i < 4000 && ss_subscription_poll(sub, &has_new, &res_id, xyz.data(), 3, &count) == SS_OK; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_EQ(ss_subscription_poll(sub, &has_new, &res_id, xyz.data(), 3, &count), SS_BUFFER_TOO_SMALL);
  EXPECT_EQ(count, 25);
  ASSERT_EQ(ss_subscription_poll(sub, &has_new, &res_id, xyz.data(), 25, &count), SS_OK);
  EXPECT_EQ(has_new, 1);
  EXPECT_EQ(res_id, 1u);
  ASSERT_EQ(ss_subscription_poll(sub, &has_new, &res_id, xyz.data(), 25, &count), SS_OK);
  EXPECT_EQ(has_new, 0);

  // A conflicting hold: refused with the server's message naming the other hold.
  CRequest lift;
  const ss_vec3 up{0, 0, 0.1};
  ASSERT_EQ(ss_request_add_vertex_constraint(lift.r, grid_index(4, 0, 0), 4, &up), SS_OK);
  ASSERT_EQ(ss_session_put_hold_begin(session, &id, "lift", lift.r, 10000, &op), SS_OK);
  poll_until_ready(op);
  EXPECT_EQ(ss_hold_put_read(op, &res_id, &version, xyz.data(), 25, &count), SS_CONFLICT);
  EXPECT_NE(std::string(ss_last_error_message()).find("'pins'"), std::string::npos) << ss_last_error_message();
  ss_hold_put_destroy(op);

  // A put destroyed before it is answered finishes in the background.
  CRequest pushing;
  const ss_vec3 down{0, 0, -0.25};
  ASSERT_EQ(ss_request_add_force(pushing.r, grid_index(4, 2, 2), &down), SS_OK);
  ASSERT_EQ(ss_session_put_hold_begin(session, &id, "push", pushing.r, 10000, &op), SS_OK);
  ss_hold_put_destroy(op);
  GeomId g;
  std::memcpy(g.bytes.data(), id.bytes, 16);
  for (int i = 0; i < 1000 && !server.service().hold(g, "push"); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(server.service().hold(g, "push"));

  uint32_t released = 0;
  ASSERT_EQ(ss_session_release_hold(session, &id, "pins", &released), SS_CONFLICT)  // the push is left free
      << ss_last_error_message();
  EXPECT_EQ(ss_session_release_hold(session, &id, "pins", &released), SS_NOT_FOUND);
  EXPECT_EQ(ss_session_put_hold_begin(session, &id, "bad id!", pins.r, 10000, &op), SS_OK);  // refused in the answer
  poll_until_ready(op);
  EXPECT_EQ(ss_hold_put_read(op, &res_id, &version, xyz.data(), 25, &count), SS_INVALID_ARGUMENT);
  ss_hold_put_destroy(op);
  EXPECT_EQ(ss_session_put_hold_begin(session, &id, "pins", pins.r, 0, &op), SS_INVALID_ARGUMENT);
  ss_subscription_destroy(sub);

  ss_geom_id unknown{};
  EXPECT_EQ(ss_session_subscribe(session, &unknown, 0, &sub), SS_NOT_FOUND);
}

// The model through the C ABI: ss_request_set_model makes a hold (and a deformation) nonlinear,
// and ss_*_read_model says how the answer was solved; a bad model is refused with a message.
TEST_P(CApiHoldsTest, NonlinearModelOfHoldsAndDeformations) {
  CRequest r;
  int32_t model = -1;
  ASSERT_EQ(ss_request_model(r.r, &model), SS_OK);
  EXPECT_EQ(model, SS_MODEL_LINEAR);
  EXPECT_EQ(ss_request_set_model(r.r, 2), SS_INVALID_ARGUMENT);
  EXPECT_NE(std::string(ss_last_error_message()).find("SS_MODEL_NONLINEAR"), std::string::npos);
  add_pins(r.r);
  const ss_vec3 down{0, 0, -0.25};
  ASSERT_EQ(ss_request_add_force(r.r, grid_index(4, 2, 2), &down), SS_OK);
  ASSERT_EQ(ss_request_set_model(r.r, SS_MODEL_NONLINEAR), SS_OK);
  ASSERT_EQ(ss_request_model(r.r, &model), SS_OK);
  EXPECT_EQ(model, SS_MODEL_NONLINEAR);

  ss_hold_put* op = nullptr;
  ASSERT_EQ(ss_session_put_hold_begin(session, &id, "push", r.r, 10000, &op), SS_OK) << ss_last_error_message();
  poll_until_ready(op);
  uint32_t res_id = 0;
  std::vector<double> held(3 * 25), alone(3 * 25), linear(3 * 25);
  int32_t count = 0, iterations = 0;
  double residual = 1.0;
  ASSERT_EQ(ss_hold_put_read(op, &res_id, nullptr, held.data(), 25, &count), SS_OK) << ss_last_error_message();
  ASSERT_EQ(ss_hold_put_read_model(op, &model, &iterations, &residual), SS_OK) << ss_last_error_message();
  EXPECT_EQ(model, SS_MODEL_NONLINEAR);
  EXPECT_GE(iterations, 1);
  EXPECT_LT(residual, 1e-8);
  ss_hold_put_destroy(op);

  // The same request solved alone, nonlinear and linear.
  ss_deformation* d = nullptr;
  int32_t ready = 0;
  for (int32_t m : {SS_MODEL_NONLINEAR, SS_MODEL_LINEAR}) {
    ASSERT_EQ(ss_request_set_model(r.r, m), SS_OK);
    ASSERT_EQ(ss_session_deform_begin(session, &id, r.r, &d), SS_OK) << ss_last_error_message();
    ASSERT_EQ(ss_deformation_wait(d, 60000, &ready), SS_OK);
    ASSERT_EQ(ready, 1);
    std::vector<double>& out = m == SS_MODEL_NONLINEAR ? alone : linear;
    ASSERT_EQ(ss_deformation_read(d, &res_id, out.data(), 25, &count), SS_OK) << ss_last_error_message();
    ASSERT_EQ(ss_deformation_read_model(d, &model, &iterations, nullptr), SS_OK);
    EXPECT_EQ(model, m);
    if (m == SS_MODEL_LINEAR) {
      EXPECT_EQ(iterations, 0);
    }
    ss_deformation_destroy(d);
  }
  double same = 0.0, apart = 0.0;
  for (size_t i = 0; i < held.size(); ++i) {
    same = std::max(same, std::abs(held[i] - alone[i]));
    apart = std::max(apart, std::abs(held[i] - linear[i]));
  }
  EXPECT_LT(same, 1e-6);
  EXPECT_GT(apart, 1e-3);  // a push of 2.7 thicknesses: the nonlinear plate deflects less
}

INSTANTIATE_TEST_SUITE_P(Sessions, CApiHoldsTest,
                         ::testing::Values(SessionKind::kEmbedded, SessionKind::kRemoteBinary, SessionKind::kRemoteJson),
                         [](const auto& p) { return std::string(name_of(p.param)); });

}  // namespace
}  // namespace softshell
