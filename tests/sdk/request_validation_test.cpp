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

namespace softshell {
namespace {

void expect_over_limit(const Result<void>& r, const std::string& part) {
  ASSERT_FALSE(r.ok()) << "expected a refusal mentioning '" << part << "'";
  EXPECT_EQ(r.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(r.error().message.find(part), std::string::npos) << r.error().message;
}

// The counts one request may have: bounded so that a small body cannot hold a solver for
// seconds (each surface constraint is three dense rows beside the factor).
TEST(RequestValidation, CountsAreBoundedByTheLimitsAndTheControlPoints) {
  const RequestLimits big = RequestLimits::for_control_points(10000);
  EXPECT_EQ(big.surface_constraints, RequestLimits::kMaxSurfaceConstraints);
  EXPECT_EQ(big.vertex_constraints, RequestLimits::kMinElementLimit);
  const RequestLimits huge = RequestLimits::for_control_points(100000);
  EXPECT_EQ(huge.vertex_constraints, 300000u);
  EXPECT_EQ(huge.forces, 400000u);
  const RequestLimits small = RequestLimits::for_control_points(12);
  EXPECT_EQ(small.surface_constraints, 12u);  // no more than the control points

  const RequestContext many{10000, nullptr};
  DeformationRequest r;
  LagrangeConstraint one{{5}, {Vec3(1, 1, 1)}, Vec3::Zero()};
  r.lagrange_constraints.assign(200, one);
  r.limit_constraints.assign(56, LimitConstraint{{0, 0, 0.5, 0.5}, Vec3::Zero(), std::nullopt, std::nullopt});
  EXPECT_TRUE(validate_request(r, many).ok());  // 256: at the limit
  r.lagrange_constraints.push_back(one);
  expect_over_limit(validate_request(r, many), "257 Lagrange and limit constraints; one request may have at most 256");
  EXPECT_TRUE(validate_request(r, {}).ok());  // without the geometry nothing is counted (C ABI elements)

  const RequestContext twelve{12, nullptr};
  DeformationRequest pins;
  pins.vertex_constraints.assign(RequestLimits::kMinElementLimit, VertexConstraint{3, kAxisAll, Vec3::Zero()});
  EXPECT_TRUE(validate_request(pins, twelve).ok());
  pins.vertex_constraints.push_back(pins.vertex_constraints.back());
  expect_over_limit(validate_request(pins, twelve), "65537 vertex constraints");

  DeformationRequest pushes;
  pushes.forces.assign(RequestLimits::kMinElementLimit + 1, PointForce{2, Vec3(0, 0, 1)});
  expect_over_limit(validate_request(pushes, twelve), "send their sum once");

  DeformationRequest long_row;
  long_row.lagrange_constraints.push_back({std::vector<int32_t>(13, 1), std::vector<Vec3>(13, Vec3(1, 0, 0)), Vec3::Zero()});
  expect_over_limit(validate_request(long_row, twelve), "13 terms");

  DeformationRequest spread;
  spread.surface_forces.assign(RequestLimits::kMaxSurfaceForces + 1, SurfaceForce{{0, 0, 0.5, 0.5}, Vec3(0, 0, 1)});
  expect_over_limit(validate_request(spread, many), "4097 surface forces");
}

}  // namespace
}  // namespace softshell
