// The data directory's metrics on GET /metrics over a real socket (127.0.0.1, ephemeral port):
// bytes on disk, committed writes, failed writes and the write-duration histogram follow what the
// requests did; a server in memory reports none of them.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "http_test_support.h"
#include "temp_dir.h"

namespace softshell {
namespace {

using namespace test;
namespace fs = std::filesystem;

// The value of the sample `series` (name and labels as written) in a Prometheus text body; NaN
// if it is absent.
double metric(const std::string& text, const std::string& series) {
  const std::string line = "\n" + series + " ";
  const size_t at = text.find(line);
  if (at == std::string::npos) return std::nan("");
  return std::strtod(text.c_str() + at + line.size(), nullptr);
}

service::ServiceOptions on(const TempDir& dir) {
  service::ServiceOptions o = test_service_options();
  o.data_dir = dir.path;
  return o;
}

size_t disk_bytes(const TempDir& dir) {
  size_t n = 0;
  for (const char* f : {"/softshell.db", "/softshell.db-wal"}) {
    std::error_code ec;
    const auto size = fs::file_size(dir.path + f, ec);
    if (!ec) n += static_cast<size_t>(size);
  }
  return n;
}

TEST(HttpStoreMetricsTest, WritesFailuresBytesAndDurations) {
  TempDir dir("softshell-metrics");
  TestServer server(on(dir));
  auto c = server.client();
  std::string m = get(*c, "/metrics").body;
  EXPECT_NE(m.find("# TYPE softshell_data_dir_bytes gauge"), std::string::npos) << m;
  EXPECT_NE(m.find("# TYPE softshell_data_dir_writes_total counter"), std::string::npos);
  EXPECT_NE(m.find("# TYPE softshell_data_dir_write_failures_total counter"), std::string::npos);
  EXPECT_NE(m.find("# TYPE softshell_data_dir_write_duration_seconds histogram"), std::string::npos);
  EXPECT_EQ(metric(m, "softshell_data_dir_writes_total"), 0.0);
  EXPECT_EQ(metric(m, "softshell_data_dir_write_duration_seconds_count"), 0.0);
  const double empty_bytes = metric(m, "softshell_data_dir_bytes");
  EXPECT_GT(empty_bytes, 0.0);  // the schema

  // An upload, two results, a delete: four write transactions.
  const ControlMesh mesh = exact_grid();
  const Reply up = post(*c, "/geometries", wire::encode_geometry_json(mesh, exact_material()), kJson, kJson);
  ASSERT_EQ(up.status, 201) << up.body;
  const std::string geom = wire::decode_upload_response_json(up.body, true).value().id.hex();
  for (int k = 1; k <= 2; ++k) {
    const Reply r = post(*c, "/geometries/" + geom + "/results", wire::encode_request_json(pinned_push(k)), kJson);
    ASSERT_EQ(r.status, 200) << r.body;
  }
  ASSERT_EQ(to_reply(c->Delete("/geometries/" + geom)).status, 204);
  m = get(*c, "/metrics").body;
  EXPECT_EQ(metric(m, "softshell_data_dir_writes_total"), 4.0) << m;
  EXPECT_EQ(metric(m, "softshell_data_dir_write_failures_total"), 0.0);
  EXPECT_EQ(metric(m, "softshell_data_dir_write_duration_seconds_count"), 4.0);
  EXPECT_EQ(metric(m, "softshell_data_dir_write_duration_seconds_bucket{le=\"+Inf\"}"), 4.0);
  EXPECT_GT(metric(m, "softshell_data_dir_write_duration_seconds_sum"), 0.0);
  EXPECT_EQ(metric(m, "softshell_data_dir_bytes"), static_cast<double>(disk_bytes(dir)));  // nothing written since
  EXPECT_GT(metric(m, "softshell_data_dir_bytes"), empty_bytes);

  // A write that fails (the file size limit, as a full disk would): 507 and one failure counted.
  ASSERT_EQ(post(*c, "/geometries", wire::encode_geometry_json(mesh, exact_material()), kJson).status, 201);
  ASSERT_EQ(server.service().wait_until_precomputed(GeomId::from_hex(geom).value(), std::chrono::seconds(30))->status,
            GeometryStatus::kReady);
  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  const auto old_handler = signal(SIGXFSZ, SIG_IGN);  // write() fails with EFBIG instead
  rlimit full = saved;
  full.rlim_cur = static_cast<rlim_t>(fs::file_size(dir.path + "/softshell.db-wal"));
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &full), 0);
  const Reply refused = post(*c, "/geometries/" + geom + "/results", wire::encode_request_json(pinned_push(3)), kJson);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &saved), 0);
  signal(SIGXFSZ, old_handler);
  EXPECT_EQ(refused.status, 507) << refused.body;
  m = get(*c, "/metrics").body;
  EXPECT_EQ(metric(m, "softshell_data_dir_writes_total"), 5.0) << m;
  EXPECT_EQ(metric(m, "softshell_data_dir_write_failures_total"), 1.0);
  EXPECT_EQ(metric(m, "softshell_data_dir_write_duration_seconds_count"), 6.0);  // failed writes are timed too
}

TEST(HttpStoreMetricsTest, AServerInMemoryReportsNoStore) {
  TestServer server;
  auto c = server.client();
  const Reply m = get(*c, "/metrics");
  ASSERT_EQ(m.status, 200);
  EXPECT_NE(m.body.find("softshell_store_bytes"), std::string::npos);  // the memory budget's families are there
  EXPECT_EQ(m.body.find("softshell_data_dir_"), std::string::npos) << m.body;
}

}  // namespace
}  // namespace softshell
