// The handle table (c_api_internal.h): slot index + generation, checked on every call.

#include <chrono>
#include <cstdlib>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "c_api_internal.h"

namespace softshell::c_api {
namespace {

// A handle's value: generation in the high bits, slot index + 1 in the low ones (so that no
// handle is 0 = NULL). 64-bit pointers: 32 + 32 bits; 32-bit pointers: a 20-bit index (about a
// million live handles) and a 12-bit generation.
constexpr int kIndexBits = sizeof(uintptr_t) >= 8 ? 32 : 20;
constexpr int kGenerationBits = static_cast<int>(sizeof(uintptr_t) * 8) - kIndexBits;
constexpr uintptr_t kIndexMask = (uintptr_t{1} << kIndexBits) - 1;
constexpr uint64_t kGenerationMask = (uint64_t{1} << kGenerationBits) - 1;

uintptr_t encode(uint32_t index, uint32_t generation) {
  return (static_cast<uintptr_t>(generation) << kIndexBits) | (static_cast<uintptr_t>(index) + 1);
}

// The next generation of a slot, never 0 (0 would let a forged small integer pass as a handle).
uint32_t next_generation(uint32_t g) {
  const uint32_t next = static_cast<uint32_t>((uint64_t{g} + 1) & kGenerationMask);
  return next == 0 ? 1 : next;
}

}  // namespace

const char* kind_name(Kind kind) {
  switch (kind) {
    case Kind::kMesh: return "ss_mesh";
    case Kind::kEvaluator: return "ss_evaluator";
    case Kind::kTessellation: return "ss_tessellation";
    case Kind::kPicker: return "ss_picker";
    case Kind::kRequest: return "ss_request";
    case Kind::kGrab: return "ss_grab";
    case Kind::kRefinement: return "ss_refinement";
    case Kind::kSession: return "ss_session";
    case Kind::kDeformation: return "ss_deformation";
    case Kind::kStressField: return "ss_stress_field";
    case Kind::kHoldPut: return "ss_hold_put";
    case Kind::kSubscription: return "ss_subscription";
    case Kind::kNone: break;
  }
  return "handle";
}

uintptr_t HandleTable::insert(Kind kind, std::shared_ptr<void> object) {
  std::lock_guard lock(mutex_);
  uint32_t index = 0;
  if (!free_.empty()) {
    index = free_.back();
    free_.pop_back();
  } else {
    if (slots_.size() >= kIndexMask - 1) fail(ErrorCode::kResourceExhausted, "too many live softshell handles");
    index = static_cast<uint32_t>(slots_.size());
    slots_.emplace_back();
  }
  Slot& slot = slots_[index];
  slot.kind = kind;
  slot.object = std::move(object);
  ++live_;
  return encode(index, slot.generation);
}

std::shared_ptr<void> HandleTable::get(uintptr_t handle, Kind kind, const char* argument) const {
  if (handle == 0) fail(ErrorCode::kInvalidArgument, std::string(argument) + " is NULL");
  const uintptr_t index1 = handle & kIndexMask;
  const uint64_t generation = static_cast<uint64_t>(handle) >> kIndexBits;
  std::lock_guard lock(mutex_);
  if (index1 == 0 || index1 > slots_.size() || generation == 0 || generation > kGenerationMask) {
    fail(ErrorCode::kInvalidArgument, std::string(argument) + " is not a handle made by softshell (expected an " +
                                          kind_name(kind) + ")");
  }
  const Slot& slot = slots_[index1 - 1];
  if (slot.generation != generation) {
    fail(ErrorCode::kInvalidArgument, std::string(argument) + " is a destroyed handle (expected a live " +
                                          kind_name(kind) + "); using a handle after its destroy is a bug");
  }
  if (slot.kind != kind) {
    // ("an": every kind's name starts with "ss_", read "ess ess")
    fail(ErrorCode::kInvalidArgument,
         std::string(argument) + " is an " + kind_name(slot.kind) + ", not an " + kind_name(kind));
  }
  return slot.object;
}

std::shared_ptr<void> HandleTable::remove(uintptr_t handle, Kind kind, const char* function) {
  if (handle == 0) return nullptr;
  const uintptr_t index1 = handle & kIndexMask;
  const uint64_t generation = static_cast<uint64_t>(handle) >> kIndexBits;
  std::shared_ptr<void> object;
  {
    std::lock_guard lock(mutex_);
    if (index1 != 0 && index1 <= slots_.size()) {
      Slot& slot = slots_[index1 - 1];
      if (slot.generation == generation && slot.kind == kind) {
        free_.push_back(static_cast<uint32_t>(index1 - 1));  // first: the only step that can throw
        object = std::move(slot.object);
        slot.object.reset();
        slot.kind = Kind::kNone;
        slot.generation = next_generation(slot.generation);
        --live_;
        return object;
      }
    }
  }
  log(SS_LOG_WARNING, std::string(function) + ": not a live " + kind_name(kind) +
                          " (destroyed twice, or another kind of handle); nothing was released");
  return nullptr;
}

size_t HandleTable::size() const {
  std::lock_guard lock(mutex_);
  return live_;
}

HandleTable& handles() {
  // Never destroyed: handles may be released from static destructors of the host.
  static auto* table = new HandleTable;
  return *table;
}

namespace {

struct RunningRequests {
  std::mutex mutex;
  std::vector<std::function<bool(std::chrono::steady_clock::time_point)>> waits;  // true once done
};

RunningRequests& running_requests() {
  static auto* requests = new RunningRequests;  // (never destroyed: used at exit)
  return *requests;
}

void finish_running_requests() {
  std::vector<std::function<bool(std::chrono::steady_clock::time_point)>> waits;
  {
    std::lock_guard lock(running_requests().mutex);
    waits.swap(running_requests().waits);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(1);
  size_t abandoned = 0;
  for (const auto& wait_until : waits) abandoned += wait_until(deadline) ? 0 : 1;
  if (abandoned > 0) {
    log(SS_LOG_WARNING, std::to_string(abandoned) + " asynchronous request(s) still running a minute after exit began " +
                            "were abandoned; wait for operations before exiting to keep their results");
  }
}

}  // namespace

void finish_before_exit(std::function<bool(std::chrono::steady_clock::time_point)> wait_until) {
  RunningRequests& requests = running_requests();
  std::lock_guard lock(requests.mutex);
  [[maybe_unused]] static const bool registered = [] {
    if (std::atexit(finish_running_requests) == 0) return true;
    log(SS_LOG_WARNING, "could not register the wait for running requests at exit; exit may cut them short");
    return false;
  }();
  // Forget finished requests here, so the list holds only running ones.
  const auto no_wait = std::chrono::steady_clock::time_point::min();
  std::erase_if(requests.waits, [&](const auto& done_by) { return done_by(no_wait); });
  requests.waits.push_back(std::move(wait_until));
}

}  // namespace softshell::c_api
