#include "softshell/mesh_validation.h"

#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell {
namespace {

ControlMesh square_pair() {
  // Two quads sharing edge 1-4.
  return ControlMesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0), Vec3(2, 1, 0)},
                     std::vector<std::vector<int32_t>>{{0, 1, 4, 3}, {1, 2, 5, 4}});
}

MeshIssue first_issue(const ControlMesh& mesh) {
  auto issues = find_mesh_issues(mesh);
  EXPECT_FALSE(issues.empty());
  return issues.empty() ? MeshIssue{MeshIssueKind::kEmpty, -1, -1, ""} : issues.front();
}

TEST(MeshValidation, ShippedMeshesAreValid) {
  for (const auto& name : test::asset_mesh_names()) {
    auto ok = validate_mesh(test::load_asset_mesh(name));
    EXPECT_TRUE(ok.ok()) << name << ": " << ok.error().message;
  }
  EXPECT_TRUE(validate_mesh(square_pair()).ok());
}

TEST(MeshValidation, Empty) {
  auto result = validate_mesh(ControlMesh{});
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(result.error().message.find("no control points"), std::string::npos);
}

TEST(MeshValidation, IndexOutOfRangeNamesFaceAndIndex) {
  ControlMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)}, std::vector<std::vector<int32_t>>{{0, 1, 7}});
  MeshIssue issue = first_issue(mesh);
  EXPECT_EQ(issue.kind, MeshIssueKind::kIndexOutOfRange);
  EXPECT_EQ(issue.face, 0);
  EXPECT_EQ(issue.code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(issue.message.find("face 0 refers to control point 7"), std::string::npos) << issue.message;
}

TEST(MeshValidation, RepeatedIndexAndSmallFace) {
  ControlMesh repeated({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)}, std::vector<std::vector<int32_t>>{{0, 1, 1, 2}});
  EXPECT_EQ(first_issue(repeated).kind, MeshIssueKind::kRepeatedIndex);
  EXPECT_NE(first_issue(repeated).message.find("twice"), std::string::npos);
  ControlMesh small({Vec3(0, 0, 0), Vec3(1, 0, 0)}, std::vector<std::vector<int32_t>>{{0, 1}});
  EXPECT_EQ(first_issue(small).kind, MeshIssueKind::kFaceTooSmall);
}

TEST(MeshValidation, NonFinite) {
  ControlMesh mesh = square_pair();
  mesh.positions()[4].y() = std::numeric_limits<double>::infinity();
  MeshIssue issue = first_issue(mesh);
  EXPECT_EQ(issue.kind, MeshIssueKind::kNonFinite);
  EXPECT_EQ(issue.vertex, 4);
}

TEST(MeshValidation, NonManifoldEdge) {
  ControlMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1)},
                   std::vector<std::vector<int32_t>>{{0, 1, 2}, {1, 0, 3}, {0, 1, 4}});
  auto issues = find_mesh_issues(mesh);
  bool found = false;
  for (const auto& issue : issues) found |= issue.kind == MeshIssueKind::kNonManifoldEdge;
  EXPECT_TRUE(found);
  EXPECT_EQ(validate_mesh(mesh).error().code, ErrorCode::kUnprocessable);
}

// Two quads that share only a corner: every edge is fine, but the surface pinches to a point at
// the shared control point (PROTOCOL.md: non-manifold topology is a 422).
TEST(MeshValidation, NonManifoldVertex) {
  ControlMesh bowtie({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0), Vec3(2, 1, 0), Vec3(2, 2, 0),
                      Vec3(1, 2, 0)},
                     std::vector<std::vector<int32_t>>{{0, 1, 2, 3}, {2, 4, 5, 6}});
  MeshIssue issue = first_issue(bowtie);
  EXPECT_EQ(issue.kind, MeshIssueKind::kNonManifoldVertex);
  EXPECT_EQ(issue.vertex, 2);
  EXPECT_NE(issue.message.find("faces 0 and 1"), std::string::npos) << issue.message;
  EXPECT_EQ(validate_mesh(bowtie).error().code, ErrorCode::kUnprocessable);
  // A closed fan around a vertex (an interior vertex) and an open one (a boundary vertex) are fine.
  EXPECT_TRUE(find_mesh_issues(square_pair()).empty());
  ControlMesh fan({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0), Vec3(-1, 1, 0), Vec3(-1, 0, 0),
                   Vec3(-1, -1, 0), Vec3(0, -1, 0), Vec3(1, -1, 0)},
                  std::vector<std::vector<int32_t>>{{0, 1, 2, 3}, {0, 3, 4, 5}, {0, 5, 6, 7}, {0, 7, 8, 1}});
  EXPECT_TRUE(find_mesh_issues(fan).empty()) << find_mesh_issues(fan).front().message;
}

TEST(MeshValidation, InconsistentOrientation) {
  ControlMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0), Vec3(2, 1, 0)},
                   std::vector<std::vector<int32_t>>{{0, 1, 4, 3}, {1, 4, 5, 2}});
  MeshIssue issue = first_issue(mesh);
  EXPECT_EQ(issue.kind, MeshIssueKind::kInconsistentOrientation);
  EXPECT_NE(issue.message.find("faces 0 and 1"), std::string::npos) << issue.message;
}

TEST(MeshValidation, ZeroAreaFace) {
  ControlMesh mesh = square_pair();
  mesh.positions()[2] = mesh.positions()[1];
  mesh.positions()[5] = mesh.positions()[4];
  MeshIssue issue = first_issue(mesh);
  EXPECT_EQ(issue.kind, MeshIssueKind::kZeroAreaFace);
  EXPECT_EQ(issue.face, 1);
}

TEST(MeshValidation, UnusedVertexAndBadCrease) {
  ControlMesh mesh = square_pair();
  mesh.positions().push_back(Vec3(5, 5, 5));
  EXPECT_EQ(first_issue(mesh).kind, MeshIssueKind::kUnusedVertex);

  ControlMesh creased = square_pair();
  creased.creases().push_back({0, 5, 2.0f});
  EXPECT_EQ(first_issue(creased).kind, MeshIssueKind::kBadTag);
  creased.creases() = {{0, 99, 2.0f}};
  EXPECT_EQ(first_issue(creased).kind, MeshIssueKind::kIndexOutOfRange);
}

TEST(MeshValidation, SummaryCountsOtherProblems) {
  ControlMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)},
                   std::vector<std::vector<int32_t>>{{0, 1, 7}, {0, 1, 8}, {0, 1, 9}});
  auto result = validate_mesh(mesh);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("and 2 other problems"), std::string::npos) << result.error().message;
}

}  // namespace
}  // namespace softshell
