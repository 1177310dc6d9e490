// The bridge against a real server over 127.0.0.1 whose deformation requests are slow: the
// physics loop must not wait, and the latest-wins queue must not grow.
//
// How the server is slowed: the real server (an EmbeddedSession with its HTTP listener open) sits
// behind a small proxy in this test that holds every `POST /geometries/{id}/results` for kDelay
// before forwarding it; every other request passes straight through. The RemoteSession talks to
// the proxy. Nothing in the product code is slowed or stubbed.

#include <chrono>
#include <cmath>
#include <thread>

#include <gtest/gtest.h>

#include "bullet_world.h"
#include "softshell/bullet/shell_bridge.h"
#include "softshell/embedded_session.h"
#include "softshell/remote_session.h"
#include "test_meshes.h"

// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks Eigen headers included after it.
#include <httplib.h>

namespace softshell::bullet {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr auto kDelay = 100ms;

// Forwards every request to 127.0.0.1:`upstream`, deformation requests after `delay`.
class SlowProxy {
 public:
  SlowProxy(int upstream, std::chrono::milliseconds delay) : upstream_(upstream) {
    server_.Post(R"(/geometries/[0-9a-fA-F]+/results)", [this, delay](const httplib::Request& req, httplib::Response& res) {
      std::this_thread::sleep_for(delay);
      ++delayed_;
      forward(req, res);
    });
    server_.Get(".*", [this](const httplib::Request& req, httplib::Response& res) { forward(req, res); });
    server_.Post(".*", [this](const httplib::Request& req, httplib::Response& res) { forward(req, res); });
    port_ = server_.bind_to_any_port("127.0.0.1");
    thread_ = std::thread([this] { server_.listen_after_bind(); });
    while (!server_.is_running()) std::this_thread::sleep_for(std::chrono::milliseconds(1));  // httplib 0.11: no wait_until_ready
  }
  ~SlowProxy() {
    server_.stop();
    thread_.join();
  }
  int port() const { return port_; }
  int delayed() const { return delayed_; }

 private:
  void forward(const httplib::Request& req, httplib::Response& res) const {
    httplib::Client client("127.0.0.1", upstream_);
    httplib::Headers headers;
    for (const char* name : {"Accept", "Content-Type"}) {
      if (req.has_header(name)) headers.emplace(name, req.get_header_value(name));
    }
    const std::string type = req.get_header_value("Content-Type");
    auto reply = req.method == "POST" ? client.Post(req.target, headers, req.body, type) : client.Get(req.target, headers);
    if (!reply) {
      res.status = 502;
      return;
    }
    res.status = reply->status;
    res.set_content(reply->body, reply->get_header_value("Content-Type"));
  }

