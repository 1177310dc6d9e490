// The "Embed in your engine" example of docs/embedding.md, compiled and run, and checked to be
// the same text as in the document.

#include <fstream>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

// [example]
#include <softshell/embedded_session.h>
#include <softshell/interaction.h>
#include <softshell/obj_io.h>
#include <softshell/picking.h>
using namespace softshell;

int run_game(const char* obj_path, int deformations_to_show) {
  ControlMesh mesh = read_obj(obj_path).value();
  EmbeddedSession server;  // the simulation server, in this process
  GeomId id = server.upload(mesh, material_preset("aluminium", 0.002).value()).value().id;
  LimitEvaluator evaluator = LimitEvaluator::create(mesh).value();
  Tessellation surface = Tessellation::create(evaluator, 3).value();  // the triangles you draw
  Picker picker = Picker::create(surface).value();

  // What touches the floor (y = -0.76, +y up) stays there.
  FloorContact floor = floor_contact(surface, {Vec3(0, -0.76, 0), Vec3::UnitY()}, {.tolerance = 0.1}).value();

  // A ray from the hand picks a point of the exact limit surface; the grab makes it follow the hand.
  Pose hand{Vec3(0.0, 3.0, 0.2), Eigen::Quaterniond::Identity()};
  std::optional<Pick> pick = picker.pick({hand.position, Vec3(0, -1, 0)}).value();
  if (!pick) return 0;
  Grab grab = Grab::begin(evaluator, pick->point, surface.control_positions(), hand).value();

  std::future<Result<DeformationResult>> pending;
  int updates = 0;
  while (updates < deformations_to_show) {        // the game loop
    hand.position.y() += 1e-4;                    // the hand moves
    if (!pending.valid()) {                       // one request in flight at a time
      DeformationRequest request;
      floor.add_to(request);
      request.limit_constraints.push_back(grab.constraint(hand));
      pending = server.deform_async(id, request);
    } else if (pending.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
      DeformationResult result = pending.get().value();  // ready: does not block
      surface.update(result.positions);                  // draw the new shape
      picker.refit().value();                            // and pick on it
      ++updates;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(16));  // draw the frame
  }
  return updates;
}
// [example]

namespace {

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(EmbeddingExample, RunsAndFollowsTheHand) {
  // Returns once five deformations were shown (or throws if one failed).
  EXPECT_EQ(run_game(SOFTSHELL_SOURCE_DIR "/assets/meshes/spot_control_mesh.obj", 5), 5);
}

TEST(EmbeddingExample, DocumentShowsThisCode) {
  // (Not __FILE__: with a compiler cache it may be relative to a build directory.)
  const std::string source = read_text(SOFTSHELL_SOURCE_DIR "/tests/interaction/embedding_example_test.cpp");
  const std::string marker = "// [example]\n";
  const size_t begin = source.find(marker) + marker.size();
  const size_t end = source.find(marker, begin);
  ASSERT_NE(source.find(marker), std::string::npos);
  ASSERT_NE(end, std::string::npos);
  const std::string code = source.substr(begin, end - begin);
  const std::string doc = read_text(SOFTSHELL_SOURCE_DIR "/docs/embedding.md");
  EXPECT_NE(doc.find(code), std::string::npos) << "docs/embedding.md no longer shows the example of embedding_example_test.cpp";
}

}  // namespace
