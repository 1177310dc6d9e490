#pragma once
// Shared helpers of the service's own tests (no HTTP): a small service and a geometry that is
// ready to solve.

#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "server_test_support.h"
#include "softshell/service/service.h"

namespace softshell::test {

/// One precomputation thread, 256 MiB store, 64 MiB factor cache; `solve_threads` 0 = the
/// service's default.
inline service::ServiceOptions small_options(int solve_threads = 0) {
  service::ServiceOptions o;
  o.precompute_threads = 1;
  if (solve_threads > 0) o.solve_threads = solve_threads;
  o.store_bytes = size_t{256} << 20;
  o.cache_bytes = size_t{64} << 20;
  return o;
}

/// Uploads `mesh` (test::exact_material) and waits until it is precomputed.
inline GeomId upload_ready(service::Service& s, const ControlMesh& mesh = exact_grid(), std::string name_space = "") {
  auto up = s.upload(mesh, exact_material(), std::move(name_space));
  EXPECT_TRUE(up) << up.error().message;
  auto info = s.wait_until_precomputed(up->id, std::chrono::milliseconds(60000));
  EXPECT_TRUE(info && info->status == GeometryStatus::kReady) << (info ? info->error : info.error().message);
  return up->id;
}

}  // namespace softshell::test
