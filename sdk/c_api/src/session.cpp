// C ABI: sessions (remote; the embedded one is created in server/embedded), uploads, blocking and
// asynchronous deformations, results, geometry status and limit combinations.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <future>
#include <mutex>
#include <string>
#include <vector>

#include "c_api_internal.h"
#include "softshell/remote_session.h"
#include "softshell/softshell_c_bridge.h"

using namespace softshell;         // NOLINT(google-build-using-namespace): a .cpp of entry points
using namespace softshell::c_api;  // NOLINT(google-build-using-namespace)

namespace {

ss_stress_sample stress_to_c(const StressSample& sample) {
  return ss_stress_sample{to_c(sample.point),          to_c(sample.position),
                          to_c(sample.membrane_force), to_c(sample.bending_moment),
                          sample.von_mises_top,        sample.von_mises_bottom};
}

Reaper<DeformationObject>& reaper() {
  static auto* r = new Reaper<DeformationObject>([](const DeformationObject&) { return std::string("a deformation"); });
  return *r;
}

}  // namespace

namespace softshell::c_api {

ss_session* wrap_session(std::shared_ptr<Session> session) {
  if (!session) fail(ErrorCode::kInvalidArgument, "wrap_session: the session is null");
  return make_handle<ss_session>(std::move(session));
}

std::shared_ptr<Session> session_of(const ss_session* handle) { return live(handle, "session"); }

void log_message(int32_t level, std::string_view message) noexcept { c_api::log(level, message); }

namespace {

// Each task is boxed for the host and unboxed (and freed) by the trampoline it runs.
class TaskSystemExecutor final : public Executor {
 public:
  explicit TaskSystemExecutor(const ss_task_system& tasks) : tasks_(tasks) {}
  void post(std::function<void()> task) override {
    auto boxed = std::make_unique<std::function<void()>>(std::move(task));
    tasks_.enqueue(&run, boxed.release(), tasks_.user_context);
  }
  int concurrency() const override { return tasks_.concurrency; }

 private:
  static void run(void* data) {
    const std::unique_ptr<std::function<void()>> task(static_cast<std::function<void()>*>(data));
    (*task)();  // softshell's tasks catch what they raise
  }
  ss_task_system tasks_;
};

}  // namespace

std::shared_ptr<Executor> executor_of(const ss_task_system& tasks) {
  if (tasks.enqueue == nullptr) fail(ErrorCode::kInvalidArgument, "task system: enqueue is NULL");
  if (tasks.concurrency < 1) {
    fail(ErrorCode::kInvalidArgument,
         "task system: concurrency must be at least 1, got " + std::to_string(tasks.concurrency));
  }
  return std::make_shared<TaskSystemExecutor>(tasks);
}

}  // namespace softshell::c_api

extern "C" {

void ss_remote_options_default(ss_remote_options* out) {
  if (out) *out = ss_remote_options{0, 0, 0, 0, nullptr};
}

ss_status ss_session_create_remote(const char* url, const ss_remote_options* options, ss_session** out_session) {
  return ss_session_create_remote_on(url, options, nullptr, out_session);
}

ss_status ss_session_create_remote_on(const char* url, const ss_remote_options* options, const ss_task_system* tasks,
                                      ss_session** out_session) {
  return guard("ss_session_create_remote", [&] {
    required(out_session, "out_session");
    *out_session = nullptr;
    required(url, "url");
    ss_remote_options o;
    ss_remote_options_default(&o);
    if (options) o = *options;
    if (o.connect_timeout_ms < 0 || o.request_timeout_ms < 0 || o.async_threads < 0 || o.async_threads > 256) {
      fail(ErrorCode::kInvalidArgument, "remote options: timeouts must be >= 0 and async_threads in 0..256");
    }
    RemoteSessionOptions ro;
    ro.format = o.binary ? wire::Format::kBinary : wire::Format::kJson;
    if (o.connect_timeout_ms > 0) ro.connect_timeout = std::chrono::milliseconds(o.connect_timeout_ms);
    if (o.request_timeout_ms > 0) ro.request_timeout = std::chrono::milliseconds(o.request_timeout_ms);
    if (o.async_threads > 0) ro.async_threads = o.async_threads;
    if (o.auth_token) ro.auth_token = o.auth_token;
    if (tasks) ro.executor = executor_of(*tasks);
    std::shared_ptr<Session> session = RemoteSession::connect(url, ro).value();
    *out_session = wrap_session(std::move(session));
  });
}

void ss_session_destroy(ss_session* session) { destroy(session, "ss_session_destroy"); }

ss_status ss_geom_id_to_hex(const ss_geom_id* id, char* out, int32_t capacity) {
  return guard("ss_geom_id_to_hex", [&] {
    required(id, "id");
    required(out, "out");
    if (capacity < 33) throw CStatus{SS_BUFFER_TOO_SMALL, "needs 33 characters (32 hex digits and NUL)"};
    static constexpr char kHex[] = "0123456789abcdef";
    for (int i = 0; i < 16; ++i) {
      out[2 * i] = kHex[id->bytes[i] >> 4];
      out[2 * i + 1] = kHex[id->bytes[i] & 15];
    }
    out[32] = '\0';
  });
}

ss_status ss_session_upload(ss_session* session, const ss_mesh* mesh, const ss_material* m, const char* name_space,
                            ss_geom_id* out_id, int32_t* out_created) {
  return guard("ss_session_upload", [&] {
    const auto s = live(session, "session");
    const auto mesh_object = live(mesh, "mesh");
    const Material mat = material(m, "material");
    required(out_id, "out_id");
    const UploadResult r = s->upload(*mesh_object, mat, name_space ? name_space : "").value();
    std::memcpy(out_id->bytes, r.id.bytes.data(), 16);
    if (out_created) *out_created = r.created ? 1 : 0;
  });
}

ss_status ss_session_remove_geometry(ss_session* session, const ss_geom_id* id) {
  return guard("ss_session_remove_geometry", [&] {
    const auto s = live(session, "session");
    s->remove_geometry(geom_id(id)).value();
  });
}

ss_status ss_session_deform(ss_session* session, const ss_geom_id* id, const ss_request* request,
                            uint32_t* out_res_id, double* out_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_session_deform", [&] {
    const auto s = live(session, "session");
    const auto req = live(request, "request");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    const DeformationResult r = s->deform(geom_id(id), *req).value();
    write_xyz(r.positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r.res_id;
  });
}

