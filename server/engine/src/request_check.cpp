#include "request_check.h"

#include "softshell/assert.h"
#include "softshell/request_validation.h"

namespace softshell::engine::internal {
namespace {

void assert_valid(const Result<void>& valid) {
  SOFTSHELL_ASSERT(valid.ok(), "the engine was given a request that does not pass validate_request (validate "
                               "requests at the boundary, as the service does): " + valid.error().message);
}

}  // namespace

void check_loads(const ShellModel& model, const DeformationRequest& request) {
  const RequestContext context{model.num_control_points(), &model.evaluator()};
  for (size_t k = 0; k < request.forces.size(); ++k) assert_valid(validate(request.forces[k], k, context));
  for (size_t k = 0; k < request.surface_forces.size(); ++k) {
    assert_valid(validate(request.surface_forces[k], k, context));
  }
  assert_valid(validate_loads(request.surface_load, request.pressure));
}

void check_constraints(const ShellModel& model, const DeformationRequest& request) {
  const RequestContext context{model.num_control_points(), &model.evaluator()};
  for (size_t k = 0; k < request.vertex_constraints.size(); ++k) {
    assert_valid(validate(request.vertex_constraints[k], k, context));
  }
  for (size_t k = 0; k < request.lagrange_constraints.size(); ++k) {
    assert_valid(validate(request.lagrange_constraints[k], k, context));
  }
  for (size_t k = 0; k < request.limit_constraints.size(); ++k) {
    assert_valid(validate(request.limit_constraints[k], k, context));
  }
}

}  // namespace softshell::engine::internal
