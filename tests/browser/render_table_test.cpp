// Render tables (GET /geometries/{id}/render), the stresses route, the app's static files and
// CORS, over real sockets. The tables are checked against the SDK's Tessellation, which is what
// a thin client's picture must equal.
#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <random>

#include "../http/http_test_support.h"
#include "softshell/service/render_table.h"
#include "softshell/tessellation.h"

namespace softshell {
namespace {

using namespace test;

// The binary layout read back the way a client reads it (docs/api-notes.md).
struct Decoded {
  uint32_t level = 0, control = 0, vertices = 0, quads = 0, entries = 0;
  std::vector<uint32_t> offsets, indices, quad_words, triangles;
  std::vector<float> position, du, dv;
};

Decoded decode(const std::string& body) {
  Decoded d;
  size_t at = 0;
  auto u32 = [&] {
    uint32_t v = 0;
    std::memcpy(&v, body.data() + at, 4);
    at += 4;
    return v;
  };
  auto f32 = [&] { return std::bit_cast<float>(u32()); };
  EXPECT_EQ(body.substr(0, 4), "SSRT");
  at = 4;
  EXPECT_EQ(u32(), 1u);
  d.level = u32();
  d.control = u32();
  d.vertices = u32();
  d.quads = u32();
  d.entries = u32();
  EXPECT_EQ(u32(), 0u);
  const size_t expected = 32 + 4 * (d.vertices + 1) + 16 * size_t{d.entries} + 32 * size_t{d.quads} + 24 * size_t{d.quads};
  EXPECT_EQ(body.size(), expected);
  if (body.size() != expected) return d;
  for (uint32_t i = 0; i <= d.vertices; ++i) d.offsets.push_back(u32());
  for (uint32_t i = 0; i < d.entries; ++i) d.indices.push_back(u32());
  for (auto* w : {&d.position, &d.du, &d.dv}) {
    for (uint32_t i = 0; i < d.entries; ++i) w->push_back(f32());
  }
  for (uint32_t i = 0; i < 8 * d.quads; ++i) d.quad_words.push_back(u32());
  for (uint32_t i = 0; i < 6 * d.quads; ++i) d.triangles.push_back(u32());
  return d;
}

double diagonal(const std::vector<Vec3>& p) {
  Vec3 lo = p[0], hi = p[0];
  for (const Vec3& x : p) {
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  return (hi - lo).norm();
}

// x = S P with the f32 weights of the binary table, against Tessellation::update: within 1e-6 of
// the object's size, for the rest shape and a deformed one; normals from the du/dv stencils
// against the Tessellation's; quads and triangles equal.
void expect_table_matches_tessellation(const std::string& mesh_name, int level) {
  SCOPED_TRACE(mesh_name + " level " + std::to_string(level));
  const ControlMesh mesh = load_asset_mesh(mesh_name);
  const LimitEvaluator evaluator = LimitEvaluator::create(mesh).value();
  const service::RenderTable table = service::render_table(evaluator, level).value();
  const Decoded d = decode(service::encode_render_table_binary(table));
  Tessellation tess = Tessellation::create(evaluator, level).value();
  ASSERT_EQ(d.vertices, tess.vertices().size());
  ASSERT_EQ(d.quads, tess.quads().size());
  ASSERT_EQ(d.control, static_cast<uint32_t>(mesh.num_vertices()));

  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.05, 0.05);
  std::vector<Vec3> deformed = mesh.positions();
  const double size = diagonal(mesh.positions());
  for (Vec3& p : deformed) p += size * Vec3(jitter(rng), jitter(rng), jitter(rng));

  const std::vector<const std::vector<Vec3>*> shapes = {&mesh.positions(), &deformed};
  for (const std::vector<Vec3>* control : shapes) {
    tess.update(*control);
    double worst = 0.0, worst_normal = 0.0;
    for (uint32_t i = 0; i < d.vertices; ++i) {
      Vec3 x = Vec3::Zero(), xu = Vec3::Zero(), xv = Vec3::Zero();
      for (uint32_t k = d.offsets[i]; k < d.offsets[i + 1]; ++k) {
        const Vec3& p = (*control)[d.indices[k]];
        x += double{d.position[k]} * p;
        xu += double{d.du[k]} * p;
        xv += double{d.dv[k]} * p;
      }
      worst = std::max(worst, (x - tess.vertices()[i]).norm());
      worst_normal = std::max(worst_normal, (xu.cross(xv).normalized() - tess.normals()[i]).norm());
    }
    EXPECT_LT(worst, 1e-6 * size) << "limit positions from the f32 stencils";
    EXPECT_LT(worst_normal, 1e-4) << "normals from the f32 du/dv stencils";
  }
  for (uint32_t q = 0; q < d.quads; ++q) {
    const Tessellation::Quad& tq = tess.quads()[q];
    const uint32_t* w = &d.quad_words[8 * q];
    for (int c = 0; c < 4; ++c) ASSERT_EQ(w[c], static_cast<uint32_t>(tq.vertices[static_cast<size_t>(c)]));
    ASSERT_EQ(w[4], static_cast<uint32_t>(tq.root_face));
    ASSERT_EQ(w[5], static_cast<uint32_t>(tq.subface));
    ASSERT_EQ(w[6], tq.path.bits);
    ASSERT_EQ(w[7], tq.path.depth | (uint32_t{tq.rotation} << 8));
  }
  for (size_t t = 0; t < tess.triangles().size(); ++t) {
    for (int c = 0; c < 3; ++c) ASSERT_EQ(d.triangles[3 * t + c], static_cast<uint32_t>(tess.triangles()[t][static_cast<size_t>(c)]));
  }
}

TEST(RenderTableTest, MatchesTessellationOnSpot) { expect_table_matches_tessellation("spot_control_mesh.obj", 2); }
TEST(RenderTableTest, MatchesTessellationWithNonQuads) {
  expect_table_matches_tessellation("catmark_nonquads.obj", 1);
  expect_table_matches_tessellation("catmark_nonquads.obj", 3);
}

TEST(RenderTableTest, JsonCarriesTheEvaluatorsStencilsExactly) {
  const ControlMesh mesh = load_asset_mesh("catmark_nonquads.obj");
  const LimitEvaluator evaluator = LimitEvaluator::create(mesh).value();
  const service::RenderTable table = service::render_table(evaluator, 2).value();
  const Tessellation tess = Tessellation::create(evaluator, 2).value();
  // The rows are the evaluator's stencils at the tessellation's vertex points.
  for (size_t i = 0; i < tess.vertex_points().size(); i += 7) {
    const LimitStencil s = evaluator.stencil(tess.vertex_points()[i]);
    ASSERT_EQ(table.offsets[i + 1] - table.offsets[i], s.size());
    for (size_t k = 0; k < s.size(); ++k) {
      EXPECT_EQ(table.indices[table.offsets[i] + k], static_cast<uint32_t>(s.indices[k]));
      EXPECT_EQ(table.position[table.offsets[i] + k], s.position[k]);
      EXPECT_EQ(table.du[table.offsets[i] + k], s.du[k]);
    }
  }
  const std::string json = service::encode_render_table_json(table);
  EXPECT_EQ(json.rfind("{\"level\":2,\"control_points\":", 0), 0u);
  EXPECT_NE(json.find("\"triangles\":["), std::string::npos);
}

TEST(RenderTableTest, LevelOutOfRange) {
  const LimitEvaluator evaluator = LimitEvaluator::create(exact_grid()).value();
  EXPECT_EQ(service::render_table(evaluator, 0).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(service::render_table(evaluator, 7).error().code, ErrorCode::kInvalidArgument);
}

std::string upload(TestServer& server, const ControlMesh& mesh) {
  auto c = server.client();
  Reply r = post(*c, "/geometries", wire::encode_geometry_json(mesh, exact_material()), kJson, kJson);
  EXPECT_TRUE(r.status == 201 || r.status == 200) << r.body;
  const auto up = wire::decode_upload_response_json(r.body, true).value();
  (void)server.service().wait_until_precomputed(up.id, std::chrono::seconds(60));
  return up.id.hex();
}

TEST(RenderRouteTest, BinaryAndJsonAgreeWithTheSdk) {
  TestServer server;
  const ControlMesh mesh = load_asset_mesh("catmark_nonquads.obj");
  const std::string id = upload(server, mesh);
  auto c = server.client();
  Reply bin = get(*c, "/geometries/" + id + "/render?level=2", kBin);
  ASSERT_EQ(bin.status, 200) << bin.body;
  EXPECT_EQ(bin.content_type, kBin);
  const Decoded d = decode(bin.body);
  const Tessellation tess = Tessellation::create(LimitEvaluator::create(mesh).value(), 2).value();
  EXPECT_EQ(d.vertices, tess.vertices().size());
  EXPECT_EQ(d.level, 2u);
  Reply json = get(*c, "/geometries/" + id + "/render?level=2");
  ASSERT_EQ(json.status, 200);
  EXPECT_EQ(json.content_type, kJson);
  EXPECT_EQ(json.body, service::encode_render_table_json(service::render_table(LimitEvaluator::create(mesh).value(), 2).value()));

  // Cacheable by content: the ETag answers 304.
  auto again = c->Get("/geometries/" + id + "/render?level=2", {{"Accept", kBin}});
  ASSERT_TRUE(again);
  const std::string etag = again->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  auto cached = c->Get("/geometries/" + id + "/render?level=2", {{"Accept", kBin}, {"If-None-Match", etag}});
  ASSERT_TRUE(cached);
  EXPECT_EQ(cached->status, 304);
  EXPECT_TRUE(cached->body.empty());
}

TEST(RenderRouteTest, Errors) {
  TestServer server;
  const std::string id = upload(server, exact_grid());
  auto c = server.client();
  for (const char* q : {"", "?level=0", "?level=7", "?level=x", "?level=-1"}) {
    Reply r = get(*c, "/geometries/" + id + "/render" + q);
    EXPECT_EQ(r.status, 400) << q;
    EXPECT_EQ(error_code(r), "invalid_argument") << r.body;
  }
  EXPECT_EQ(get(*c, "/geometries/00000000000000000000000000000000/render?level=1").status, 404);
  EXPECT_EQ(get(*c, "/geometries/nothex/render?level=1").status, 400);
}

TEST(StressesRouteTest, LevelAndPoints) {
  TestServer server;
  const std::string id = upload(server, exact_grid());
  auto c = server.client();
  ASSERT_EQ(post(*c, "/geometries/" + id + "/results", wire::encode_request_json(pinned_push()), kJson).status, 200);
  Reply r = get(*c, "/geometries/" + id + "/results/1/stresses?level=2&yield_strength=1e3");
  ASSERT_EQ(r.status, 200) << r.body;
  const StressField field = wire::decode_stress_field_json(r.body).value();
  const Tessellation tess = Tessellation::create(LimitEvaluator::create(exact_grid()).value(), 2).value();
  EXPECT_EQ(field.samples.size(), tess.vertices().size());  // one per render vertex, in their order
  EXPECT_EQ(field.res_id, 1u);
  EXPECT_GT(field.max.von_mises(), 0.0);
  Reply points = post(*c, "/geometries/" + id + "/results/1/stresses",
                      R"({"points": [{"face": 5, "subface": 0, "u": 0.5, "v": 0.5}]})", kJson);
  ASSERT_EQ(points.status, 200) << points.body;
  EXPECT_EQ(wire::decode_stress_field_json(points.body).value().samples.size(), 1u);
  EXPECT_EQ(get(*c, "/geometries/" + id + "/results/9/stresses?level=1").status, 404);
  EXPECT_EQ(get(*c, "/geometries/" + id + "/results/1/stresses?level=9").status, 400);
  EXPECT_EQ(get(*c, "/geometries/" + id + "/results/1/stresses").status, 400);
  EXPECT_EQ(post(*c, "/geometries/" + id + "/results/1/stresses", "x", kBin).status, 415);
}

TEST(AppRouteTest, ServesTheAppFromTheBinary) {
  TestServer server;
  auto c = server.client();
  Reply index = get(*c, "/");
  ASSERT_EQ(index.status, 200);
  EXPECT_EQ(index.content_type, "text/html; charset=utf-8");
  EXPECT_NE(index.body.find("/app/main.js"), std::string::npos);
  EXPECT_EQ(get(*c, "/?geometry=00112233445566778899aabbccddeeff").body, index.body);
  for (const char* f : {"/app/main.js", "/app/view.js", "/app/client.js"}) {
    Reply js = get(*c, f);
    EXPECT_EQ(js.status, 200) << f;
    EXPECT_EQ(js.content_type, "text/javascript; charset=utf-8") << f;
    EXPECT_GT(js.body.size(), 1000u) << f;
  }
  EXPECT_EQ(get(*c, "/app/style.css").content_type, "text/css; charset=utf-8");
  Reply missing = get(*c, "/app/nothing.js");
  EXPECT_EQ(missing.status, 404);
  EXPECT_EQ(error_code(missing), "not_found");
  EXPECT_EQ(get(*c, "/app/../CMakeLists.txt").status, 404);
  // Revalidation by ETag.
  auto first = c->Get("/app/main.js");
  ASSERT_TRUE(first);
  auto second = c->Get("/app/main.js", {{"If-None-Match", first->get_header_value("ETag")}});
  ASSERT_TRUE(second);
  EXPECT_EQ(second->status, 304);
}

TEST(CorsTest, OffByDefault) {
  TestServer server;
  auto c = server.client();
  auto r = c->Get("/health", {{"Origin", "http://elsewhere.example"}});
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->has_header("Access-Control-Allow-Origin"));
  auto pre = c->Options("/geometries", {{"Origin", "http://elsewhere.example"}, {"Access-Control-Request-Method", "POST"}});
  ASSERT_TRUE(pre);
  EXPECT_FALSE(pre->has_header("Access-Control-Allow-Origin"));
  EXPECT_GE(pre->status, 400);
}

TEST(CorsTest, AllowedOriginsGetHeadersAndPreflights) {
  http::ServerOptions options = test_server_options();
  options.cors_origins = {"http://app.example:3000"};
  TestServer server(test_service_options(), options);
  auto c = server.client();
  auto pre = c->Options("/geometries/00112233445566778899aabbccddeeff/holds/hand-1",
                        {{"Origin", "http://app.example:3000"}, {"Access-Control-Request-Method", "PUT"},
                         {"Access-Control-Request-Headers", "content-type"}});
  ASSERT_TRUE(pre);
  EXPECT_EQ(pre->status, 204);
  EXPECT_EQ(pre->get_header_value("Access-Control-Allow-Origin"), "http://app.example:3000");
  EXPECT_NE(pre->get_header_value("Access-Control-Allow-Methods").find("PUT"), std::string::npos);
  EXPECT_NE(pre->get_header_value("Access-Control-Allow-Headers").find("Content-Type"), std::string::npos);
  auto get_ok = c->Get("/health", {{"Origin", "http://app.example:3000"}});
  ASSERT_TRUE(get_ok);
  EXPECT_EQ(get_ok->get_header_value("Access-Control-Allow-Origin"), "http://app.example:3000");
  EXPECT_EQ(get_ok->get_header_value("Vary"), "Origin");
  // Errors carry the headers too (so the page can read the server's message).
  auto missing = c->Get("/geometries/00112233445566778899aabbccddeeff", {{"Origin", "http://app.example:3000"}});
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404);
  EXPECT_EQ(missing->get_header_value("Access-Control-Allow-Origin"), "http://app.example:3000");
  // Other origins get nothing.
  auto other = c->Get("/health", {{"Origin", "http://evil.example"}});
  ASSERT_TRUE(other);
  EXPECT_FALSE(other->has_header("Access-Control-Allow-Origin"));
  auto other_pre = c->Options("/geometries", {{"Origin", "http://evil.example"}, {"Access-Control-Request-Method", "POST"}});
  ASSERT_TRUE(other_pre);
  EXPECT_FALSE(other_pre->has_header("Access-Control-Allow-Methods"));
}

}  // namespace
}  // namespace softshell
