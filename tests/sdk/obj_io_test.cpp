#include "softshell/obj_io.h"

#include <random>

#include <gtest/gtest.h>

#include "softshell/mesh_validation.h"
#include "test_meshes.h"

namespace softshell {
namespace {

TEST(ObjIo, ParsesAllFaceForms) {
  const char* text =
      "# comment\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\nv 2 0 0\n"
      "vt 0 0\nvn 0 0 1\n"
      "g group\ns off\nusemtl x\n"
      "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
      "f 2//1 5//1 3//1\n"
      "f -4/1 -1/1 -3/1\n";
  auto mesh = parse_obj(text);
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->num_vertices(), 5);
  ASSERT_EQ(mesh->num_faces(), 3);
  EXPECT_EQ(mesh->face_size(1), 3);
  EXPECT_EQ(mesh->face(1)[1], 4);
  // Negative indices are relative to the vertices read so far: -4 -> 2, -1 -> 5, -3 -> 3.
  EXPECT_EQ(mesh->face(2)[0], 1);
  EXPECT_EQ(mesh->face(2)[1], 4);
  EXPECT_EQ(mesh->face(2)[2], 2);
}

TEST(ObjIo, ReadsOpenSubdivTags) {
  const char* text =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "f 1 2 3 4\n"
      "t crease 2/1/0 0 1 6.0\n"
      "t crease 3/1/0 1 2 3 2.5\n"
      "t corner 1/1/0 3 10\n"
      "t interpolateboundary 1/0/0 0\n"
      "t hole 1/0/0 0\n";
  auto mesh = parse_obj(text);
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  ASSERT_EQ(mesh->creases().size(), 3u);
  EXPECT_EQ(mesh->creases()[0].v0, 0);
  EXPECT_EQ(mesh->creases()[0].v1, 1);
  EXPECT_EQ(mesh->creases()[0].sharpness, 6.0f);
  EXPECT_EQ(mesh->creases()[2].v0, 2);
  EXPECT_EQ(mesh->creases()[2].v1, 3);
  EXPECT_EQ(mesh->creases()[2].sharpness, 2.5f);
  ASSERT_EQ(mesh->corners().size(), 1u);
  EXPECT_EQ(mesh->corners()[0].vertex, 3);
  EXPECT_EQ(mesh->boundary(), BoundaryMode::kNone);
}

TEST(ObjIo, NonManifoldVertexNamesTheLineAndTheVertex) {
  const auto mesh = parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 1 0\nv 2 2 0\nv 1 2 0\n"
                              "f 1 2 3 4\nf 3 5 6 7\n", "bowtie.obj", ObjReadOptions{.validate = true});
  ASSERT_FALSE(mesh);
  EXPECT_EQ(mesh.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(mesh.error().message.find("bowtie.obj:9: this face meets other faces only at vertex 3"), std::string::npos)
      << mesh.error().message;
}

TEST(ObjIo, LineContinuation) {
  auto mesh = parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 \\\n 3\n");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->face_size(0), 3);
}

TEST(ObjIo, RoundTripsExactly) {
  for (const auto& name : test::asset_mesh_names()) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto again = parse_obj(format_obj(mesh));
    ASSERT_TRUE(again.ok()) << name << ": " << again.error().message;
    EXPECT_EQ(*again, mesh) << name;
  }
}

TEST(ObjIo, ShippedMeshesMatchTheirDocumentedCounts) {
  struct Expect { const char* name; int v, f; size_t creases; };
  // Counts from assets/meshes/SOURCES.md.
  for (const Expect& e : {Expect{"catmark_cube.obj", 8, 6, 0}, Expect{"catmark_car.obj", 1642, 1575, 0},
                          Expect{"blub_quadrangulated.obj", 7106, 7104, 0}, Expect{"penguin_control_mesh.obj", 201, 221, 0},
                          Expect{"catmark_rook.obj", 768, 777, 0}}) {
    ControlMesh mesh = test::load_asset_mesh(e.name);
    EXPECT_EQ(mesh.num_vertices(), e.v) << e.name;
    EXPECT_EQ(mesh.num_faces(), e.f) << e.name;
  }
  EXPECT_GT(test::load_asset_mesh("catmark_car.obj").creases().size(), 300u);
  EXPECT_EQ(test::load_asset_mesh("catmark_tent.obj").boundary(), BoundaryMode::kEdgeAndCorner);
}

struct BadObj { const char* text; const char* expect; };

