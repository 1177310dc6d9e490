#include "test_sessions.h"

namespace softshell::test {

std::vector<DeformationRequest> ManualSession::requests() const {
  std::lock_guard lock(mutex_);
  return requests_;
}

size_t ManualSession::outstanding() const {
  std::lock_guard lock(mutex_);
  return promises_.size();
}

void ManualSession::answer(std::vector<Vec3> positions) {
  std::lock_guard lock(mutex_);
  if (promises_.empty()) throw std::logic_error("ManualSession::answer: nothing outstanding");
  DeformationResult result;
  result.res_id = next_id_++;
  result.positions = std::move(positions);
  promises_.front().set_value(Result<DeformationResult>(std::move(result)));
  promises_.pop_front();
}

void ManualSession::fail_next(Error error) {
  std::lock_guard lock(mutex_);
  if (promises_.empty()) throw std::logic_error("ManualSession::fail_next: nothing outstanding");
  promises_.front().set_value(Result<DeformationResult>(std::move(error)));
  promises_.pop_front();
}

Result<UploadResult> ManualSession::upload(const ControlMesh&, const Material&, std::string_view) {
  UploadResult out;
  out.id.bytes[0] = 1;
  out.created = true;
  out.status = GeometryStatus::kReady;
  return out;
}

std::future<Result<DeformationResult>> ManualSession::deform_async(const GeomId&, const DeformationRequest& request) {
  std::lock_guard lock(mutex_);
  requests_.push_back(request);
  promises_.emplace_back();
  return promises_.back().get_future();
}

}  // namespace softshell::test

