// The softshell-server executable: options, the "listening" line, serving, clean stop on signals.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "child_process.h"
#include "http_test_support.h"
#include "sse_client.h"
#include "temp_dir.h"

namespace softshell {
namespace {

using namespace test;

TEST(ServerAppTest, ServesAndStopsCleanlyOnSignals) {
  for (int sig : {SIGTERM, SIGINT}) {
    Child server({SOFTSHELL_SERVER_EXE, "--host", "127.0.0.1", "--port", "0", "--threads", "1", "--cache-mb", "64",
                  "--store-mb", "256", "--max-body-mb", "1", "--log-level", "info"});
    const std::string out = server.read_until("\n", std::chrono::seconds(30));
    ASSERT_NE(out.find("softshell-server listening on http://127.0.0.1:"), std::string::npos) << out;
    const int port = port_of(out.substr(0, out.find('\n')));
    ASSERT_GT(port, 0);
    {
      httplib::Client c("127.0.0.1", port);
      auto health = c.Get("/health");
      ASSERT_TRUE(health);
      EXPECT_EQ(health->status, 200);
      // --max-body-mb 1
      auto big = c.Post("/geometries", std::string((1 << 20) + 10, 'x'), kBin);
      ASSERT_TRUE(big);
      EXPECT_EQ(big->status, 413);
      auto up = c.Post("/geometries", wire::encode_geometry_binary(exact_grid(), exact_material()).value(), kBin);
      ASSERT_TRUE(up);
      EXPECT_EQ(up->status, 201);
    }
    kill(server.pid(), sig);
    EXPECT_EQ(server.wait(std::chrono::seconds(15)), 0) << "signal " << sig;
    const std::string log = server.drain_stderr();
    // One line per request: method, path, status, microseconds.
    EXPECT_NE(log.find("GET /health 200 "), std::string::npos) << log;
    EXPECT_NE(log.find("POST /geometries 201 "), std::string::npos) << log;
    EXPECT_NE(log.find("POST /geometries 413 "), std::string::npos) << log;
    EXPECT_NE(log.find("us\n"), std::string::npos) << log;
    EXPECT_NE(log.find("stopped"), std::string::npos) << log;
  }
}

TEST(ServerAppTest, HelpAndBadOptions) {
  Child help({SOFTSHELL_SERVER_EXE, "--help"});
  const std::string text = help.read_until("--log-level", std::chrono::seconds(10));
  EXPECT_EQ(help.wait(std::chrono::seconds(10)), 0);
  for (const char* option : {"--host", "--port", "--threads", "--cache-mb", "--max-body-mb", "--log-level"}) {
    EXPECT_NE(text.find(option), std::string::npos) << option;
  }
  Child bad({SOFTSHELL_SERVER_EXE, "--port", "99999"});
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  EXPECT_NE(bad.drain_stderr().find("--port"), std::string::npos);
  Child unknown({SOFTSHELL_SERVER_EXE, "--frobnicate"});
  EXPECT_EQ(unknown.wait(std::chrono::seconds(10)), 2);
}

// CLI11: --opt=value as well as --opt value, --version, SOFTSHELL_* environment variables (the
// command line wins), help that names each variable.
TEST(ServerAppTest, OptionFormsVersionAndEnvironment) {
  Child version({SOFTSHELL_SERVER_EXE, "--version"});
  const std::string v = version.read_until("\n", std::chrono::seconds(10));
  EXPECT_EQ(version.wait(std::chrono::seconds(10)), 0);
  EXPECT_EQ(v.rfind(std::string("softshell-server ") + SOFTSHELL_VERSION_STRING, 0), 0u) << v;

  Child help({SOFTSHELL_SERVER_EXE, "--help"});
  const std::string text = help.read_until("SOFTSHELL_LOG_LEVEL", std::chrono::seconds(10));
  EXPECT_EQ(help.wait(std::chrono::seconds(10)), 0);
  for (const char* env : {"SOFTSHELL_HOST", "SOFTSHELL_PORT", "SOFTSHELL_THREADS", "SOFTSHELL_SOLVE_THREADS",
                          "SOFTSHELL_PRECOMPUTE_JOBS", "SOFTSHELL_CACHE_MB", "SOFTSHELL_STORE_MB", "SOFTSHELL_MAX_BODY_MB",
                          "SOFTSHELL_MAX_CONNECTIONS", "SOFTSHELL_EVENT_WRITERS", "SOFTSHELL_MAX_HOLDS",
                          "SOFTSHELL_SHUTDOWN_TIMEOUT", "SOFTSHELL_KEEP_RESULTS", "SOFTSHELL_RESULT_BUDGET_MB",
                          "SOFTSHELL_LOG_LEVEL"}) {
    EXPECT_NE(text.find(env), std::string::npos) << env;
  }

  // --opt=value; the port and the body limit from the environment.
  Child server({SOFTSHELL_SERVER_EXE, "--host=127.0.0.1", "--threads=1", "--log-level=warning"},
               {{"SOFTSHELL_PORT", "0"}, {"SOFTSHELL_MAX_BODY_MB", "1"}, {"SOFTSHELL_CACHE_MB", "64"}});
  const std::string out = server.read_until("\n", std::chrono::seconds(30));
  ASSERT_NE(out.find("softshell-server listening on http://127.0.0.1:"), std::string::npos) << out;
  const int port = port_of(out.substr(0, out.find('\n')));
  ASSERT_GT(port, 0);  // 0 came from SOFTSHELL_PORT: a free port, not 8080
  {
    httplib::Client c("127.0.0.1", port);
    auto big = c.Post("/geometries", std::string((1 << 20) + 10, 'x'), kBin);
    ASSERT_TRUE(big);
    EXPECT_EQ(big->status, 413);  // SOFTSHELL_MAX_BODY_MB=1
  }
  kill(server.pid(), SIGTERM);
  EXPECT_EQ(server.wait(std::chrono::seconds(15)), 0);
  // --log-level=warning: no per-request info lines.
  EXPECT_EQ(server.drain_stderr().find("POST /geometries 413"), std::string::npos);

  // A bad value from the environment is refused like one on the command line.
  Child bad({SOFTSHELL_SERVER_EXE}, {{"SOFTSHELL_PORT", "99999"}});
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  EXPECT_NE(bad.drain_stderr().find("--port"), std::string::npos);
  Child level({SOFTSHELL_SERVER_EXE, "--log-level=loud"});
  EXPECT_EQ(level.wait(std::chrono::seconds(10)), 2);
}

// --max-holds: the live holds one geometry takes.
TEST(ServerAppTest, MaxHoldsLimitsTheLiveHoldsOfAGeometry) {
  Child server({SOFTSHELL_SERVER_EXE, "--port=0", "--threads=1", "--max-holds=2", "--log-level=warning"});
  const std::string out = server.read_until("\n", std::chrono::seconds(30));
  const int port = port_of(out.substr(0, out.find('\n')));
  ASSERT_GT(port, 0) << out;
  {
    httplib::Client c("127.0.0.1", port);
    c.set_read_timeout(std::chrono::seconds(60));
    auto up = c.Post("/geometries", wire::encode_geometry_binary(exact_grid(), exact_material()).value(), kBin);
    ASSERT_TRUE(up);
    ASSERT_EQ(up->status, 201);
    const std::string base = "/geometries/" + wire::decode_upload_response_binary(up->body, true).value().id.hex();
    DeformationRequest pins;
    pins.vertex_constraints = pinned_corners(4);
    DeformationRequest push;
    push.forces.push_back({grid_index(4, 2, 2), Vec3(0.0, 0.0, -0.1)});
    const std::string pins_body = wire::encode_request_json(pins), push_body = wire::encode_request_json(push);
    auto a = c.Put(base + "/holds/pins", pins_body, kJson);  // waits for the precomputation
    ASSERT_TRUE(a);
    EXPECT_EQ(a->status, 200) << a->body;
    auto b = c.Put(base + "/holds/hand-1", push_body, kJson);
    ASSERT_TRUE(b);
    EXPECT_EQ(b->status, 200) << b->body;
    auto third = c.Put(base + "/holds/hand-2", push_body, kJson);
    ASSERT_TRUE(third);
    EXPECT_EQ(third->status, 409) << third->body;
    EXPECT_NE(third->body.find("2 live holds"), std::string::npos) << third->body;
    auto again = c.Put(base + "/holds/hand-1", push_body, kJson);  // a hold that exists is always taken
    ASSERT_TRUE(again);
    EXPECT_EQ(again->status, 200) << again->body;
  }
  kill(server.pid(), SIGTERM);
  EXPECT_EQ(server.wait(std::chrono::seconds(15)), 0);
  Child bad({SOFTSHELL_SERVER_EXE, "--max-holds=0"});
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  EXPECT_NE(bad.drain_stderr().find("--max-holds"), std::string::npos);
}

// A stop finishes what runs within --shutdown-timeout and then exits anyway; a second signal
// exits at once. What holds the stop here: a client that asked for large answers and reads
// none of them, so the server's write waits on a full socket (for up to its 30 s I/O timeout).
TEST(ServerAppTest, StopHasADeadlineAndASecondSignalStopsAtOnce) {
  for (const bool second_signal : {false, true}) {
    Child server({SOFTSHELL_SERVER_EXE, "--port=0", "--threads=1", "--log-level=warning", "--shutdown-timeout",
                  second_signal ? "600" : "1"});
    const std::string out = server.read_until("\n", std::chrono::seconds(30));
    const int port = port_of(out.substr(0, out.find('\n')));
    ASSERT_GT(port, 0) << out;
    std::string result_path;
    {
      httplib::Client c("127.0.0.1", port);
      c.set_read_timeout(std::chrono::seconds(60));
      auto up = c.Post("/geometries", wire::encode_geometry_binary(exact_grid(40), exact_material()).value(), kBin);
      ASSERT_TRUE(up);
      ASSERT_EQ(up->status, 201);
      const std::string base = "/geometries/" + wire::decode_upload_response_binary(up->body, true).value().id.hex();
      auto solved = c.Post(base + "/results", wire::encode_request_json(pinned_push(1, 40)), kJson);
      ASSERT_TRUE(solved);
      ASSERT_EQ(solved->status, 200) << solved->body;
      result_path = base + "/results/1";
    }
    const int fd = connect_loopback(port, /*rcvbuf=*/4096);
    ASSERT_GE(fd, 0);
    std::string pipelined;
    for (int i = 0; i < 64; ++i) pipelined += "GET " + result_path + " HTTP/1.1\r\nHost: x\r\nAccept: application/json\r\n\r\n";
    ASSERT_EQ(::send(fd, pipelined.data(), pipelined.size(), MSG_NOSIGNAL), static_cast<ssize_t>(pipelined.size()));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the server's writes fill the socket

    const auto start = std::chrono::steady_clock::now();
    kill(server.pid(), SIGTERM);
    if (second_signal) {
      EXPECT_EQ(server.wait(std::chrono::seconds(1)), -1) << "the stop should still wait for the blocked answer";
      kill(server.pid(), SIGTERM);
    }
    EXPECT_EQ(server.wait(std::chrono::seconds(20)), 1);
    // Well before the 30 s the blocked write would take.
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(20));
    const std::string log = server.drain_stderr();
    EXPECT_NE(log.find(second_signal ? "received SIGTERM again" : "the shutdown timeout passed"), std::string::npos)
        << log;
    EXPECT_NE(log.find("1 connection(s) still busy"), std::string::npos) << log;
    ::close(fd);
  }
  Child bad({SOFTSHELL_SERVER_EXE, "--shutdown-timeout=-1"});
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  EXPECT_NE(bad.drain_stderr().find("--shutdown-timeout"), std::string::npos);
  Child bad_limit({SOFTSHELL_SERVER_EXE, "--nonlinear-time-limit=-1"});
  EXPECT_EQ(bad_limit.wait(std::chrono::seconds(10)), 2);
  EXPECT_NE(bad_limit.drain_stderr().find("--nonlinear-time-limit"), std::string::npos);
}

// --nonlinear-refresh (or its variable): the start's log says which refresh rule nonlinear
// solves use, and they answer. Two servers on the counted rule (the default, and the variable)
// give the same bytes to the same drag of a hold. (That the counted rule repeats itself on a
// slower host is the engine's test,
// NonlinearSolver.TheCountedRefreshRuleGivesTheSameAnswersOnASlowerHost.)
TEST(ServerAppTest, NonlinearRefreshRuleFromTheCommandLineOrTheEnvironment) {
  const auto run = [](std::vector<std::string> args, std::vector<std::pair<std::string, std::string>> env,
                      std::vector<std::string>& answers) {
    Child server(std::move(args), std::move(env));
    const std::string out = server.read_until("\n", std::chrono::seconds(30));
    const int port = port_of(out.substr(0, out.find('\n')));
    EXPECT_GT(port, 0) << out;
    httplib::Client c("127.0.0.1", port);
    c.set_read_timeout(std::chrono::seconds(60));
    const Reply up =
        port > 0 ? to_reply(c.Post("/geometries", wire::encode_geometry_binary(exact_grid(), exact_material()).value(), kBin))
                 : Reply{};
    EXPECT_EQ(up.status, 201) << up.body;
    if (up.status == 201) {
      const std::string base = "/geometries/" + wire::decode_upload_response_binary(up.body, true).value().id.hex();
      for (double pull : {0.2, 0.4}) {  // a hold changed: the second solve starts from the first's answer
        DeformationRequest request;
        request.vertex_constraints = pinned_corners(4);
        request.forces.push_back({grid_index(4, 2, 2), Vec3(0.0, 0.0, pull)});
        request.model = DeformationModel::kNonlinear;
        const Reply put = to_reply(c.Put(base + "/holds/hand", wire::encode_request_json(request), kJson));
        EXPECT_EQ(put.status, 200) << put.body;
        const Reply answer = get(c, base + "/latest_result", kBin);
        EXPECT_EQ(answer.status, 200) << answer.body;
        answers.push_back(answer.body);
      }
    }
    kill(server.pid(), SIGTERM);
    EXPECT_EQ(server.wait(std::chrono::seconds(15)), 0);
    return server.drain_stderr();
  };
  std::vector<std::string> default_answers, env_answers, timed_answers, env_timed_answers;
  const std::string default_log = run({SOFTSHELL_SERVER_EXE, "--port=0"}, {}, default_answers);
  EXPECT_NE(default_log.find("nonlinear solves: at most 60 s each, refresh rule counted"), std::string::npos)
      << default_log;
  const std::string env_log = run({SOFTSHELL_SERVER_EXE, "--port=0", "--nonlinear-time-limit=30"},
                                  {{"SOFTSHELL_NONLINEAR_REFRESH", "counted"}}, env_answers);
  EXPECT_NE(env_log.find("nonlinear solves: at most 30 s each, refresh rule counted"), std::string::npos) << env_log;
  ASSERT_EQ(default_answers.size(), 2u);
  EXPECT_EQ(default_answers, env_answers);
  EXPECT_NE(default_answers[0], default_answers[1]);

  const std::string timed_log =
      run({SOFTSHELL_SERVER_EXE, "--port=0", "--nonlinear-refresh", "timed"}, {}, timed_answers);
  EXPECT_NE(timed_log.find("nonlinear solves: at most 60 s each, refresh rule timed"), std::string::npos) << timed_log;
  EXPECT_EQ(timed_answers.size(), 2u);
  const std::string from_env = run({SOFTSHELL_SERVER_EXE, "--port=0"}, {{"SOFTSHELL_NONLINEAR_REFRESH", "timed"}},
                                   env_timed_answers);
  EXPECT_NE(from_env.find("refresh rule timed"), std::string::npos) << from_env;
  EXPECT_EQ(env_timed_answers.size(), 2u);
  Child bad({SOFTSHELL_SERVER_EXE, "--nonlinear-refresh=sometimes"});
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  EXPECT_NE(bad.drain_stderr().find("--nonlinear-refresh"), std::string::npos);
}

TEST(ServerAppTest, BusyPortIsAnError) {
  TestServer taken;
  Child server({SOFTSHELL_SERVER_EXE, "--host", "127.0.0.1", "--port", std::to_string(taken.port())});
  EXPECT_EQ(server.wait(std::chrono::seconds(15)), 1);
  EXPECT_NE(server.drain_stderr().find("cannot listen"), std::string::npos);
}

// --auth-token-file (and SOFTSHELL_AUTH_TOKEN_FILE): a bad file stops the start with the reason;
// a good one makes every request but /health need the token; a file others can read is warned of.
TEST(ServerAppTest, AuthTokenFile) {
  const TempDir temp("softshell-app-auth");
  const std::string& dir = temp.path;
  auto write = [&](const std::string& name, const std::string& text, mode_t mode) {
    const std::string path = dir + "/" + name;
    FILE* f = std::fopen(path.c_str(), "wb");
    std::fwrite(text.data(), 1, text.size(), f);
    std::fclose(f);
    chmod(path.c_str(), mode);
    return path;
  };
  const std::string token = "app-token-0123456789abcdef";
  const std::string good = write("good", token + "\n", 0600);
  const std::string shared = write("shared", token + "\n", 0644);
  for (const auto& [path, says] : std::vector<std::pair<std::string, std::string>>{
           {dir + "/missing", "does not exist"},
           {write("empty", "\n", 0600), "empty"},
           {write("short", "0123456789\n", 0600), "at least 16"},
           {write("spaced", "0123456789 0123456789\n", 0600), "visible ASCII"}}) {
    Child bad({SOFTSHELL_SERVER_EXE, "--port=0", "--auth-token-file", path});
    EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2) << path;
    const std::string err = bad.drain_stderr();
    EXPECT_NE(err.find("--auth-token-file"), std::string::npos) << err;
    EXPECT_NE(err.find(says), std::string::npos) << err;
    EXPECT_NE(err.find(path), std::string::npos) << err;
  }
  for (const bool from_env : {false, true}) {
    std::vector<std::string> args{SOFTSHELL_SERVER_EXE, "--port=0", "--threads=1", "--log-level=warning"};
    std::vector<std::pair<std::string, std::string>> env;
    if (from_env) env.emplace_back("SOFTSHELL_AUTH_TOKEN_FILE", shared);
    else args.insert(args.end(), {"--auth-token-file", good});
    Child server(args, env);
    const std::string out = server.read_until("\n", std::chrono::seconds(30));
    const int port = port_of(out.substr(0, out.find('\n')));
    ASSERT_GT(port, 0) << out << server.drain_stderr();
    {
      httplib::Client c("127.0.0.1", port);
      auto health = c.Get("/health");
      ASSERT_TRUE(health);
      EXPECT_EQ(health->status, 200);
      auto anonymous = c.Get("/geometries");
      ASSERT_TRUE(anonymous);
      EXPECT_EQ(anonymous->status, 401);
      EXPECT_EQ(anonymous->get_header_value("WWW-Authenticate"), R"(Bearer realm="softshell")");
      auto ok = c.Get("/geometries", {{"Authorization", "Bearer " + token}});
      ASSERT_TRUE(ok);
      EXPECT_EQ(ok->status, 200);
    }
    kill(server.pid(), SIGTERM);
    EXPECT_EQ(server.wait(std::chrono::seconds(15)), 0);
    const std::string log = server.drain_stderr();
    // The shared file (0644) is warned of; the private one is not.
    EXPECT_EQ(log.find("chmod 600") != std::string::npos, from_env) << log;
  }
}

}  // namespace
}  // namespace softshell