ss_status ss_session_deform_begin(ss_session* session, const ss_geom_id* id, const ss_request* request,
                                  ss_deformation** out_operation) {
  return guard("ss_session_deform_begin", [&] {
    required(out_operation, "out_operation");
    *out_operation = nullptr;
    const auto s = live(session, "session");
    const auto req = live(request, "request");
    reaper().purge_finished();
    auto op = std::make_shared<DeformationObject>();
    op->session = s;
    op->future = s->deform_async(geom_id(id), *req).share();
    if (!op->future.valid()) fail(ErrorCode::kInternal, "the session returned no future");
    finish_before_exit(op->future);
    *out_operation = make_handle<ss_deformation>(std::move(op));
  });
}

ss_status ss_deformation_poll(ss_deformation* operation, int32_t* out_ready) {
  return guard("ss_deformation_poll", [&] {
    const auto op = live(operation, "operation");
    required(out_ready, "out_ready");
    *out_ready = op->ready() ? 1 : 0;
  });
}

ss_status ss_deformation_wait(ss_deformation* operation, int32_t timeout_ms, int32_t* out_ready) {
  return guard("ss_deformation_wait", [&] {
    const auto op = live(operation, "operation");
    required(out_ready, "out_ready");
    count_arg(timeout_ms, "timeout_ms");
    *out_ready = op->future.wait_for(std::chrono::milliseconds(timeout_ms)) == std::future_status::ready ? 1 : 0;
  });
}

