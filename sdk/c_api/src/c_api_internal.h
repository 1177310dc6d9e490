#pragma once
// Private to the C ABI's sources: the handle table, the objects behind each handle kind, and the
// argument and buffer helpers every entry point uses. (Not installed.)
//
// Handles are generation-checked ids, as Box2D's: a handle's value encodes a slot index of one
// process-wide table and the slot's generation when the handle was made. Destroying a handle bumps
// the generation, so a stale handle is recognised by comparing numbers, without ever reading freed
// memory; a slot reused by a later object does not revive the old handle. The value travels as the
// typed pointer of softshell_c.h (`ss_mesh*` ...), which C never dereferences (Vulkan's
// non-dispatchable handles do the same), so C, C# (IntPtr) and Unreal code keep their signatures.

#include <chrono>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/interaction.h"
#include "softshell/level_of_detail.h"
#include "softshell/limit_evaluator.h"
#include "softshell/picking.h"
#include "softshell/result.h"
#include "softshell/session.h"
#include "softshell/stresses.h"
#include "softshell/softshell_c.h"
#include "softshell/tessellation.h"

namespace softshell::c_api {

// ------------------------------------------------------------------------------------------------
// Objects behind the handles

/// A picker refers to its tessellation, so it keeps it alive.
struct PickerObject {
  std::shared_ptr<Tessellation> tessellation;
  Picker picker;
};

/// An asynchronous deformation: the session stays alive while the request runs.
struct DeformationObject {
  std::shared_ptr<Session> session;
  std::shared_future<Result<DeformationResult>> future;
  bool ready() const { return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready; }
};

/// An asynchronous put of a hold.
struct HoldPutObject {
  std::shared_ptr<Session> session;
  std::string hold_id;
  std::shared_future<Result<HeldResult>> future;
  bool ready() const { return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready; }
};

/// Asynchronous requests still running when the process exits are waited for (up to a minute
/// in all) by an atexit handler registered with the first one. It runs before the libraries'
/// own teardown (BLAS frees its state at unload), so exit neither abandons a request mid-flight
/// nor unloads what a running solve still uses. Every `*_begin` entry point calls this.
void finish_before_exit(std::function<bool(std::chrono::steady_clock::time_point)> wait_until);
template <class T>
void finish_before_exit(const std::shared_future<T>& future) {
  finish_before_exit([future](std::chrono::steady_clock::time_point deadline) {
    return future.wait_until(deadline) == std::future_status::ready;
  });
}

/// Asynchronous operations destroyed while running: kept (with their session) until they finish,
/// so that destroying one never blocks (the last reference to a session would wait for its
/// requests) and no request is abandoned mid-flight. Failures nobody read are logged as
/// "<what(op)> destroyed before it was read failed: ...". One per operation kind, never destroyed
/// (orphans finish during exit: see finish_before_exit).
void log(int32_t level, std::string_view message) noexcept;  // (below)

template <class Operation>
class Reaper {
 public:
  using Describe = std::string (*)(const Operation&);
  explicit Reaper(Describe what) : what_(what) {}
  void adopt(const Operation& op) {
    std::lock_guard lock(mutex_);
    purge();
    orphans_.push_back(op);
  }
  void purge_finished() {
    std::lock_guard lock(mutex_);
    purge();
  }

