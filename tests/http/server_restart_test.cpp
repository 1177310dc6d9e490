// softshell-server --data-dir: kill -9 while 8 clients post deformations, restart on the same
// directory, and every result answered 200 is there with the same id and bytes; a clean restart
// restores everything; a deleted geometry's ids continue after a restart when its content is
// uploaded again; a damaged store or a directory another server holds is refused.
#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <map>
#include <mutex>
#include <thread>

#include "child_process.h"
#include "http_test_support.h"
#include "temp_dir.h"

namespace softshell {
namespace {

using namespace test;

// A server on `dir`; its port once it listens (0 if it did not start).
struct Server {
  explicit Server(const std::string& dir)
      : child({SOFTSHELL_SERVER_EXE, "--port=0", "--threads=1", "--solve-threads=2", "--cache-mb=64",
               "--store-mb=256", "--log-level=warning", "--data-dir", dir}) {
    const std::string out = child.read_until("\n", std::chrono::seconds(60));
    if (out.find("softshell-server listening on http://127.0.0.1:") != std::string::npos) {
      port = port_of(out.substr(0, out.find('\n')));
    }
  }
  Child child;
  int port = 0;
};

// What a client saw of one result: the POST's answer and GETs of the result in both layouts and
// of its request.
struct Seen {
  std::string posted, json, binary, request;
};

std::string path_of(const std::string& geom, uint32_t k) { return "/geometries/" + geom + "/results/" + std::to_string(k); }

// GET bodies of result k (json, binary, request); empty strings where a GET failed.
Seen fetch(httplib::Client& c, const std::string& geom, uint32_t k) {
  Seen s;
  auto get_body = [&](const std::string& path, const char* accept) {
    auto r = c.Get(path, httplib::Headers{{"Accept", accept}});
    return r && r->status == 200 ? r->body : std::string();
  };
  s.json = get_body(path_of(geom, k), kJson);
  s.binary = get_body(path_of(geom, k), kBin);
  s.request = get_body(path_of(geom, k) + "/request", kJson);
  return s;
}

std::string upload(int port, const ControlMesh& mesh) {
  httplib::Client c("127.0.0.1", port);
  const Reply up = post(c, "/geometries", wire::encode_geometry_json(mesh, exact_material()), kJson, kJson);
  EXPECT_TRUE(up.status == 201 || up.status == 200) << up.body;
  return wire::decode_upload_response_json(up.body, true).value().id.hex();
}

std::vector<uint32_t> ids_of(int port, const std::string& geom) {
  httplib::Client c("127.0.0.1", port);
  const Reply r = get(c, "/geometries/" + geom + "/results");
  EXPECT_EQ(r.status, 200) << r.body;
  return wire::decode_result_ids_json(r.body).value();
}

TEST(ServerRestartTest, KillDuringPostsLosesNothingAnswered) {
  TempDir dir("softshell-restart");
  std::optional<Server> server(std::in_place, dir.path);
  ASSERT_GT(server->port, 0) << server->child.drain_stderr();
  const int port = server->port;
  const std::string geom = upload(port, exact_grid(8));
  const std::string other = upload(port, exact_grid(4));  // a geometry without results comes back too

  constexpr int kClients = 8;
  std::mutex mu;
  std::map<uint32_t, Seen> answered;  // res_id -> what its client saw
  std::atomic<int> count{0}, duplicates{0};
  std::atomic<bool> stop{false};
  std::vector<std::thread> clients;
  for (int t = 0; t < kClients; ++t) {
    clients.emplace_back([&, t] {
      httplib::Client c("127.0.0.1", port);
      c.set_connection_timeout(5);
      c.set_read_timeout(30);
      for (int k = 1; !stop.load(); ++k) {
        const std::string body = wire::encode_request_json(pinned_push(100 * t + k, 8));
        auto r = c.Post("/geometries/" + geom + "/results", httplib::Headers{{"Accept", kJson}}, body, kJson);
        if (!r) return;  // the server is gone
        if (r->status != 200) continue;
        const uint32_t id = wire::decode_result_json(r->body).value().res_id;
        Seen seen = fetch(c, geom, id);
        seen.posted = r->body;
        std::lock_guard lock(mu);
        if (!answered.emplace(id, std::move(seen)).second) duplicates.fetch_add(1);
        count.fetch_add(1);
      }
    });
  }
  // Kill -9 mid-stream, once enough results were answered.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (count.load() < 80 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  kill(server->child.pid(), SIGKILL);
  EXPECT_EQ(server->child.wait(std::chrono::seconds(10)), 128 + SIGKILL);
  stop.store(true);
  for (auto& c : clients) c.join();
  ASSERT_GE(count.load(), 80) << "the clients were too slow to reach the kill";
  EXPECT_EQ(duplicates.load(), 0);

  server.emplace(dir.path);
  ASSERT_GT(server->port, 0) << server->child.drain_stderr();
  httplib::Client c("127.0.0.1", server->port);
  // The geometries, in upload order.
  const Reply list = get(c, "/geometries");
  const auto infos = wire::decode_geometry_list_json(list.body).value();
  ASSERT_EQ(infos.size(), 2u);
  EXPECT_EQ(infos[0].id.hex(), geom);
  EXPECT_EQ(infos[1].id.hex(), other);
  EXPECT_EQ(infos[1].results, 0u);

  // Ids 1..n with no gap: every answered one, and perhaps a few whose POST was cut by the kill.
  const std::vector<uint32_t> ids = ids_of(server->port, geom);
  ASSERT_FALSE(ids.empty());
  for (size_t i = 0; i < ids.size(); ++i) ASSERT_EQ(ids[i], i + 1);
  ASSERT_GE(ids.size(), answered.rbegin()->first);
  std::cout << "[ restart ] " << answered.size() << " results answered 200 before kill -9, " << ids.size()
            << " restored (" << ids.size() - answered.size() << " stored but unanswered when it died)\n";
  for (const auto& [id, seen] : answered) {
    const Seen now = fetch(c, geom, id);
    EXPECT_EQ(now.json, seen.posted) << "result " << id;
    if (!seen.json.empty()) {
      EXPECT_EQ(now.json, seen.json) << "result " << id;
    }
    if (!seen.binary.empty()) {
      EXPECT_EQ(now.binary, seen.binary) << "result " << id;
    }
    if (!seen.request.empty()) {
      EXPECT_EQ(now.request, seen.request) << "result " << id;
    }
  }
  // The next result continues the ids (it waits for the background precomputation).
  const Reply next =
      post(c, "/geometries/" + geom + "/results", wire::encode_request_json(pinned_push(7, 8)), kJson, kJson);
  ASSERT_EQ(next.status, 200) << next.body;
  EXPECT_EQ(wire::decode_result_json(next.body).value().res_id, ids.size() + 1);
  // Stresses of a restored result are served (by the rebuilt model).
  EXPECT_EQ(get(c, path_of(geom, 1) + "/stresses?level=1").status, 200);

  // A second server on the same directory is refused while this one holds it.
  Server second(dir.path);
  EXPECT_EQ(second.port, 0);
  EXPECT_EQ(second.child.wait(std::chrono::seconds(30)), 1);
  EXPECT_NE(second.child.drain_stderr().find("is in use by another softshell server (process " +
                                             std::to_string(server->child.pid()) + ")"),
            std::string::npos);
}

TEST(ServerRestartTest, CleanRestartRestoresEverything) {
  TempDir dir("softshell-restart");
  std::string geom;
  std::vector<Seen> before;
  {
    Server server(dir.path);
    ASSERT_GT(server.port, 0) << server.child.drain_stderr();
    geom = upload(server.port, exact_grid(4));
    httplib::Client c("127.0.0.1", server.port);
    for (int k = 1; k <= 12; ++k) {
      DeformationRequest request = pinned_push(k);
      if (k % 3 == 0) request.model = DeformationModel::kNonlinear;  // iterations and residual come back too
      const Reply r = post(c, "/geometries/" + geom + "/results", wire::encode_request_json(request), kJson, kJson);
      ASSERT_EQ(r.status, 200) << r.body;
      before.push_back(fetch(c, geom, static_cast<uint32_t>(k)));
    }
    kill(server.child.pid(), SIGTERM);
    EXPECT_EQ(server.child.wait(std::chrono::seconds(30)), 0);
  }
  Server server(dir.path);
  ASSERT_GT(server.port, 0) << server.child.drain_stderr();
  EXPECT_EQ(ids_of(server.port, geom).size(), 12u);
  httplib::Client c("127.0.0.1", server.port);
  for (uint32_t k = 1; k <= 12; ++k) {
    const Seen now = fetch(c, geom, k);
    EXPECT_EQ(now.json, before[k - 1].json) << k;
    EXPECT_EQ(now.binary, before[k - 1].binary) << k;
    EXPECT_EQ(now.request, before[k - 1].request) << k;
  }
  const Reply latest = get(c, "/geometries/" + geom + "/latest_result?have=0", kJson);
  EXPECT_EQ(latest.status, 200);
  EXPECT_EQ(latest.body, before.back().json);
}

// Upload, post results, DELETE, kill -9 (no clean shutdown: the delete's answer is enough),
// restart on the same directory, upload the same content again: its ids continue after the
// deleted ones, which stay 410, and nothing is reused (also across a second restart).
TEST(ServerRestartTest, IdsOfADeletedGeometryContinueAfterARestart) {
  TempDir dir("softshell-restart");
  std::string geom;
  auto post_one = [](int port, const std::string& g, int k) {
    httplib::Client c("127.0.0.1", port);
    const Reply r = post(c, "/geometries/" + g + "/results", wire::encode_request_json(pinned_push(k)), kJson, kJson);
    EXPECT_EQ(r.status, 200) << r.body;
    return r.status == 200 ? wire::decode_result_json(r.body).value().res_id : 0u;
  };
  {
    Server server(dir.path);
    ASSERT_GT(server.port, 0) << server.child.drain_stderr();
    geom = upload(server.port, exact_grid(4));
    for (int k = 1; k <= 3; ++k) EXPECT_EQ(post_one(server.port, geom, k), static_cast<uint32_t>(k));
    httplib::Client c("127.0.0.1", server.port);
    auto gone = c.Delete("/geometries/" + geom);
    ASSERT_TRUE(gone);
    ASSERT_EQ(gone->status, 204) << gone->body;
    kill(server.child.pid(), SIGKILL);
    server.child.wait(std::chrono::seconds(30));
  }
  {
    Server server(dir.path);
    ASSERT_GT(server.port, 0) << server.child.drain_stderr();
    httplib::Client c("127.0.0.1", server.port);
    EXPECT_EQ(get(c, "/geometries/" + geom + "/status").status, 404);  // the delete held
    EXPECT_EQ(upload(server.port, exact_grid(4)), geom);
    EXPECT_EQ(post_one(server.port, geom, 4), 4u);
    EXPECT_EQ(ids_of(server.port, geom), (std::vector<uint32_t>{4}));
    const Reply old = get(c, path_of(geom, 2), kJson);
    EXPECT_EQ(old.status, 410) << old.body;
    EXPECT_NE(old.body.find("earlier upload of it that was deleted"), std::string::npos) << old.body;
    kill(server.child.pid(), SIGTERM);
    EXPECT_EQ(server.child.wait(std::chrono::seconds(30)), 0);
  }
  // The second life, restored: still after the first, and the first's ids still 410.
  Server server(dir.path);
  ASSERT_GT(server.port, 0) << server.child.drain_stderr();
  httplib::Client c("127.0.0.1", server.port);
  EXPECT_EQ(ids_of(server.port, geom), (std::vector<uint32_t>{4}));
  EXPECT_EQ(get(c, path_of(geom, 3), kJson).status, 410);
  EXPECT_EQ(post_one(server.port, geom, 5), 5u);
}

TEST(ServerRestartTest, ADamagedStoreIsRefusedWithAClearMessage) {
  TempDir dir("softshell-restart");
  std::ofstream(dir.path + "/softshell.db") << std::string(4096, 'x');
  Server server(dir.path);
  EXPECT_EQ(server.port, 0);
  EXPECT_EQ(server.child.wait(std::chrono::seconds(30)), 1);
  const std::string err = server.child.drain_stderr();
  EXPECT_NE(err.find("softshell-server: " + dir.path + "/softshell.db is damaged or not a softshell store"),
            std::string::npos)
      << err;
}

}  // namespace
}  // namespace softshell
