#include "test_sessions.h"

namespace softshell::test {

std::vector<DeformationRequest> ScriptedSession::requests() const {
  std::lock_guard lock(mutex_);
  return requests_;
}

size_t ScriptedSession::outstanding() const {
  std::lock_guard lock(mutex_);
  return promises_.size();
}

void ScriptedSession::answer(std::vector<Vec3> positions) {
  std::lock_guard lock(mutex_);
  if (promises_.empty()) throw std::logic_error("ScriptedSession::answer: nothing outstanding");
  DeformationResult result;
  result.res_id = next_id_++;
  result.positions = std::move(positions);
  promises_.front().set_value(Result<DeformationResult>(std::move(result)));
  promises_.pop_front();
}

void ScriptedSession::fail_next(Error error) {
  std::lock_guard lock(mutex_);
  if (promises_.empty()) throw std::logic_error("ScriptedSession::fail_next: nothing outstanding");
  promises_.front().set_value(Result<DeformationResult>(std::move(error)));
  promises_.pop_front();
}

Result<UploadResult> ScriptedSession::upload(const ControlMesh&, const Material&, std::string_view) {
  UploadResult out;
  out.id.bytes[0] = 1;
  out.created = true;
  out.status = GeometryStatus::kReady;
  return out;
}

std::future<Result<DeformationResult>> ScriptedSession::deform_async(const GeomId&, const DeformationRequest& request) {
  std::lock_guard lock(mutex_);
  requests_.push_back(request);
  promises_.emplace_back();
  return promises_.back().get_future();
}

}  // namespace softshell::test

namespace softshell::test {

Result<UploadResult> EngineSession::upload(const ControlMesh& mesh, const Material& material, std::string_view) {
  auto model = engine::ShellModel::build(mesh, material);
  if (!model) return model.error();
  std::lock_guard lock(mutex_);
  auto entry = std::make_unique<Entry>();
  entry->model = *model;
  entry->solver = std::make_unique<engine::Solver>(entry->model, cache_);
  UploadResult out;
  out.id.bytes[0] = static_cast<uint8_t>(entries_.size());
  out.created = true;
  out.status = GeometryStatus::kReady;
  entries_.push_back(std::move(entry));
  return out;
}

Result<DeformationResult> EngineSession::deform(const GeomId& id, const DeformationRequest& request) {
  Entry* entry = nullptr;
  {
    std::lock_guard lock(mutex_);
    if (id.bytes[0] >= entries_.size()) return Error{ErrorCode::kNotFound, "unknown geometry"};
    entry = entries_[id.bytes[0]].get();
  }
  auto solution = entry->solver->solve(request);
  if (!solution) return solution.error();
  std::lock_guard lock(mutex_);
  return DeformationResult{entry->next_id++, solution->positions(entry->model->mesh())};
}

std::future<Result<DeformationResult>> EngineSession::deform_async(const GeomId& id, const DeformationRequest& request) {
  return std::async(std::launch::async, [this, id, request] { return deform(id, request); });
}

}  // namespace softshell::test