 private:
  void purge() {
    std::erase_if(orphans_, [this](const Operation& o) {
      if (!o.ready()) return false;
      const auto& r = o.future.get();
      if (!r.ok()) c_api::log(SS_LOG_WARNING, what_(o) + " destroyed before it was read failed: " + r.error().message);
      return true;
    });
  }
  Describe what_;
  std::mutex mutex_;
  std::vector<Operation> orphans_;
};

/// A subscription, and a result taken from it that did not fit the caller's buffer yet.
struct SubscriptionObject {
  std::shared_ptr<Session> session;  // (destroyed after the subscription)
  std::unique_ptr<EventSubscription> subscription;
  std::mutex mu;
  std::optional<HeldResult> held_back;
};

enum class Kind : uint8_t {
  kNone = 0,
  kMesh,
  kEvaluator,
  kTessellation,
  kPicker,
  kRequest,
  kGrab,
  kRefinement,
  kSession,
  kDeformation,
  kStressField,
  kHoldPut,
  kSubscription,
};
/// "ss_mesh", "ss_evaluator", ...
const char* kind_name(Kind kind);

/// The C handle type of each kind and the C++ object behind it.
template <class Handle>
struct HandleTraits;
#define SOFTSHELL_C_HANDLE(handle_type, kind_value, object_type) \
  template <>                                                     \
  struct HandleTraits<handle_type> {                              \
    static constexpr Kind kind = Kind::kind_value;                \
    using Object = object_type;                                   \
  };
SOFTSHELL_C_HANDLE(ss_mesh, kMesh, ControlMesh)
SOFTSHELL_C_HANDLE(ss_evaluator, kEvaluator, LimitEvaluator)
SOFTSHELL_C_HANDLE(ss_tessellation, kTessellation, Tessellation)
SOFTSHELL_C_HANDLE(ss_picker, kPicker, PickerObject)
SOFTSHELL_C_HANDLE(ss_request, kRequest, DeformationRequest)
SOFTSHELL_C_HANDLE(ss_grab, kGrab, Grab)
SOFTSHELL_C_HANDLE(ss_refinement, kRefinement, MeshRefinement)
SOFTSHELL_C_HANDLE(ss_session, kSession, Session)
SOFTSHELL_C_HANDLE(ss_deformation, kDeformation, DeformationObject)
SOFTSHELL_C_HANDLE(ss_stress_field, kStressField, StressField)
SOFTSHELL_C_HANDLE(ss_hold_put, kHoldPut, HoldPutObject)
SOFTSHELL_C_HANDLE(ss_subscription, kSubscription, SubscriptionObject)
#undef SOFTSHELL_C_HANDLE

// ------------------------------------------------------------------------------------------------
// The handle table

/// Every live handle of the process. Thread-safe; lookups copy the object's shared_ptr under a
/// mutex, so a call in flight keeps its object alive even if another thread destroys the handle.
class HandleTable {
 public:
  /// A new handle for `object` (never 0). Throws kResourceExhausted when the index space is full.
  uintptr_t insert(Kind kind, std::shared_ptr<void> object);
  /// The object of a live handle of `kind`; throws kInvalidArgument saying what is wrong with it
  /// (NULL, never made by softshell, destroyed, or of another kind), naming `argument`.
  std::shared_ptr<void> get(uintptr_t handle, Kind kind, const char* argument) const;
  /// Takes a live handle of `kind` out of the table and returns its object (for the caller to
  /// release outside the lock). Empty, and a warning logged, for a handle that is not live; empty
  /// and silent for 0.
  std::shared_ptr<void> remove(uintptr_t handle, Kind kind, const char* function);
  /// Live handles (for tests: leaks show up here).
  size_t size() const;