TEST(ObjIo, MalformedInputGivesLineAndReason) {
  const BadObj cases[] = {
      {"v 0 0\n", "three coordinates"},
      {"v 0 0 x\n", "not a number"},
      {"v 0 0 nan\n", "not finite"},
      {"v 0 0 inf\n", "not finite"},
      {"v 0 0 0 1 2 3 4 5\n", "unexpected"},
      {"v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3"},
      {"v 0 0 0\nv 1 0 0\nf 1 2 3\n", "not defined yet"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 0\n", "start at 1"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 -4\n", "before the first"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 3x\n", "not an integer"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 3/a/1\n", "v/vt/vn"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 99999999999999999999\n", "not an integer"},
      {"bogus 1 2 3\n", "unknown OBJ statement"},
      {"t crease 2/1\n", "ni/nf/ns"},
      {"t crease 2/1/0 0\n", "expected an integer"},
      {"t crease 2/1/0 0 1 -1\n", "sharpness"},
      {"t crease 99999999/1/0 0 1\n", "counts"},
      {"t corner 1/0/0 0\n", "corner"},
  };
  for (const auto& c : cases) {
    auto mesh = parse_obj(c.text, "bad.obj");
    ASSERT_FALSE(mesh.ok()) << c.text;
    EXPECT_EQ(mesh.error().code, ErrorCode::kInvalidArgument) << c.text;
    EXPECT_NE(mesh.error().message.find(c.expect), std::string::npos) << c.text << " -> " << mesh.error().message;
    EXPECT_EQ(mesh.error().message.rfind("bad.obj:", 0), 0u) << mesh.error().message;
  }
}

TEST(ObjIo, LimitsProtectAgainstHugeFiles) {
  ObjReadOptions options;
  options.max_vertices = 2;
  auto mesh = parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 1\n", "x", options);
  ASSERT_FALSE(mesh.ok());
  EXPECT_NE(mesh.error().message.find("more than 2 vertices"), std::string::npos);
  options = ObjReadOptions{};
  options.max_face_size = 3;
  EXPECT_FALSE(parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 1\nv 0 1 0\nf 1 2 3 4\n", "x", options).ok());
}

TEST(ObjIo, MissingFileIsAnIoError) {
  auto mesh = read_obj("/nonexistent/softshell.obj");
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kIoError);
}

TEST(ObjIo, DirectoryIsNamedAsOne) {
  auto mesh = read_obj(::testing::TempDir());
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kIoError);
  EXPECT_NE(mesh.error().message.find("is a directory"), std::string::npos) << mesh.error().message;
  auto missing = read_obj("/nonexistent/softshell.obj");
  EXPECT_NE(missing.error().message.find("No such file or directory"), std::string::npos) << missing.error().message;
}

// With `validate`, problems for the simulation are reported in the file's terms: the face's line
// and OBJ's 1-based vertex numbers (validate_mesh speaks of 0-based control points).
TEST(ObjIo, ValidationSpeaksInTheFilesTerms) {
  ObjReadOptions options;
  options.validate = true;
  const char* square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
  struct Case {
    std::string text;
    ErrorCode code;
    const char* expect;
  };
  const Case cases[] = {
      {std::string(square) + "# a comment\nf 1 2 3 4\nf 1 2 3\n", ErrorCode::kUnprocessable,
       "m.obj:7: this face and the face on line 6 run along their shared edge 1-2 in the same direction"},
      {std::string(square) + "v 5 5 5\nf 1 2 3 4\n", ErrorCode::kUnprocessable,
       "m.obj:5: vertex 5 belongs to no face"},
      {std::string(square) + "f 1 2 2\nf 1 3 4\n", ErrorCode::kInvalidArgument,
       "m.obj:5: the face uses vertex 2 twice (vertices 1 2 2)"},
      {"v 0 0 0\nv 1 0 0\nv 2 0 0\n\nf 1 2 3\n", ErrorCode::kUnprocessable,
       "m.obj:5: the face (vertices 1 2 3) has zero area"},
      {std::string(square) + "v 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n", ErrorCode::kUnprocessable,
       "the edge between vertices 1 and 2 belongs to the faces on lines 6, 7, 8"},
      {"# nothing\n", ErrorCode::kInvalidArgument, "m.obj: the file has no vertices"},
  };
  for (const Case& c : cases) {
    auto mesh = parse_obj(c.text, "m.obj", options);
    ASSERT_FALSE(mesh.ok()) << c.text;
    EXPECT_EQ(mesh.error().code, c.code) << c.text;
    EXPECT_NE(mesh.error().message.find(c.expect), std::string::npos) << c.text << " -> " << mesh.error().message;
  }
  // A good file passes, and without `validate` nothing is checked beyond the syntax.
  EXPECT_TRUE(parse_obj(std::string(square) + "f 1 2 3 4\n", "m.obj", options).ok());
  EXPECT_TRUE(parse_obj(std::string(square) + "v 5 5 5\nf 1 2 3 4\n", "m.obj").ok());
}

// A short fuzz run in the test suite (the libFuzzer target runs longer in CI): random mutations of
// real files must never crash, hang or produce a mesh that breaks validation.
TEST(ObjIo, FuzzMutationsNeverCrash) {
  std::mt19937 rng(12345);
  const std::string seed_text = format_obj(test::load_asset_mesh("catmark_gregory_test5.obj")) +
                                "t crease 2/1/0 0 1 3\nt corner 1/1/0 2 1\n";
  const std::string alphabet = "vft/-+.0123456789eE \n\\#xnai";
  int parsed = 0;
  for (int iteration = 0; iteration < 3000; ++iteration) {
    std::string text = seed_text;
    const int edits = 1 + static_cast<int>(rng() % 8);
    for (int e = 0; e < edits && !text.empty(); ++e) {
      const size_t pos = rng() % text.size();
      switch (rng() % 4) {
        case 0: text[pos] = alphabet[rng() % alphabet.size()]; break;
        case 1: text.erase(pos, 1 + rng() % 5); break;
        case 2: text.insert(pos, 1, alphabet[rng() % alphabet.size()]); break;
        default: text.insert(pos, text.substr(rng() % text.size(), rng() % 40)); break;
      }
    }
    auto mesh = parse_obj(text);
    if (mesh.ok()) {
      ++parsed;
      (void)find_mesh_issues(*mesh);  // must not crash either
    } else {
      EXPECT_FALSE(mesh.error().message.empty());
    }
  }
  EXPECT_GT(parsed, 0);
}

}  // namespace
}  // namespace softshell
