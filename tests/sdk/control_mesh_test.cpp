#include "softshell/control_mesh.h"

#include <gtest/gtest.h>

#include "softshell/material.h"
#include "test_meshes.h"

namespace softshell {
namespace {

TEST(ControlMesh, StoresFacesOfAnySize) {
  ControlMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0), Vec3(2, 0, 0)},
                   std::vector<std::vector<int32_t>>{{0, 1, 2, 3}, {1, 4, 2}});
  EXPECT_EQ(mesh.num_vertices(), 5);
  EXPECT_EQ(mesh.num_faces(), 2);
  EXPECT_EQ(mesh.face_size(0), 4);
  EXPECT_EQ(mesh.face_size(1), 3);
  EXPECT_EQ(mesh.face(1)[1], 4);
  EXPECT_FALSE(mesh.all_quads());
  EXPECT_EQ(mesh.face_sizes(), (std::vector<int32_t>{4, 3}));
  EXPECT_NEAR(mesh.bounding_diagonal(), std::sqrt(5.0), 1e-15);
}

TEST(ControlMesh, FlatConstructorRejectsInconsistentSizes) {
  EXPECT_THROW(ControlMesh({Vec3::Zero()}, std::vector<int32_t>{3}, std::vector<int32_t>{0, 0}), Exception);
  EXPECT_THROW(ControlMesh({Vec3::Zero()}, std::vector<int32_t>{-1}, std::vector<int32_t>{}), Exception);
  EXPECT_THROW(ControlMesh({Vec3::Zero()}, std::vector<int32_t>{1}, std::vector<int32_t>{0, 0}), Exception);
  EXPECT_NO_THROW(ControlMesh({Vec3::Zero()}, std::vector<int32_t>{2}, std::vector<int32_t>{0, 0}));
}

TEST(ControlMesh, EqualityCoversTags) {
  ControlMesh a = test::make_grid(2, 2);
  ControlMesh b = a;
  EXPECT_EQ(a, b);
  b.creases().push_back({0, 1, 2.0f});
  EXPECT_FALSE(a == b);
  b = a;
  b.set_boundary(BoundaryMode::kNone);
  EXPECT_FALSE(a == b);
}

TEST(Material, ChecksRanges) {
  EXPECT_TRUE(Material{}.check().ok());
  EXPECT_EQ(Material({0.0, 0.3, 0.01}).check().error().code, ErrorCode::kUnprocessable);
  EXPECT_EQ(Material({-1.0, 0.3, 0.01}).check().error().code, ErrorCode::kUnprocessable);
  EXPECT_FALSE(Material({1e9, 0.5, 0.01}).check().ok());
  EXPECT_FALSE(Material({1e9, -1.0, 0.01}).check().ok());
  EXPECT_FALSE(Material({1e9, 0.3, 0.0}).check().ok());
  EXPECT_FALSE(Material({std::nan(""), 0.3, 0.01}).check().ok());
  EXPECT_NE(Material({1e9, 0.7, 0.01}).check().error().message.find("Poisson"), std::string::npos);
}

TEST(Material, BendingStiffness) {
  Material m{1.0e6, 0.3, 0.1};
  EXPECT_NEAR(m.bending_stiffness(), 1.0e6 * 1e-3 / (12 * 0.91), 1e-9);
  EXPECT_NEAR(m.membrane_stiffness(), 1.0e5 / 0.91, 1e-9);
}

TEST(Material, Presets) {
  auto steel = material_preset("Steel", 0.002);
  ASSERT_TRUE(steel.ok());
  EXPECT_EQ(steel->youngs_modulus, 2.0e11);
  EXPECT_EQ(steel->thickness, 0.002);
  EXPECT_TRUE(material_preset("aluminum").ok());
  auto unknown = material_preset("unobtainium");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("rubber"), std::string::npos);
  EXPECT_FALSE(material_preset("steel", -1.0).ok());
  for (const auto& p : material_presets()) EXPECT_TRUE(p.material.check().ok()) << p.name;
}

}  // namespace
}  // namespace softshell
