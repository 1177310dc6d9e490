// EmbeddedSession and RemoteSession: the same script gives the same results through both.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdio>
#include <thread>

#include "http_test_support.h"
#include "softshell/embedded_session.h"
#include "softshell/remote_session.h"

namespace softshell {
namespace {

using namespace test;

// What a script observed through a session.
struct Transcript {
  std::vector<GeomId> ids;
  std::vector<bool> created;
  std::vector<DeformationResult> results;
  std::vector<uint32_t> history;
  std::optional<DeformationResult> latest;
  std::vector<LimitComb> combs;
  DeformationRequest replayed;
  Geometry echoed;
  std::vector<Error> errors;
};

// Uploads, deforms (synchronously and asynchronously, every request kind), reads back.
Transcript run_script(Session& s) {
  Transcript t;
  const ControlMesh grid = exact_grid(4);
  const ControlMesh nonquads = load_asset_mesh("catmark_nonquads.obj");
  for (const auto& [mesh, ns] : {std::pair{grid, std::string()}, std::pair{grid, std::string("team")},
                                 std::pair{nonquads, std::string()}, std::pair{grid, std::string()}}) {
    auto up = s.upload(mesh, exact_material(), ns);
    EXPECT_TRUE(up) << up.error().message;
    t.ids.push_back(up->id);
    t.created.push_back(up->created);
  }
  const GeomId id = t.ids[0];

  t.results.push_back(s.deform(id, pinned_push(1)).value());
  DeformationRequest limit;
  limit.vertex_constraints = pinned_corners(4);
  limit.limit_constraints.push_back({{5, 0, 0.25, 0.75}, Vec3(0, 0, 0.0625), {}, {}});  // JSON-only
  t.results.push_back(s.deform(id, limit).value());
  DeformationRequest loads;
  loads.vertex_constraints = pinned_corners(4);
  loads.surface_load = Vec3(0, 0, -2);
  loads.pressure = 0.5;
  t.results.push_back(s.deform(id, loads).value());
  auto async = s.deform_async(id, pinned_push(3));
  t.results.push_back(async.get().value());

  DeformationRequest lagrange;
  lagrange.vertex_constraints = pinned_corners(4);
  const LimitComb comb = s.limit_comb(id, {6, 0, 0.5, 0.5}).value();
  LagrangeConstraint c;
  c.indices = comb.indices;
  for (double w : comb.position) c.coefficients.push_back(Vec3(w, w, w));
  c.values = Vec3(0, 0, 0.125);
  lagrange.lagrange_constraints.push_back(c);
  t.results.push_back(s.deform(id, lagrange).value());

  t.history = s.result_ids(id).value();
  t.latest = s.latest_result(id, 2, Ms(0)).value();
  t.combs.push_back(s.limit_comb(id, {3, 0, 0.5, 0.25}).value());
  t.combs.push_back(s.limit_comb(t.ids[2], {0, 2, 0.75, 0.5}).value());
  t.replayed = s.result_request(id, 3).value();
  t.echoed = s.geometry(t.ids[1]).value();

  // Errors are values with the same codes.
  DeformationRequest free_body;
  free_body.forces.push_back({12, Vec3(0, 0, 1)});
  t.errors.push_back(s.deform(id, free_body).error());
  t.errors.push_back(s.result(id, 99).error());
  t.errors.push_back(s.limit_comb(id, {0, 0, 2.0, 0.5}).error());
  t.errors.push_back(s.deform(GeomId{}, pinned_push(1)).error());
  Material soft = exact_material();
  soft.poisson_ratio = 0.5;
  t.errors.push_back(s.upload(grid, soft).error());
  return t;
}

void expect_same(const Transcript& a, const Transcript& b, bool f32_results) {
  ASSERT_EQ(a.ids, b.ids);
  EXPECT_EQ(a.created, b.created);
  ASSERT_EQ(a.results.size(), b.results.size());
  for (size_t k = 0; k < a.results.size(); ++k) {
    EXPECT_EQ(a.results[k].res_id, b.results[k].res_id);
    ASSERT_EQ(a.results[k].positions.size(), b.results[k].positions.size());
    for (size_t i = 0; i < a.results[k].positions.size(); ++i) {
      for (int x = 0; x < 3; ++x) {
        const double expected = f32_results ? static_cast<double>(static_cast<float>(a.results[k].positions[i][x]))
                                            : a.results[k].positions[i][x];
        if (f32_results && k == 4) {
          // The Lagrange request was built from binary (f32) limit_comb weights and sent as f32:
          // its inputs differ from the embedded run's by f32 rounding, so its result does too.
          EXPECT_NEAR(b.results[k].positions[i][x], expected, 1e-6) << "result " << k << ", control point " << i;
        } else {
          EXPECT_EQ(b.results[k].positions[i][x], expected) << "result " << k << ", control point " << i;
        }
      }
    }
  }
  EXPECT_EQ(a.history, b.history);
  ASSERT_TRUE(a.latest && b.latest);
  EXPECT_EQ(a.latest->res_id, b.latest->res_id);
  ASSERT_EQ(a.combs.size(), b.combs.size());
  for (size_t k = 0; k < a.combs.size(); ++k) {
    EXPECT_EQ(a.combs[k].point, b.combs[k].point);
    EXPECT_EQ(a.combs[k].indices, b.combs[k].indices);
    for (size_t i = 0; i < a.combs[k].position.size(); ++i) {
      if (f32_results) {
        EXPECT_EQ(b.combs[k].position[i], static_cast<double>(static_cast<float>(a.combs[k].position[i])));
      } else {
        EXPECT_EQ(b.combs[k].position[i], a.combs[k].position[i]);
        EXPECT_EQ(b.combs[k].du[i], a.combs[k].du[i]);
        EXPECT_EQ(b.combs[k].dv[i], a.combs[k].dv[i]);
      }
    }
  }
  EXPECT_EQ(wire::encode_request_json(a.replayed), wire::encode_request_json(b.replayed));
  EXPECT_EQ(a.echoed.mesh, b.echoed.mesh);
  EXPECT_EQ(a.echoed.name_space, b.echoed.name_space);
  ASSERT_EQ(a.errors.size(), b.errors.size());
  for (size_t k = 0; k < a.errors.size(); ++k) {
    EXPECT_EQ(a.errors[k].code, b.errors[k].code) << k << ": " << a.errors[k].message << " / " << b.errors[k].message;
    EXPECT_EQ(a.errors[k].message, b.errors[k].message);
  }
}

TEST(EmbeddedSessionTest, SameScriptSameResultsEmbeddedAndRemote) {
  EmbeddedSession embedded(test_service_options());
  const Transcript reference = run_script(embedded);
  EXPECT_EQ(reference.created, (std::vector<bool>{true, true, true, false}));
  EXPECT_EQ(reference.history, (std::vector<uint32_t>{1, 2, 3, 4, 5}));
  EXPECT_EQ(reference.latest->res_id, 5u);
  EXPECT_EQ(reference.errors[0].code, ErrorCode::kUnprocessable);
  EXPECT_EQ(reference.errors[1].code, ErrorCode::kNotFound);
  EXPECT_EQ(reference.errors[2].code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(reference.errors[3].code, ErrorCode::kNotFound);
  EXPECT_EQ(reference.errors[4].code, ErrorCode::kUnprocessable);

  {
    TestServer server;
    RemoteSessionOptions json;
    json.format = wire::Format::kJson;
    RemoteSession remote(server.url(), json);
    SCOPED_TRACE("remote, JSON");
    expect_same(reference, run_script(remote), /*f32_results=*/false);
  }
  {
    TestServer server;
    RemoteSession remote(server.url());  // binary by default
    SCOPED_TRACE("remote, binary");
    expect_same(reference, run_script(remote), /*f32_results=*/true);
  }
}

TEST(EmbeddedSessionTest, ListenerLetsOtherDevicesJoin) {
  EmbeddedSession app(test_service_options());
  auto port = app.listen("127.0.0.1", 0);
  ASSERT_TRUE(port) << port.error().message;
  EXPECT_EQ(app.port(), *port);
  EXPECT_FALSE(app.listen("127.0.0.1", 0));  // open already

  const GeomId id = app.upload(exact_grid(), exact_material()).value().id;
  auto device = RemoteSession::connect("http://127.0.0.1:" + std::to_string(*port));
  ASSERT_TRUE(device) << device.error().message;
  // The device sees the app's geometry and deforms it; the app's long poll sees the result.
  std::optional<DeformationResult> seen;
  std::thread follower([&] { seen = app.latest_result(id, 0, Ms(20000)).value(); });
  auto r = (*device)->deform(id, pinned_push(2));
  ASSERT_TRUE(r) << r.error().message;
  follower.join();
  ASSERT_TRUE(seen);
  EXPECT_EQ(seen->res_id, r->res_id);
  auto info = (*device)->geometry_info(id);
  ASSERT_TRUE(info);
  EXPECT_EQ(info->status, GeometryStatus::kReady);
  EXPECT_EQ(info->results, 1u);
  device->reset();

  app.stop_listening();
  EXPECT_EQ(app.port(), 0);
  EXPECT_TRUE(app.deform(id, pinned_push(1)));  // still works in-process
  EXPECT_FALSE(RemoteSession::connect("http://127.0.0.1:" + std::to_string(*port)));
}

// Whether a TCP connection to `address:port` (IPv4, in network order) is accepted.
bool accepts(in_addr address, int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port));
  to.sin_addr = address;
  const bool ok = ::connect(fd, reinterpret_cast<const sockaddr*>(&to), sizeof to) == 0;
  ::close(fd);
  return ok;
}

// listen() with its defaults binds 127.0.0.1 only, as softshell-server does: the port is closed
// on every other address of this machine. With ServerOptions::auth_token it wants the token.
TEST(EmbeddedSessionTest, ListenDefaultsToLoopbackAndTakesAToken) {
  EmbeddedSession app(test_service_options());
  auto port = app.listen();
  ASSERT_TRUE(port) << port.error().message;
  in_addr loopback{};
  loopback.s_addr = htonl(INADDR_LOOPBACK);
  EXPECT_TRUE(accepts(loopback, *port));
  int others = 0;
  ifaddrs* list = nullptr;
  ASSERT_EQ(::getifaddrs(&list), 0);
  for (const ifaddrs* a = list; a; a = a->ifa_next) {
    if (!a->ifa_addr || a->ifa_addr->sa_family != AF_INET) continue;
    const in_addr address = reinterpret_cast<const sockaddr_in*>(a->ifa_addr)->sin_addr;
    if ((ntohl(address.s_addr) >> 24) == 127) continue;
    ++others;
    char text[INET_ADDRSTRLEN] = {};
    ::inet_ntop(AF_INET, &address, text, sizeof text);
    EXPECT_FALSE(accepts(address, *port)) << "the default listener answers on " << text;
  }
  ::freeifaddrs(list);
  if (others == 0) std::printf("note: no non-loopback IPv4 address here; only 127.0.0.1 was checked\n");

  EmbeddedSession shared(test_service_options());
  http::ServerOptions options;
  options.auth_token = "embedded-token-0123456789";
  auto shared_port = shared.listen("127.0.0.1", 0, options);
  ASSERT_TRUE(shared_port) << shared_port.error().message;
  const std::string url = "http://127.0.0.1:" + std::to_string(*shared_port);
  const GeomId id = shared.upload(exact_grid(), exact_material()).value().id;
  auto anonymous = RemoteSession::connect(url);
  ASSERT_TRUE(anonymous) << anonymous.error().message;
  auto refused = (*anonymous)->geometry_info(id);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("auth_token"), std::string::npos) << refused.error().message;
  RemoteSessionOptions with;
  with.auth_token = options.auth_token;
  auto device = RemoteSession::connect(url, with);
  ASSERT_TRUE(device) << device.error().message;
  auto info = (*device)->geometry_info(id);
  ASSERT_TRUE(info) << info.error().message;
  // A token the server would refuse is refused by listen().
  EmbeddedSession weak(test_service_options());
  http::ServerOptions short_token;
  short_token.auth_token = "short";
  EXPECT_FALSE(weak.listen("127.0.0.1", 0, short_token));
}

TEST(EmbeddedSessionTest, AsyncDeformationNeverBlocksTheCaller) {
  EmbeddedSession session(test_service_options());
  // deform_async right after the upload: the precomputation is still running.
  const GeomId id = session.upload(make_grid(32, 32), exact_material()).value().id;
  const auto start = std::chrono::steady_clock::now();
  auto future = session.deform_async(id, pinned_push(1, 32));
  EXPECT_LT(seconds_since(start), 0.05);  // returned at once
  ASSERT_EQ(future.wait_for(std::chrono::seconds(60)), std::future_status::ready);
  auto r = future.get();
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->res_id, 1u);
}

}  // namespace
}  // namespace softshell
