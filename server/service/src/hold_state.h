#pragma once
// The hold state of a geometry as linear algebra (private to the service): every live hold's
// contents as one block of the combined request, the solve of that request, and the analysis
// that tells a hold contradicting others (409) from a state left undetermined (422).

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "softshell/deformation.h"
#include "softshell/engine/nonlinear_solver.h"
#include "softshell/engine/solver.h"
#include "softshell/hold.h"
#include "memory_budget.h"
#include "softshell/limit_evaluator.h"
#include "softshell/result.h"

namespace softshell::service::internal {

/// A content key: the first 16 bytes of SHA-256 over a hold's canonical request.
using BlockKey = std::array<uint8_t, 16>;

/// One version of a hold's contents (immutable once made).
struct HoldVersion {
  uint64_t version = 0;
  DeformationRequest request;
  std::string canonical;  // wire::encode_request_json(request): equal contents <=> equal text
  BlockKey key{};         // of `canonical`: the same whenever the contents are
  size_t bytes = 0;       // what it counts against the memory budget
};
using HoldVersionPtr = std::shared_ptr<const HoldVersion>;

/// Makes a version from a request (computes the canonical text, key and size) and reserves its
/// size in `budget` until the last reference to it is dropped; kResourceExhausted if it does not
/// fit. (`budget` must outlive every version.)
Result<std::shared_ptr<HoldVersion>> make_hold_version(DeformationRequest request, MemoryBudget& budget);

/// The holds a hold state is made of, by hold id (sorted: the assembly order is deterministic).
using HoldMap = std::map<std::string, HoldVersionPtr, std::less<>>;

/// The versions a result of `holds` includes.
HoldVersions versions_of(const HoldMap& holds);

/// One hold's share of the combined request: its rows are contiguous there, and `key` names its
/// contents, so a solver that caches constraint blocks by content can reuse an unchanged hold's.
struct HoldBlock {
  std::string_view hold_id;
  uint64_t version = 0;
  const BlockKey* key = nullptr;
  const DeformationRequest* request = nullptr;
  // Half-open ranges of its items in `AssembledHoldState::merged`.
  size_t vertex_begin = 0, vertex_end = 0;
  size_t lagrange_begin = 0, lagrange_end = 0;
  size_t limit_begin = 0, limit_end = 0;
};

/// The model a hold state is solved with: nonlinear when any of its holds asks for it
/// (PROTOCOL.md "The nonlinear model"), else linear.
DeformationModel model_of(const HoldMap& holds);

/// The hold state as one request: constraints combined block by block (in hold-id order), loads
/// added, `model` = model_of(holds). Valid while the `HoldMap` it was made from lives.
struct AssembledHoldState {
  std::vector<HoldBlock> blocks;
  DeformationRequest merged;
};
AssembledHoldState assemble(const HoldMap& holds);

/// A solved hold state.
struct HoldSolution {
  Eigen::VectorXd displacement;                     ///< 3n
  engine::SolveStats stats;                         ///< of a linear solve
  std::optional<engine::NonlinearStats> nonlinear;  ///< of a nonlinear solve
};

/// The solvers of a geometry's hold state, and where a nonlinear solve starts.
struct HoldSolvers {
  const engine::Solver& linear;
  const engine::NonlinearSolver& nonlinear;
  /// The previous nonlinear answer of this hold state (3n), the warm start of the next nonlinear
  /// solve during a drag; null: from rest.
  const Eigen::VectorXd* previous = nullptr;
};

/// Solves an assembled hold state with `state.merged.model` (no hold: the rest shape, zero
/// displacement, linear). A nonlinear solve starts from `solvers.previous`; if it cannot reach
/// equilibrium from there it is tried once more from rest (the warm start only saves time; a
/// state the solver reaches only from rest is still solved). Never an unconverged answer: the
/// engine's kUnprocessable (with its message) instead.
///
/// This is the seam for the engine's cache of constraint blocks keyed by content (issue 12,
/// "Constraints at full speed"): today it hands `state.merged` to `Solver::solve`, which rebuilds
/// every hold's rows on each solve; once the engine takes blocks, pass `state.blocks` (rows and
/// key of each hold) instead, so that holds that did not change between two solves cost almost
/// nothing and a changed hand about one grab. Nothing else in the service needs to change.
Result<HoldSolution> solve_hold_state(const HoldSolvers& solvers, const AssembledHoldState& state);

/// Why the hold state with `hold_id`'s new version `trial.at(hold_id)` could not be solved, as
/// the error its PUT gets: kUnprocessable (422) if the hold contradicts itself or the state is
/// otherwise undetermined or unsolvable, kConflict (409) naming the other holds it contradicts
/// (a smallest set of them). `previous` is the version the hold keeps (0: it is not created).
/// Other codes of `solve_error` are passed on.
Error explain_refusal(const HoldMap& trial, const std::string& hold_id, uint64_t previous, const Error& solve_error,
                      const LimitEvaluator& evaluator, double length);

/// Whether the linear constraints (vertex, Lagrange and limit constraints) of the holds named in
/// `subset` can all be met at once; if not, `detail` says which equation misses by how much.
/// Exposed for tests.
bool constraints_consistent(const HoldMap& holds, const std::vector<std::string>& subset,
                            const LimitEvaluator& evaluator, double length, std::string* detail);

}  // namespace softshell::service::internal