  int upstream_;
  httplib::Server server_;
  std::thread thread_;
  int port_ = 0;
  std::atomic<int> delayed_{0};
};

TEST(ShellBridgeRemote, SlowServerNeverStallsThePhysicsLoopAndTheQueueStaysAtTwo) {
  // The real server, its HTTP API on an ephemeral port, and the slowing proxy in front of it.
  auto server = std::make_shared<EmbeddedSession>();
  const auto port = server->listen("127.0.0.1", 0);
  ASSERT_TRUE(port.ok()) << port.error().message;
  SlowProxy proxy(*port, kDelay);
  auto remote = RemoteSession::connect("http://127.0.0.1:" + std::to_string(proxy.port()));
  ASSERT_TRUE(remote.ok()) << remote.error().message;
  std::shared_ptr<Session> session = std::move(*remote);

  // A plate with fixed edges (as in shell_bridge_test), uploaded and warmed up (precomputation
  // and factorization done) before the clock starts.
  constexpr int kN = 12;
  const ControlMesh mesh = test::make_grid(kN, kN, 1.0, 1.0);
  ShellSettings settings;
  settings.mesh.level = 2;
  settings.holds.enabled = false;  // requests solved alone: the proxy slows POST .../results (and passes no PUT or stream)
  settings.transform.setIdentity();
  settings.transform.setOrigin(btVector3(-0.5f, -0.5f, 0.0f));
  for (int j = 0; j <= kN; ++j) {
    for (int i = 0; i <= kN; ++i) {
      if (i == 0 || j == 0 || i == kN || j == kN) {
        settings.supports.vertex_constraints.push_back({test::grid_index(kN, i, j), kAxisAll, Vec3::Zero()});
      }
    }
  }
  const auto uploaded = session->upload(mesh, Material{2.0e9, 0.35, 0.005, 1200.0}, "bullet-slow-server");
  ASSERT_TRUE(uploaded.ok()) << uploaded.error().message;
  ASSERT_TRUE(session->deform(uploaded->id, settings.supports).ok());

  test::BulletWorld scene;
  ShellBridge bridge(scene.world);
  const ShellId shell = bridge.add_shell(session, uploaded->id, mesh, settings).value();
  btRigidBody* sphere = scene.add_sphere(0.05, 1.0, btVector3(0.0f, 0.0f, 0.08f));
  sphere->setActivationState(DISABLE_DEACTIVATION);

  // 1.5 s of physics at 120 Hz in real time; every step's stepSimulation + update is timed.
  const float dt = 1.0f / 120.0f;
  const int steps = 180;
  double total_ms = 0.0, worst_ms = 0.0;
  uint32_t max_depth = 0;
  auto next = Clock::now();
  const auto start = next;
  for (int step = 0; step < steps; ++step) {
    next += std::chrono::microseconds(8333);
    std::this_thread::sleep_until(next);
    const auto t0 = Clock::now();
    scene.world.stepSimulation(dt, 1, dt);
    bridge.update();
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    total_ms += ms;
    worst_ms = std::max(worst_ms, ms);
    max_depth = std::max(max_depth, bridge.stats(shell).channel.max_depth);
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  const ShellStats stats = bridge.stats(shell);
  const double mean_ms = total_ms / steps;
  std::printf("slow server (%lld ms per deformation): stepSimulation + update %.3f ms mean, %.3f ms worst; "
              "%s submitted, %s sent, %s replaced, %s results shown, max depth %u\n",
              static_cast<long long>(kDelay.count()), mean_ms, worst_ms, std::to_string(stats.channel.submitted).c_str(),
              std::to_string(stats.channel.sent).c_str(), std::to_string(stats.channel.replaced).c_str(),
              std::to_string(stats.results_applied).c_str(), max_depth);

  // The loop never waited for the server.
  EXPECT_LT(mean_ms, 1.0);
  // Latest wins: at most one request in flight and one waiting; the frames in between replaced
  // the waiting one instead of queueing; requests went out no faster than the server answered.
  EXPECT_LE(max_depth, 2u);
  EXPECT_GT(stats.channel.replaced, 0u);
  EXPECT_LE(static_cast<double>(stats.channel.sent), seconds / std::chrono::duration<double>(kDelay).count() + 2.0);
  EXPECT_GE(stats.channel.submitted, stats.channel.sent + stats.channel.replaced);
  // And the results still came back and were shown.
  EXPECT_GT(stats.results_applied, 0u);
  EXPECT_EQ(stats.channel.failed, 0u);
  EXPECT_FALSE(stats.last_error) << stats.last_error->message;

  // Settled: the dent the server computed for the sphere's weight is what the shell shows.
  ASSERT_TRUE(bridge.wait_idle(10s).ok());
  const DeformationRequest* sent = bridge.last_sent_request(shell);
  ASSERT_NE(sent, nullptr);
  Vec3 total = Vec3::Zero();
  for (const PointForce& f : sent->forces) total += f.force;
  EXPECT_NEAR(total.z(), -9.81, 0.05 * 9.81);
  const size_t centre = size_t(test::grid_index(kN, kN / 2, kN / 2));
  EXPECT_LT(bridge.control_positions(shell)[centre].z(), -1e-4);
  EXPECT_GT(proxy.delayed(), 0);
}

}  // namespace
}  // namespace softshell::bullet
