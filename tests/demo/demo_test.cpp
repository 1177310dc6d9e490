// The demo's scripted session end to end (short): every layer working together.
#include "demo.h"

#include <filesystem>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace softshell::demo {
namespace {

TEST(Demo, ShortSessionRunsEveryLayer) {
  DemoOptions options;
  options.material = material_preset("aluminium", 0.002).value();
  options.out_dir = std::filesystem::temp_directory_path() / "softshell-demo-test";
  std::filesystem::remove_all(options.out_dir);
  options.deformations = 12;
  options.bullet_steps = 60;
  options.level = 2;
  options.picture_width = 160;
  options.picture_height = 120;
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  EXPECT_EQ(report->server, "embedded");
  EXPECT_GE(report->deformations, 12);
  EXPECT_GT(report->precompute_ms, 0.0);
  EXPECT_GT(report->latency_p50_ms, 0.0);
  EXPECT_LE(report->latency_p50_ms, report->latency_max_ms);
  // The follower ends with the master's last result.
  EXPECT_TRUE(report->follower.matches_master);
  EXPECT_EQ(report->follower.final_res_id, report->last_res_id);
  EXPECT_GE(report->follower.received, 1);
  // Bullet bodies landed and dented the shell.
  EXPECT_EQ(report->bullet.bodies, 3);
  EXPECT_GT(report->bullet.contacts, 0);
  EXPECT_GT(report->bullet.max_deflection, 0.0);
  EXPECT_GT(report->max_displacement, 0.0);
  for (const auto& path : report->outputs) EXPECT_TRUE(std::filesystem::exists(path)) << path;
  EXPECT_EQ(report->outputs.size(), 7u);

  // The --json line carries every documented field.
  const auto j = nlohmann::json::parse(format_json(*report));
  for (const char* key : {"mesh", "server", "deformations", "precompute_ms", "latency_ms", "follower", "bullet", "outputs"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["follower"]["final_res_id"].get<uint32_t>(), report->last_res_id);
  EXPECT_TRUE(j["latency_ms"].contains("p95"));
  EXPECT_TRUE(j["bullet"].contains("max_deflection"));
  EXPECT_NE(format_summary(*report).find("follower"), std::string::npos);
}

TEST(Demo, BadInputIsAnErrorNotACrash) {
  DemoOptions options;
  options.mesh = "/nonexistent.obj";
  auto report = run_demo(options);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.error().code, ErrorCode::kIoError);
  options.mesh.clear();
  options.deformations = 3;
  EXPECT_EQ(run_demo(options).error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace softshell::demo
