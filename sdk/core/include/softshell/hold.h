#pragma once
/// \file
/// \brief Holds (PROTOCOL.md version 2): one participant's standing contribution to an object (a
/// hand, a pin, a body resting on it, the floor), and what the server reports about them.
///
/// A hold has the contents of a `DeformationRequest` and a name chosen by its client; the
/// object's *hold state* is the solve of all live holds together. Every change of a hold gets the
/// next version of that hold (1, 2, ...); a result of the hold state says which version of every
/// hold it includes.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "softshell/deformation.h"

namespace softshell {

/// Longest hold id (characters of `[A-Za-z0-9._-]`).
inline constexpr size_t kMaxHoldIdLength = 64;

/// The versions of the holds a hold-state result includes, sorted by hold id.
using HoldVersions = std::vector<std::pair<std::string, uint64_t>>;

/// The version of `hold_id` in `versions`; 0 if the result does not include that hold.
inline uint64_t version_of(const HoldVersions& versions, std::string_view hold_id) {
  for (const auto& [id, version] : versions) {
    if (id == hold_id) return version;
  }
  return 0;
}

/// Where a geometry's hold state is.
enum class HoldStateStatus : uint8_t {
  kSolved,      ///< the newest hold-state result includes every live hold's newest version
  kSolving,     ///< changes are waiting for (or in) the solve
  kUnsolvable,  ///< a release left the remaining holds unsolvable; no result until a change fixes it
};

/// One live hold (`GET /geometries/{id}/holds`).
struct HoldInfo {
  std::string hold_id;
  uint64_t version = 0;     ///< the hold's newest version
  double expires_in = 0.0;  ///< seconds until its lease ends unless it is PUT again
};

/// A geometry's holds and the state of their solve.
struct HoldList {
  std::vector<HoldInfo> holds;                       ///< sorted by hold id
  uint32_t res_id = 0;                               ///< newest stored result of the hold state (0 = none)
  HoldStateStatus state = HoldStateStatus::kSolved;
  std::string message;                               ///< why the state is unsolvable ("" otherwise)
};

/// One hold with its contents (`GET /geometries/{id}/holds/{hold_id}`).
struct HoldDetail {
  HoldInfo info;
  DeformationRequest request;
};

/// A result with the hold versions its hold state includes (`holds` is absent for results of
/// `POST .../results`, which are solved alone).
struct HeldResult {
  DeformationResult result;
  std::optional<HoldVersions> holds;
};

}  // namespace softshell