 private:
  struct Slot {
    uint32_t generation = 1;
    Kind kind = Kind::kNone;
    std::shared_ptr<void> object;
  };
  mutable std::mutex mutex_;
  std::vector<Slot> slots_;
  std::vector<uint32_t> free_;
  size_t live_ = 0;
};

HandleTable& handles();

/// The object behind `handle`, or an exception (see HandleTable::get).
template <class H>
std::shared_ptr<typename HandleTraits<H>::Object> live(const H* handle, const char* argument) {
  return std::static_pointer_cast<typename HandleTraits<H>::Object>(
      handles().get(reinterpret_cast<uintptr_t>(handle), HandleTraits<H>::kind, argument));
}

/// A new handle owning `object`.
template <class H>
H* make_handle(std::shared_ptr<typename HandleTraits<H>::Object> object) {
  return reinterpret_cast<H*>(handles().insert(HandleTraits<H>::kind, std::move(object)));
}

/// Releases a handle; NULL is a no-op, a stale or foreign handle only logs a warning.
template <class H>
void destroy(H* handle, const char* function) noexcept {
  try {
    std::shared_ptr<void> object = handles().remove(reinterpret_cast<uintptr_t>(handle), HandleTraits<H>::kind, function);
    object.reset();  // outside the table's lock: a destructor may take a while
  } catch (...) {
    // remove() only allocates for its warning; nothing to report from a destroy.
  }
}

// ------------------------------------------------------------------------------------------------
// Errors and logging

/// A status that exists only in the C ABI (SS_BUFFER_TOO_SMALL, SS_NOT_READY), thrown inside a guard.
struct CStatus {
  ss_status status;
  std::string message;
};

/// Logs to the SDK's process-wide sink (softshell/log.h), which is the C log callback when one is
/// installed (ss_set_log_callback). `level`: SS_LOG_*.
void log(int32_t level, std::string_view message) noexcept;

// ------------------------------------------------------------------------------------------------
// Arguments in, buffers out

template <class T>
T* required(T* p, const char* argument) {
  if (p == nullptr) fail(ErrorCode::kInvalidArgument, std::string(argument) + " is NULL");
  return p;
}

int32_t count_arg(int32_t n, const char* argument);
Vec3 vec(const ss_vec3* v, const char* argument);
inline ss_vec3 to_c(const Vec3& v) { return ss_vec3{v.x(), v.y(), v.z()}; }
SurfacePoint point(const ss_surface_point* p, const char* argument);
inline ss_surface_point to_c(const SurfacePoint& p) { return ss_surface_point{p.face, p.subface, p.u, p.v}; }
Pose pose(const ss_pose* p, const char* argument);
/// `count` xyz triples from `xyz` (which may be NULL only for count 0), all finite.
std::vector<Vec3> read_xyz(const double* xyz, int32_t count, const char* argument);
GeomId geom_id(const ss_geom_id* id);
Material material(const ss_material* m, const char* argument);
ss_material to_c(const Material& m);

/// The buffer convention of softshell_c.h: always report the count; NULL/0 asks only for it; a
/// buffer too small writes nothing (SS_BUFFER_TOO_SMALL).
template <class T, class Fill>
void write_items(T* out, int32_t capacity, int32_t* out_count, size_t items, const char* what, Fill&& fill) {
  required(out_count, "out_count");
  count_arg(capacity, "capacity");
  if (items > static_cast<size_t>(INT32_MAX)) {
    fail(ErrorCode::kResourceExhausted, std::string(what) + ": too many items for an int32 count");
  }
  *out_count = static_cast<int32_t>(items);
  if (out == nullptr) {
    if (capacity == 0) return;  // size query
    fail(ErrorCode::kInvalidArgument,
         std::string(what) + ": the output buffer is NULL but capacity is " + std::to_string(capacity));
  }
  if (static_cast<size_t>(capacity) < items) {
    throw CStatus{SS_BUFFER_TOO_SMALL, std::string(what) + ": needs " + std::to_string(items) +
                                           " items, the buffer holds " + std::to_string(capacity)};
  }
  fill(out);
}

void write_xyz(const std::vector<Vec3>& points, double* out, int32_t capacity, int32_t* out_count, const char* what);
/// How a result was solved, into the outputs of ss_*_read_model (each nullable).
void write_model(const DeformationResult& r, int32_t* out_model, int32_t* out_iterations, double* out_residual);
void write_xyz_f(const std::vector<Vec3>& points, float* out, int32_t capacity, int32_t* out_count, const char* what);
/// Copies `text` into a caller's char buffer, truncated to fit and always NUL-terminated (no-op for
/// a NULL buffer or capacity 0).
void write_string(std::string_view text, char* out, int32_t capacity);

}  // namespace softshell::c_api