ss_status ss_deformation_read(ss_deformation* operation, uint32_t* out_res_id, double* out_xyz, int32_t capacity,
                              int32_t* out_count) {
  return guard("ss_deformation_read", [&] {
    const auto op = live(operation, "operation");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    if (!op->ready()) throw CStatus{SS_NOT_READY, "the deformation is still running; poll until it is ready"};
    const Result<DeformationResult>& r = op->future.get();
    if (!r.ok()) throw Exception(r.error());
    write_xyz(r.value().positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r.value().res_id;
  });
}

ss_status ss_deformation_read_model(ss_deformation* operation, int32_t* out_model, int32_t* out_iterations,
                                    double* out_residual) {
  return guard("ss_deformation_read_model", [&] {
    const auto op = live(operation, "operation");
    if (!op->ready()) throw CStatus{SS_NOT_READY, "the deformation is still running; poll until it is ready"};
    const Result<DeformationResult>& r = op->future.get();
    if (!r.ok()) throw Exception(r.error());
    write_model(r.value(), out_model, out_iterations, out_residual);
  });
}

void ss_deformation_destroy(ss_deformation* operation) {
  try {
    std::shared_ptr<void> object =
        handles().remove(reinterpret_cast<uintptr_t>(operation), Kind::kDeformation, "ss_deformation_destroy");
    const auto op = std::static_pointer_cast<DeformationObject>(object);
    if (op && op->future.valid() && !op->ready()) reaper().adopt(*op);
  } catch (...) {
    // Out of memory while adopting: the operation is released here and may then wait.
  }
}

ss_status ss_session_latest_result(ss_session* session, const ss_geom_id* id, uint32_t have, int32_t wait_ms,
                                   int32_t* out_has_new, uint32_t* out_res_id, double* out_xyz, int32_t capacity,
                                   int32_t* out_count) {
  return guard("ss_session_latest_result", [&] {
    const auto s = live(session, "session");
    required(out_has_new, "out_has_new");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    count_arg(wait_ms, "wait_ms");
    *out_has_new = 0;
    const auto r = s->latest_result(geom_id(id), have, std::chrono::milliseconds(wait_ms)).value();
    if (!r) {
      *out_count = 0;
      return;
    }
    write_xyz(r->positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r->res_id;
    *out_has_new = 1;
  });
}

ss_status ss_session_geometry_status(ss_session* session, const ss_geom_id* id, ss_geometry_status* out_status,
                                     char* out_error, int32_t error_capacity) {
  return guard("ss_session_geometry_status", [&] {
    const auto s = live(session, "session");
    required(out_status, "out_status");
    count_arg(error_capacity, "error_capacity");
    write_string("", out_error, error_capacity);
    const GeometryInfo info = s->geometry_info(geom_id(id)).value();
    ss_geometry_status& o = *out_status;
    o.status = info.status == GeometryStatus::kReady    ? SS_GEOMETRY_READY
               : info.status == GeometryStatus::kFailed ? SS_GEOMETRY_FAILED
                                                        : SS_GEOMETRY_PRECOMPUTING;
    o.num_vertices = info.vertices;
    o.num_faces = info.faces;
    o.num_results = info.results;
    o.progress = info.status == GeometryStatus::kReady ? 1.0 : info.progress;
    if (info.status == GeometryStatus::kFailed) write_string(info.error, out_error, error_capacity);
  });
}

ss_status ss_session_limit_comb(ss_session* session, const ss_geom_id* id, const ss_surface_point* p,
                                int32_t* out_indices, double* out_position, double* out_du, double* out_dv,
                                int32_t capacity, int32_t* out_count) {
  return guard("ss_session_limit_comb", [&] {
    const auto s = live(session, "session");
    const SurfacePoint sp = point(p, "point");
    required(out_count, "out_count");
    count_arg(capacity, "capacity");
    const LimitComb comb = s->limit_comb(geom_id(id), sp).value();
    write_items(out_indices, capacity, out_count, comb.indices.size(), "limit combination", [&](int32_t* o) {
      std::copy(comb.indices.begin(), comb.indices.end(), o);
      if (out_position) std::copy(comb.position.begin(), comb.position.end(), out_position);
      if (out_du) std::copy(comb.du.begin(), comb.du.end(), out_du);
      if (out_dv) std::copy(comb.dv.begin(), comb.dv.end(), out_dv);
    });
  });
}

ss_status ss_session_stresses(ss_session* session, const ss_geom_id* id, uint32_t res_id, int32_t level,
                              const ss_surface_point* points, int32_t num_points, double yield_strength,
                              ss_stress_field** out_field) {
  return guard("ss_session_stresses", [&] {
    required(out_field, "out_field");
    *out_field = nullptr;
    const auto s = live(session, "session");
    StressQuery query;
    if (level < 0 || level > StressQuery::kMaxLevel) {
      fail(ErrorCode::kInvalidArgument, "level must be 1.." + std::to_string(StressQuery::kMaxLevel) +
                                            " (tessellation vertices) or 0 (the given points), got " +
                                            std::to_string(level));
    }
    query.level = level;
    count_arg(num_points, "num_points");
    if (level == 0) {
      if (num_points == 0) fail(ErrorCode::kInvalidArgument, "level 0 asks for the given points, but num_points is 0");
      if (static_cast<size_t>(num_points) > StressQuery::kMaxPoints) {
        fail(ErrorCode::kInvalidArgument, "at most " + std::to_string(StressQuery::kMaxPoints) +
                                              " points per query, got " + std::to_string(num_points));
      }
      required(points, "points");
      query.points.reserve(static_cast<size_t>(num_points));
      for (int32_t i = 0; i < num_points; ++i) query.points.push_back(point(points + i, "points"));
    } else if (num_points != 0) {
      fail(ErrorCode::kInvalidArgument, "give either a level (1..4) or points (level 0), not both");
    }
    if (!std::isfinite(yield_strength) || yield_strength < 0.0) {
      fail(ErrorCode::kInvalidArgument, "yield_strength must be finite and >= 0 (Pa; 0 = unknown)");
    }
    query.yield_strength = yield_strength;
    auto field = std::make_shared<StressField>(s->stresses(geom_id(id), res_id, query).value());
    *out_field = make_handle<ss_stress_field>(std::move(field));
  });
}

ss_status ss_stress_field_samples(const ss_stress_field* field, ss_stress_sample* out_samples, int32_t capacity,
                                  int32_t* out_count) {
  return guard("ss_stress_field_samples", [&] {
    const auto f = live(field, "field");
    write_items(out_samples, capacity, out_count, f->samples.size(), "stress samples", [&](ss_stress_sample* o) {
      for (const StressSample& sample : f->samples) *o++ = stress_to_c(sample);
    });
  });
}

ss_status ss_stress_field_max(const ss_stress_field* field, ss_stress_sample* out_max, int32_t* out_exceeds_yield) {
  return guard("ss_stress_field_max", [&] {
    const auto f = live(field, "field");
    *required(out_max, "out_max") = stress_to_c(f->max);
    if (out_exceeds_yield) *out_exceeds_yield = f->exceeds_yield ? 1 : 0;
  });
}

void ss_stress_field_destroy(ss_stress_field* field) { destroy(field, "ss_stress_field_destroy"); }

}  // extern "C"
