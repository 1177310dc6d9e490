// The one request validator (softshell/request_validation.h): every element kind, with and without
// the mesh known, and surface points against a real limit surface.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "softshell/limit_evaluator.h"
#include "softshell/request_validation.h"
#include "test_meshes.h"

namespace softshell {
namespace {

void expect_invalid(const Result<void>& r, const std::string& part) {
  ASSERT_FALSE(r.ok()) << "expected an error mentioning '" << part << "'";
  EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(r.error().message.find(part), std::string::npos) << r.error().message;
}

DeformationRequest valid_request() {
  DeformationRequest r;
  r.vertex_constraints = {{0, kAxisAll, Vec3::Zero()}, {9, kAxisZ, Vec3(0, 0, 0.01)}};
  r.lagrange_constraints = {{{1, 2}, {Vec3(0.5, 0.5, 0.5), Vec3(0.5, 0.5, 0.5)}, Vec3::Zero()}};
  r.forces = {{4, Vec3(0, 0, -1)}};
  r.limit_constraints = {{{3, 0, 0.25, 0.5}, Vec3(0, 0, 0.01), std::nullopt, std::nullopt}};
  r.surface_forces = {{{1, 0, 1.0, 0.0}, Vec3(1, 0, 0)}};
  r.surface_load = Vec3(0, 0, -9.81);
  r.pressure = 2.0;
  return r;
}

TEST(RequestValidation, AcceptsAValidRequest) {
  const ControlMesh grid = test::make_grid(3, 2);  // 12 control points, 6 faces
  const LimitEvaluator evaluator = LimitEvaluator::create(grid).value();
  EXPECT_TRUE(validate_request(valid_request(), {grid.num_vertices(), &evaluator}).ok());
  EXPECT_TRUE(validate_request(valid_request(), {}).ok());
  EXPECT_TRUE(validate_request(DeformationRequest{}, {}).ok());
}

TEST(RequestValidation, NamesTheFirstBadElement) {
  const RequestContext ten{10, nullptr};
  DeformationRequest r = valid_request();
  expect_invalid(validate_request(r, {9, nullptr}), "vertex constraint 1 refers to control point 9, but the geometry has 9");
  r.vertex_constraints[0].mask = 0;
  expect_invalid(validate_request(r, ten), "vertex constraint 0 has mask 0");
  r = valid_request();
  r.vertex_constraints[1].mask = 8;
  expect_invalid(validate_request(r, ten), "mask 8");
  r = valid_request();
  r.vertex_constraints[1].index = -1;
  expect_invalid(validate_request(r, {}), "0-based");
  r = valid_request();
  r.lagrange_constraints[0].coefficients.pop_back();
  expect_invalid(validate_request(r, ten), "they must match");
  r = valid_request();
  r.lagrange_constraints[0].values.y() = std::nan("");
  expect_invalid(validate_request(r, ten), "Lagrange constraint 0 has a value that is not finite");
  r = valid_request();
  r.forces[0].force.x() = INFINITY;
  expect_invalid(validate_request(r, ten), "force 0 is not finite");
  r = valid_request();
  r.limit_constraints[0].point.u = -0.1;
  expect_invalid(validate_request(r, ten), "[0, 1]");
  r = valid_request();
  r.limit_constraints[0].point.v = std::nan("");
  expect_invalid(validate_request(r, ten), "NaN");
  r = valid_request();
  r.limit_constraints[0].du_displacement = Vec3(0, std::nan(""), 0);
  expect_invalid(validate_request(r, ten), "tangent displacement");
  r = valid_request();
  r.surface_forces[0].point.face = -2;
  expect_invalid(validate_request(r, ten), "surface force 0 has a negative face index");
  r = valid_request();
  r.pressure = -INFINITY;
  expect_invalid(validate_request(r, ten), "the pressure is -inf");
  r = valid_request();
  r.surface_load.z() = std::nan("");
  expect_invalid(validate_request(r, ten), "surface load");
}

TEST(RequestValidation, ChecksSurfacePointsOnTheLimitSurface) {
  const ControlMesh grid = test::make_grid(3, 2);
  const LimitEvaluator evaluator = LimitEvaluator::create(grid).value();
  const RequestContext context{grid.num_vertices(), &evaluator};
  DeformationRequest r = valid_request();
  r.limit_constraints[0].point.face = 6;  // one past the last face
  expect_invalid(validate_request(r, context), "limit constraint 0");
  EXPECT_TRUE(validate_request(r, {grid.num_vertices(), nullptr}).ok()) << "without the surface only the range is known";
  r = valid_request();
  r.surface_forces[0].point.subface = 1;  // a quad has one sub-face
  expect_invalid(validate_request(r, context), "surface force 0");
}

TEST(RequestValidation, OneElementAtATime) {
  EXPECT_TRUE(validate(VertexConstraint{5, 3, Vec3::Zero()}, 7, {}).ok());
  expect_invalid(validate(VertexConstraint{5, 9, Vec3::Zero()}, 7, {}), "vertex constraint 7 has mask 9");
  expect_invalid(validate(PointForce{12, Vec3::Zero()}, 2, {12, nullptr}), "force 2 refers to control point 12");
  expect_invalid(validate_loads(Vec3::Zero(), std::nan("")), "the pressure is NaN");
}

}  // namespace
}  // namespace softshell
