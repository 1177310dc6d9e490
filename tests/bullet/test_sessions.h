#pragma once
// Test doubles of softshell::Session for the bridge's own logic (queueing, request contents).
// The physics acceptance tests run against the real sessions (EmbeddedSession, RemoteSession).

#include <deque>
#include <functional>
#include <future>
#include <mutex>
#include <vector>

#include "softshell/session.h"

namespace softshell::test {

/// A session whose `deform_async` calls are recorded and answered only when the test says so.
/// Answers are computed by `solve` (default: the rest positions) — there is no physics here.
class ScriptedSession final : public Session {
 public:
  explicit ScriptedSession(ControlMesh mesh) : mesh_(std::move(mesh)) {}

  /// Requests received by deform_async, oldest first.
  std::vector<DeformationRequest> requests() const;
  /// Number of requests not answered yet.
  size_t outstanding() const;
  /// Answers the oldest outstanding request with `positions` (or the rest positions).
  void answer(std::vector<Vec3> positions);
  void answer() { answer(mesh_.positions()); }
  /// Answers the oldest outstanding request with an error.
  void fail_next(Error error);

  Result<UploadResult> upload(const ControlMesh& mesh, const Material& material, std::string_view name_space) override;
  Result<std::vector<GeometryInfo>> geometries() override { return unsupported(); }
  Result<Geometry> geometry(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> deform(const GeomId&, const DeformationRequest&) override { return unsupported(); }
  std::future<Result<DeformationResult>> deform_async(const GeomId& id, const DeformationRequest& request) override;
  Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> result(const GeomId&, uint32_t) override { return unsupported(); }
  Result<std::optional<DeformationResult>> latest_result(const GeomId&, uint32_t, std::chrono::milliseconds) override {
    return unsupported();
  }
  Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return unsupported(); }

 private:
  static Error unsupported() { return Error{ErrorCode::kInternal, "not part of the test double"}; }
  ControlMesh mesh_;
  mutable std::mutex mutex_;
  std::vector<DeformationRequest> requests_;
  std::deque<std::promise<Result<DeformationResult>>> promises_;
  uint32_t next_id_ = 1;
};

}  // namespace softshell::test

#include <map>
#include <memory>

#include "softshell/engine/factor_cache.h"
#include "softshell/engine/shell_model.h"
#include "softshell/engine/solver.h"

namespace softshell::test {

/// Interim: an in-process Session over softshell::engine, used until EmbeddedSession is on main.
class EngineSession final : public Session {
 public:
  Result<UploadResult> upload(const ControlMesh& mesh, const Material& material, std::string_view name_space) override;
  Result<std::vector<GeometryInfo>> geometries() override { return unsupported(); }
  Result<Geometry> geometry(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> deform(const GeomId& id, const DeformationRequest& request) override;
  std::future<Result<DeformationResult>> deform_async(const GeomId& id, const DeformationRequest& request) override;
  Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> result(const GeomId&, uint32_t) override { return unsupported(); }
  Result<std::optional<DeformationResult>> latest_result(const GeomId&, uint32_t, std::chrono::milliseconds) override {
    return unsupported();
  }
  Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return unsupported(); }

 private:
  static Error unsupported() { return Error{ErrorCode::kInternal, "not part of the test double"}; }
  struct Entry {
    std::shared_ptr<const engine::ShellModel> model;
    std::unique_ptr<engine::Solver> solver;
    uint32_t next_id = 1;
  };
  std::mutex mutex_;
  std::shared_ptr<engine::FactorCache> cache_ = std::make_shared<engine::FactorCache>();
  std::vector<std::unique_ptr<Entry>> entries_;
};

}  // namespace softshell::test
