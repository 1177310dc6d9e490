#pragma once
// The engine's preconditions on a request (private). Requests are validated once, at the boundary
// (softshell/request_validation.h: the service, the C ABI); the engine asserts the same rules
// (SOFTSHELL_ASSERT: a failure is a bug of the caller), each rule in one place.

#include "softshell/deformation.h"
#include "softshell/engine/shell_model.h"

namespace softshell::engine::internal {

/// Asserts that the forces, surface forces, surface load and pressure are valid (load_vector).
void check_loads(const ShellModel& model, const DeformationRequest& request);

/// Asserts that the vertex, Lagrange and limit constraints are valid (the solver; the loads are
/// checked where the load vector is built).
void check_constraints(const ShellModel& model, const DeformationRequest& request);

}  // namespace softshell::engine::internal
