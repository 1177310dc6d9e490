// Malformed and hostile requests: each gets its documented 4xx JSON error, and the server keeps
// serving.
#include <gtest/gtest.h>

#include <limits>

#include "http_test_support.h"

namespace softshell {
namespace {

using namespace test;

struct Case {
  std::string name;
  std::string method;  // GET or POST
  std::string path;    // {id} = a ready geometry, {tri} = a geometry with non-quad faces
  std::string content_type;
  std::string body;
  std::string accept;
  int status;
  std::string error;  // short code of the JSON error
};

std::string json_mesh(const std::string& material, const std::string& faces = "[[0,1,3,2]]",
                      const std::string& vertices = "[[0,0,0],[1,0,0],[0,1,0],[1,1,0]]") {
  return R"({"vertices":)" + vertices + R"(,"faces":)" + faces + R"(,"material":)" + material + "}";
}
const std::string kGoodMaterial = R"({"youngs_modulus":1e6,"poisson_ratio":0.3,"thickness":0.01})";

std::vector<Case> hostile_cases() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  auto geometry_header = [](uint32_t n, uint32_t m) { return Bytes().u32(n).u32(m).f32(1e6f).f32(0.25f).f32(0.01f); };
  Bytes quad = geometry_header(4, 1);
  for (int i = 0; i < 4; ++i) quad.vec(static_cast<float>(i & 1), static_cast<float>(i >> 1), 0);
  quad.u32(0).u32(1).u32(3).u32(2);
  Bytes nan_vertex = geometry_header(4, 1).vec(nan, 0, 0).vec(1, 0, 0).vec(0, 1, 0).vec(1, 1, 0).u32(0).u32(1).u32(3).u32(2);
  Bytes bad_index = geometry_header(4, 1).vec(0, 0, 0).vec(1, 0, 0).vec(0, 1, 0).vec(1, 1, 0).u32(0).u32(1).u32(4).u32(2);
  const std::string pinned = wire::encode_request_binary(pinned_push(1)).value();
  auto one_vertex_constraint = [](uint32_t mask, uint32_t index) {
    return Bytes().u32(1).u32(0).u32(0).vec(0, 0, 0).u32(mask).u32(index).data;
  };
  const std::string free_body = R"({"forces":[{"index":12,"force":[0,0,-1]}]})";
  const std::string ghost_constraint =
      R"({"vertex_constraints":[{"index":0}],"limit_constraints":[{"face":0,"u":0.5,"v":0.5}]})";

