// The softshell-server executable: options, the "listening" line, serving, clean stop on signals.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <vector>

#include "http_test_support.h"

namespace softshell {
namespace {

using namespace test;

// A child process with its stdout and stderr captured.
class Child {
 public:
  explicit Child(std::vector<std::string> args, const std::vector<std::pair<std::string, std::string>>& env = {}) {
    int out[2], err[2];
    if (pipe(out) != 0 || pipe(err) != 0) throw std::runtime_error("pipe failed");
    pid_ = fork();
    if (pid_ == 0) {
      dup2(out[1], 1);
      dup2(err[1], 2);
      close(out[0]);
      close(err[0]);
      for (const auto& [name, value] : env) setenv(name.c_str(), value.c_str(), 1);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out[1]);
    close(err[1]);
    out_ = out[0];
    err_ = err[0];
  }
  ~Child() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    close(out_);
    close(err_);
  }

  // Reads stdout until `needle` appeared or the timeout passed; returns what was read.
  std::string read_until(const std::string& needle, std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (stdout_.find(needle) == std::string::npos && std::chrono::steady_clock::now() < deadline) {
      pollfd p{out_, POLLIN, 0};
      if (poll(&p, 1, 100) > 0) {
        char buf[512];
        const ssize_t n = read(out_, buf, sizeof buf);
        if (n <= 0) break;
        stdout_.append(buf, static_cast<size_t>(n));
      }
    }
    return stdout_;
  }
  std::string drain_stderr() {
    std::string all;
    char buf[4096];
    fcntl(err_, F_SETFL, O_NONBLOCK);
    for (ssize_t n; (n = read(err_, buf, sizeof buf)) > 0;) all.append(buf, static_cast<size_t>(n));
    return all;
  }
  // Waits for the exit; returns the exit status or -1 on timeout.
  int wait(std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      usleep(10000);
    }
    return -1;
  }
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  int out_ = -1, err_ = -1;
  bool exited_ = false;
  std::string stdout_;
};

int port_of(const std::string& line) {
  const auto colon = line.rfind(':');
  return colon == std::string::npos ? 0 : std::atoi(line.c_str() + colon + 1);
}

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
                          "SOFTSHELL_KEEP_RESULTS", "SOFTSHELL_RESULT_BUDGET_MB",
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

TEST(ServerAppTest, BusyPortIsAnError) {
  TestServer taken;
  Child server({SOFTSHELL_SERVER_EXE, "--host", "127.0.0.1", "--port", std::to_string(taken.port())});
  EXPECT_EQ(server.wait(std::chrono::seconds(15)), 1);
  EXPECT_NE(server.drain_stderr().find("cannot listen"), std::string::npos);
}

}  // namespace
}  // namespace softshell
