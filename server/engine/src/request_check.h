#pragma once
// Validation of deformation requests against a model (private): every index, mask, number and
// surface point is checked before any numerics run, with messages that say what to fix.

#include "softshell/deformation.h"
#include "softshell/engine/shell_model.h"

namespace softshell::engine::internal {

/// Throws Exception(kInvalidArgument) for a bad force, surface force, surface load or pressure.
void check_loads(const ShellModel& model, const DeformationRequest& request);

/// Throws Exception(kInvalidArgument) for a bad constraint or load anywhere in the request.
void check_request(const ShellModel& model, const DeformationRequest& request);

}  // namespace softshell::engine::internal
