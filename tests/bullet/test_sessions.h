#pragma once
// A test double of softshell::Session for the bridge's own logic (queueing, request contents):
// deform_async calls are recorded and answered only when the test says so. There is no physics
// here; the acceptance tests run against the real sessions (EmbeddedSession, RemoteSession).

#include <deque>
#include <future>
#include <mutex>
#include <vector>

#include "softshell/session.h"

namespace softshell::test {

class ManualSession final : public Session {
 public:
  explicit ManualSession(ControlMesh mesh) : mesh_(std::move(mesh)) {}

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
  std::future<Result<DeformationResult>> deform_async(const GeomId& id, const DeformationRequest& request) override;
  // Not used by the bridge:
  Result<std::vector<GeometryInfo>> geometries() override { return unsupported(); }
  Result<GeometryInfo> geometry_info(const GeomId&) override { return unsupported(); }
  Result<Geometry> geometry(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> deform(const GeomId&, const DeformationRequest&) override { return unsupported(); }
  Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> result(const GeomId&, uint32_t) override { return unsupported(); }
  Result<DeformationRequest> result_request(const GeomId&, uint32_t) override { return unsupported(); }
  Result<std::optional<DeformationResult>> latest_result(const GeomId&, uint32_t, std::chrono::milliseconds) override {
    return unsupported();
  }
  Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return unsupported(); }
  Result<StressField> stresses(const GeomId&, uint32_t, const StressQuery&) override { return unsupported(); }

 private:
  static Error unsupported() { return Error{ErrorCode::kInternal, "not part of the test double"}; }
  ControlMesh mesh_;
  mutable std::mutex mutex_;
  std::vector<DeformationRequest> requests_;
  std::deque<std::promise<Result<DeformationResult>>> promises_;
  uint32_t next_id_ = 1;
};

}  // namespace softshell::test