  return {
      // --- uploads ---------------------------------------------------------------------------
      {"binary upload shorter than its header", "POST", "/geometries", kBin, "abc", "", 400, "invalid_argument"},
      {"binary upload whose counts claim gigabytes", "POST", "/geometries", kBin,
       geometry_header(0xffffffffu, 0xffffffffu).data, "", 400, "invalid_argument"},
      {"binary upload truncated by one byte", "POST", "/geometries", kBin, quad.data.substr(0, quad.data.size() - 1), "",
       400, "invalid_argument"},
      {"binary upload with trailing bytes", "POST", "/geometries", kBin, quad.data + "xyz", "", 400, "invalid_argument"},
      {"binary upload with a NaN coordinate", "POST", "/geometries", kBin, nan_vertex.data, "", 400, "invalid_argument"},
      {"binary upload with a face index out of range", "POST", "/geometries", kBin, bad_index.data, "", 400,
       "invalid_argument"},
      {"binary upload of an empty mesh", "POST", "/geometries", kBin, geometry_header(0, 0).data, "", 400,
       "invalid_argument"},
      {"JSON upload that is not JSON", "POST", "/geometries", kJson, "{\"vertices\": [", "", 400, "invalid_argument"},
      {"JSON upload nested 100 deep", "POST", "/geometries", kJson, std::string(100, '[') + std::string(100, ']'), "",
       400, "invalid_argument"},
      {"JSON upload with E <= 0", "POST", "/geometries", kJson,
       json_mesh(R"({"youngs_modulus":0,"poisson_ratio":0.3,"thickness":0.01})"), "", 422, "unprocessable"},
      {"JSON upload with nu >= 0.5", "POST", "/geometries", kJson,
       json_mesh(R"({"youngs_modulus":1e6,"poisson_ratio":0.5,"thickness":0.01})"), "", 422, "unprocessable"},
      {"JSON upload with t <= 0", "POST", "/geometries", kJson,
       json_mesh(R"({"youngs_modulus":1e6,"poisson_ratio":0.3,"thickness":-1})"), "", 422, "unprocessable"},
      {"JSON upload with a 2-vertex face", "POST", "/geometries", kJson, json_mesh(kGoodMaterial, "[[0,1]]"), "", 400,
       "invalid_argument"},
      {"JSON upload with a repeated vertex", "POST", "/geometries", kJson, json_mesh(kGoodMaterial, "[[0,1,1,2]]"), "",
       400, "invalid_argument"},
      {"JSON upload with a number too large for a double", "POST", "/geometries", kJson,
       json_mesh(kGoodMaterial, "[[0,1,3,2]]", "[[0,0,1e999],[1,0,0],[0,1,0],[1,1,0]]"), "", 400, "invalid_argument"},
      {"JSON upload of a non-manifold mesh", "POST", "/geometries", kJson,
       json_mesh(kGoodMaterial, "[[0,1,3,2],[1,0,4,5],[0,1,7,6]]",
                 "[[0,0,0],[1,0,0],[0,1,0],[1,1,0],[0,-1,0],[1,-1,0],[0,0,1],[1,0,1]]"),
       "", 422, "unprocessable"},
      {"upload as text/plain", "POST", "/geometries", "text/plain", quad.data, "", 415, "unsupported_media_type"},
      {"upload without a Content-Type", "POST", "/geometries", "", quad.data, "", 415, "unsupported_media_type"},
      {"upload into a 300-byte namespace", "POST", "/geometries?namespace=" + std::string(300, 'n'), kBin, quad.data,
       "", 400, "invalid_argument"},
      // --- deformation requests ---------------------------------------------------------------
      {"binary request shorter than its counts", "POST", "/geometries/{id}/results", kBin, "12345678", "", 400,
       "invalid_argument"},
      {"binary request whose counts claim gigabytes", "POST", "/geometries/{id}/results", kBin,
       Bytes().u32(0xffffffffu).u32(0xffffffffu).u32(0xffffffffu).data, "", 400, "invalid_argument"},
      {"binary request with a Lagrange count claiming gigabytes", "POST", "/geometries/{id}/results", kBin,
       Bytes().u32(0).u32(1).u32(0).u32(0x7fffffffu).vec(0, 0, 0).data, "", 400, "invalid_argument"},
      {"binary request with trailing bytes", "POST", "/geometries/{id}/results", kBin, pinned + "!", "", 400,
       "invalid_argument"},
      {"binary request truncated", "POST", "/geometries/{id}/results", kBin, pinned.substr(0, pinned.size() - 2), "",
       400, "invalid_argument"},
      {"vertex constraint mask 0", "POST", "/geometries/{id}/results", kBin, one_vertex_constraint(0, 1), "", 400,
       "invalid_argument"},
      {"vertex constraint mask 8", "POST", "/geometries/{id}/results", kBin, one_vertex_constraint(8, 1), "", 400,
       "invalid_argument"},
      {"vertex constraint index out of range", "POST", "/geometries/{id}/results", kBin, one_vertex_constraint(7, 25),
       "", 400, "invalid_argument"},
      {"binary request with an infinite force", "POST", "/geometries/{id}/results", kBin,
       Bytes().u32(0).u32(0).u32(1).vec(0, inf, 0).u32(3).data, "", 400, "invalid_argument"},
      {"binary request with a NaN displacement", "POST", "/geometries/{id}/results", kBin,
       Bytes().u32(1).u32(0).u32(0).vec(nan, 0, 0).u32(7).u32(0).data, "", 400, "invalid_argument"},
      {"JSON request that is not JSON", "POST", "/geometries/{id}/results", kJson, "{forces: []}", "", 400,
       "invalid_argument"},
      {"JSON request with an unknown field", "POST", "/geometries/{id}/results", kJson, R"({"force":[]})", "", 400,
       "invalid_argument"},
      {"JSON request with a mask of 9", "POST", "/geometries/{id}/results", kJson,
       R"({"vertex_constraints":[{"index":1,"mask":9}]})", "", 400, "invalid_argument"},
      {"JSON request with u outside [0, 1]", "POST", "/geometries/{id}/results", kJson,
       R"({"limit_constraints":[{"face":0,"u":1.5,"v":0.5}]})", "", 400, "invalid_argument"},
      {"JSON request on a face that does not exist", "POST", "/geometries/{id}/results", kJson,
       R"({"vertex_constraints":[{"index":0}],"limit_constraints":[{"face":16,"u":0.5,"v":0.5}]})", "", 400,
       "invalid_argument"},
      {"limit constraint on a ghost face", "POST", "/geometries/{ghost}/results", kJson, ghost_constraint, "", 400,
       "invalid_argument"},
      {"a free body with no constraints", "POST", "/geometries/{id}/results", kJson, free_body, "", 422, "unprocessable"},
      {"an all-zero Lagrange equation with a non-zero value", "POST", "/geometries/{id}/results", kJson,
       R"({"vertex_constraints":[{"index":0},{"index":4},{"index":20}],)"
       R"("lagrange_constraints":[{"indices":[6],"coefficients":[[0,0,0]],"values":[0,1,0]}]})",
       "", 422, "unprocessable"},
      {"request as text/plain", "POST", "/geometries/{id}/results", "text/plain", free_body, "", 415,
       "unsupported_media_type"},
      {"request for an unknown geometry", "POST", "/geometries/00000000000000000000000000000000/results", kJson, "{}", "",
       404, "not_found"},
      {"request with a malformed id", "POST", "/geometries/not-hex/results", kJson, "{}", "", 400, "invalid_argument"},
      // --- reads -------------------------------------------------------------------------------
      {"unknown geometry", "GET", "/geometries/0123456789abcdef0123456789abcdef", "", "", "", 404, "not_found"},
      {"id of 31 hex characters", "GET", "/geometries/0123456789abcdef0123456789abcde", "", "", "", 400,
       "invalid_argument"},
      {"id with a non-hex character", "GET", "/geometries/0123456789abcdef0123456789abcdeg/results", "", "", "", 400,
       "invalid_argument"},
      {"result id that is not a number", "GET", "/geometries/{id}/results/abc", "", "", "", 400, "invalid_argument"},
      {"result that does not exist", "GET", "/geometries/{id}/results/99", "", "", "", 404, "not_found"},
      {"binary GET of a mesh with triangles", "GET", "/geometries/{tri}", "", "", kBin, 406, "not_acceptable"},
      {"limit_comb with u > 1", "GET", "/geometries/{id}/limit_comb?u=1.5&v=0.5&face-index=0", "", "", "", 400,
       "invalid_argument"},
      {"limit_comb with v = NaN", "GET", "/geometries/{id}/limit_comb?u=0.5&v=nan&face-index=0", "", "", "", 400,
       "invalid_argument"},
      {"limit_comb on a face out of range", "GET", "/geometries/{id}/limit_comb?u=0.5&v=0.5&face-index=16", "", "", "",
       400, "invalid_argument"},
      {"limit_comb on a sub-face a quad lacks", "GET", "/geometries/{id}/limit_comb?u=0.5&v=0.5&face-index=0&subface=1",
       "", "", "", 400, "invalid_argument"},
      {"limit_comb without face-index", "GET", "/geometries/{id}/limit_comb?u=0.5&v=0.5", "", "", "", 400,
       "invalid_argument"},
      {"limit_comb on an unknown geometry", "GET",
       "/geometries/ffffffffffffffffffffffffffffffff/limit_comb?u=0.5&v=0.5&face-index=0", "", "", "", 404, "not_found"},
      {"latest_result with have = -1", "GET", "/geometries/{id}/latest_result?have=-1", "", "", "", 400,
       "invalid_argument"},
      {"latest_result with wait = soon", "GET", "/geometries/{id}/latest_result?wait=soon", "", "", "", 400,
       "invalid_argument"},
      {"latest_result with a negative wait", "GET", "/geometries/{id}/latest_result?wait=-1", "", "", "", 400,
       "invalid_argument"},
      {"unknown endpoint", "GET", "/geometries/{id}/nonsense", "", "", "", 404, "not_found"},
  };
}

TEST(HttpHostileTest, EveryMalformedRequestGetsItsDocumentedError) {
  TestServer server;
  auto c = server.client();
  // A ready quad grid, a mesh with triangles and a ghost-layer mesh.
  auto upload = [&](const std::string& body) {
    Reply r = post(*c, "/geometries", body, kJson);
    EXPECT_EQ(r.status, 201) << r.body;
    return wire::decode_upload_response_json(r.body, true).value().id.hex();
  };
  const std::string id = upload(wire::encode_geometry_json(exact_grid(), exact_material()));
  const std::string tri = upload(wire::encode_geometry_json(load_asset_mesh("catmark_nonquads.obj"), exact_material()));
  ControlMesh ghost_mesh = exact_grid();
  ghost_mesh.set_boundary(BoundaryMode::kNone);
  const std::string ghost = upload(wire::encode_geometry_json(ghost_mesh, exact_material()));

  const auto cases = hostile_cases();
  ASSERT_GE(cases.size(), 20u);
  for (Case k : cases) {
    for (auto [key, value] : {std::pair{"{id}", id}, std::pair{"{tri}", tri}, std::pair{"{ghost}", ghost}}) {
      if (auto at = k.path.find(key); at != std::string::npos) k.path.replace(at, std::string(key).size(), value);
    }
    Reply r = k.method == "GET" ? get(*c, k.path, k.accept) : post(*c, k.path, k.body, k.content_type, k.accept);
    EXPECT_EQ(r.status, k.status) << k.name << ": " << r.body;
    EXPECT_EQ(r.content_type, kJson) << k.name;
    EXPECT_EQ(error_code(r), k.error) << k.name << ": " << r.body;
    EXPECT_NE(wire::decode_error_json(r.body, r.status).message, "") << k.name;
    // Still serving, on a fresh connection too.
    EXPECT_EQ(get(*c, "/health").status, 200) << "after " << k.name;
  }
  EXPECT_EQ(get(*server.client(), "/health").status, 200);
  // No client mistake was answered with a 5xx.
  for (const auto& e : server.http().endpoint_stats()) EXPECT_EQ(e.server_errors, 0u) << e.endpoint;
  // Nothing was stored by the refused requests.
  EXPECT_EQ(server.service().geometries().size(), 3u);
  EXPECT_EQ(server.service().stats().results, 0u);
}

TEST(HttpHostileTest, BodiesOverTheLimitGet413) {
  http::ServerOptions options = test_server_options();
  options.max_body_bytes = 1 << 20;
  TestServer server(test_service_options(), options);
  auto c = server.client();
  Reply r = post(*c, "/geometries", std::string((1 << 20) + 1, '\0'), kBin);
  EXPECT_EQ(r.status, 413);
  EXPECT_EQ(error_code(r), "payload_too_large");
  EXPECT_NE(r.body.find("1.00 MiB"), std::string::npos) << r.body;
  EXPECT_EQ(get(*server.client(), "/health").status, 200);
  // Just under the limit is read (and rejected for what it is).
  EXPECT_EQ(post(*server.client(), "/geometries", std::string(1 << 20, '\0'), kBin).status, 400);
}

// The attack of issue 17: 1,000 one-point Lagrange constraints in a 33 KB body held a solver
// thread for 9 s at 376 MB and made a normal request wait as long. Now such a request is refused
// at the boundary with what to do instead, and the normal one is solved at once.
TEST(HttpHostileTest, RequestsWithTooManyConstraintRowsAreRefused) {
  TestServer server;
  auto c = server.client();
  Reply up = post(*c, "/geometries", wire::encode_geometry_json(exact_grid(40), exact_material()), kJson);
  ASSERT_EQ(up.status, 201) << up.body;
  const std::string base = "/geometries/" + wire::decode_upload_response_json(up.body, true).value().id.hex();
  DeformationRequest heavy = pinned_push(1, 40);
  for (int i = 0; i < 1000; ++i) {
    heavy.lagrange_constraints.push_back({{100 + i}, {Vec3(1, 1, 1)}, Vec3::Zero()});
  }
  Reply refused = post(*c, base + "/results", wire::encode_request_json(heavy), kJson);
  EXPECT_EQ(refused.status, 422) << refused.body;
  EXPECT_NE(refused.body.find("1000 Lagrange and limit constraints"), std::string::npos) << refused.body;
  EXPECT_NE(refused.body.find("vertex constraints instead"), std::string::npos) << refused.body;
  // Binary layout: the same rule.
  Reply binary = post(*c, base + "/results", wire::encode_request_binary(heavy).value(), kBin);
  EXPECT_EQ(binary.status, 422) << binary.body;
  // Nothing was stored; a normal request is solved and gets the first id.
  Reply normal = post(*c, base + "/results", wire::encode_request_json(pinned_push(1, 40)), kJson);
  ASSERT_EQ(normal.status, 200) << normal.body;
  EXPECT_EQ(wire::decode_result_json(normal.body).value().res_id, 1u);
  // At the limit it is solved (256 one-point constraints on distinct control points, all zero).
  DeformationRequest at_limit = pinned_push(1, 40);
  for (int i = 0; i < 256; ++i) at_limit.lagrange_constraints.push_back({{100 + 5 * i}, {Vec3(1, 1, 1)}, Vec3::Zero()});
  Reply solved = post(*c, base + "/results", wire::encode_request_json(at_limit), kJson);
  EXPECT_EQ(solved.status, 200) << solved.body.substr(0, 300);
}

TEST(HttpHostileTest, CompressedBodiesAreRefusedBeforeTheyAreInflated) {
  TestServer server;
  auto c = server.client();
  c->set_compress(true);  // gzip the request body (Content-Encoding: gzip)
  const std::string zeros(8 << 20, '\0');  // inflates from a few kB
  auto r = c->Post("/geometries", zeros, kBin);
  ASSERT_TRUE(r) << httplib::to_string(r.error());
  EXPECT_EQ(r->status, 415);
  EXPECT_NE(r->body.find("uncompressed"), std::string::npos) << r->body;
  // The same client goes on (over a new connection) and the server is healthy.
  c->set_compress(false);
  EXPECT_EQ(get(*c, "/health").status, 200);
  EXPECT_EQ(post(*c, "/geometries", wire::encode_geometry_binary(exact_grid(), exact_material()).value(), kBin).status,
            201);
}

TEST(HttpHostileTest, JsonBodiesAreBoundedByWhatTheirDecodingTakes) {
  http::ServerOptions options = test_server_options();
  const std::string fits = wire::encode_geometry_json(exact_grid(4), exact_material());
  const std::string larger = wire::encode_geometry_json(exact_grid(8), exact_material());
  // A budget of exactly what decoding `fits` takes: `larger` gets 413, with the way out.
  options.max_json_decode_bytes = fits.size() * http::ServerOptions::kJsonDecodeFactor;
  TestServer server(test_service_options(), options);
  auto c = server.client();
  Reply r = post(*c, "/geometries", larger, kJson);
  EXPECT_EQ(r.status, 413);
  EXPECT_EQ(error_code(r), "payload_too_large");
  EXPECT_NE(r.body.find("send the binary layout"), std::string::npos) << r.body;
  // Binary bodies are not affected.
  EXPECT_EQ(post(*c, "/geometries", wire::encode_geometry_binary(exact_grid(8), exact_material()).value(), kBin).status,
            201);
  Reply small = post(*c, "/geometries", fits, kJson);
  EXPECT_EQ(small.status, 201) << small.body;
}

}  // namespace
}  // namespace softshell
