#pragma once
// A test double of `Session` for unit tests of code written against the interface (ParallelLevels,
// the C ABI's session functions): uploads get ids 1, 2, ...; `deform_async` calls are queued and
// the test completes them one by one, in any order, with `finish`. It simulates nothing: a
// "result" has position i = (i, k, 0) for call k. End-to-end tests use the real EmbeddedSession.

#include <deque>
#include <future>
#include <map>
#include <mutex>
#include <optional>

#include "softshell/session.h"

namespace softshell::test {

class ScriptedSession : public Session {
 public:
  Result<UploadResult> upload(const ControlMesh& mesh, const Material&, std::string_view) override {
    std::lock_guard lock(mutex_);
    UploadResult r;
    r.id.bytes[0] = static_cast<uint8_t>(++uploads_);
    r.created = true;
    vertices_[r.id.bytes[0]] = mesh.num_vertices();
    return r;
  }
  Result<std::vector<GeometryInfo>> geometries() override { return unsupported(); }
  Result<Geometry> geometry(const GeomId&) override { return unsupported(); }
  Result<GeometryInfo> geometry_info(const GeomId&) override { return unsupported(); }
  Result<DeformationRequest> result_request(const GeomId&, uint32_t) override { return unsupported(); }
  Result<DeformationResult> deform(const GeomId& id, const DeformationRequest& request) override {
    auto future = deform_async(id, request);
    finish(calls() - 1);
    return future.get();
  }
  std::future<Result<DeformationResult>> deform_async(const GeomId& id, const DeformationRequest& request) override {
    std::lock_guard lock(mutex_);
    calls_.push_back({id.bytes[0], request, std::promise<Result<DeformationResult>>()});
    return calls_.back().promise.get_future();
  }
  Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return unsupported(); }
  Result<DeformationResult> result(const GeomId&, uint32_t) override { return unsupported(); }
  Result<std::optional<DeformationResult>> latest_result(const GeomId& id, uint32_t have,
                                                         std::chrono::milliseconds) override {
    std::lock_guard lock(mutex_);
    auto it = latest_.find(id.bytes[0]);
    if (it == latest_.end() || it->second.res_id <= have) return std::optional<DeformationResult>();
    return std::optional<DeformationResult>(it->second);
  }
  Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return unsupported(); }
  Result<StressField> stresses(const GeomId&, uint32_t, const StressQuery&) override { return unsupported(); }

  // Completes call k with a result of the geometry's size (or an error).
  void finish(size_t k, bool ok = true) {
    std::lock_guard lock(mutex_);
    Call& c = calls_.at(k);
    if (ok) {
      DeformationResult r;
      r.res_id = static_cast<uint32_t>(k + 1);
      for (int32_t i = 0; i < vertices_[c.geometry]; ++i) r.positions.emplace_back(double(i), double(k), 0.0);
      latest_[c.geometry] = r;
      c.promise.set_value(std::move(r));
    } else {
      c.promise.set_value(Error{ErrorCode::kUnprocessable, "undetermined: a rigid-body motion is free"});
    }
  }
  size_t calls() {
    std::lock_guard lock(mutex_);
    return calls_.size();
  }
  DeformationRequest request(size_t k) {
    std::lock_guard lock(mutex_);
    return calls_.at(k).request;
  }

 private:
  static Error unsupported() { return Error{ErrorCode::kInternal, "not scripted"}; }
  struct Call {
    uint8_t geometry;
    DeformationRequest request;
    std::promise<Result<DeformationResult>> promise;
  };
  std::mutex mutex_;
  std::deque<Call> calls_;
  std::map<uint8_t, int32_t> vertices_;
  std::map<uint8_t, DeformationResult> latest_;
  int uploads_ = 0;
};

}  // namespace softshell::test
