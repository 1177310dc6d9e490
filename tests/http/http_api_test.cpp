// Every endpoint of PROTOCOL.md in both formats, over real sockets.
#include <gtest/gtest.h>

#include <thread>

#include "http_test_support.h"
#include "softshell/content_id.h"
#include "softshell/http/negotiation.h"

namespace softshell {
namespace {

using namespace test;

std::string geometry_binary(const ControlMesh& mesh = exact_grid()) {
  return wire::encode_geometry_binary(mesh, exact_material()).value();
}
std::string geometry_json(const ControlMesh& mesh = exact_grid()) {
  return wire::encode_geometry_json(mesh, exact_material());
}

// Uploads and waits until the geometry is ready; returns its hex id.
std::string upload_ready(TestServer& server, const std::string& body = geometry_binary(), const char* type = kBin,
                         const std::string& query = "") {
  auto c = server.client();
  Reply r = post(*c, "/geometries" + query, body, type, kJson);
  EXPECT_TRUE(r.status == 201 || r.status == 200) << r.status << " " << r.body;
  auto up = wire::decode_upload_response_json(r.body, r.status == 201).value();
  (void)server.service().wait_until_precomputed(up.id, std::chrono::seconds(30));
  return up.id.hex();
}

TEST(HttpApiTest, HealthAndMetrics) {
  TestServer server;
  auto c = server.client();
  Reply h = get(*c, "/health");
  EXPECT_EQ(h.status, 200);
  EXPECT_EQ(h.body, std::string(R"({"status":"ok","version":")") + SOFTSHELL_VERSION_STRING + "\"}");
  EXPECT_EQ(h.content_type, kJson);
  EXPECT_EQ(h.server, std::string("softshell/") + SOFTSHELL_VERSION_STRING);
  Reply unrouted = get(*c, "/nowhere");  // error pages carry it too
  EXPECT_EQ(unrouted.status, 404);
  EXPECT_EQ(unrouted.server, std::string("softshell/") + SOFTSHELL_VERSION_STRING);
  upload_ready(server);
  // A request is counted once its answer is written, so the upload's own connection may count it
  // a moment after the upload's answer arrived here: wait (boundedly) until it has.
  const std::string upload_counted = "softshell_http_requests_total{endpoint=\"POST /geometries\"";
  Reply m = get(*c, "/metrics");
  for (int i = 0; i < 500 && m.body.find(upload_counted) == std::string::npos; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    m = get(*c, "/metrics");
  }
  EXPECT_EQ(m.status, 200);
  EXPECT_EQ(m.content_type.rfind("text/plain", 0), 0u);
  for (const char* family :
       {"softshell_http_requests_total{endpoint=\"GET /health\",status=\"200\"} 2",  // TestServer + the test
        "softshell_http_request_duration_seconds_bucket{endpoint=\"POST /geometries\",le=\"+Inf\"} 1",
        "softshell_geometries{status=\"ready\"} 1", "softshell_results 0", "softshell_precomputations_running 0",
        "softshell_factor_cache_bytes", "softshell_store_bytes", "softshell_solve_duration_seconds_count 0"}) {
    EXPECT_NE(m.body.find(family), std::string::npos) << family << "\n" << m.body;
  }
}

TEST(HttpApiTest, UploadBothFormatsSameIdIdempotent) {
  TestServer server;
  auto c = server.client();
  const GeomId expected = geometry_id(exact_grid(), exact_material(), "");

  // Binary body: 201 and the 16 raw id bytes (the body's own format).
  Reply first = post(*c, "/geometries", geometry_binary(), kBin);
  EXPECT_EQ(first.status, 201);
  EXPECT_EQ(first.content_type, kBin);
  ASSERT_EQ(first.body.size(), 16u);
  EXPECT_EQ(wire::decode_upload_response_binary(first.body, true)->id, expected);

  // The same values as JSON: 200, the same id, JSON answer with a status.
  Reply again = post(*c, "/geometries", geometry_json(), kJson);
  EXPECT_EQ(again.status, 200);
  EXPECT_EQ(again.content_type, kJson);
  auto up = wire::decode_upload_response_json(again.body, false);
  ASSERT_TRUE(up) << again.body;
  EXPECT_EQ(up->id, expected);

  // Accept overrides the body's format.
  Reply as_json = post(*c, "/geometries", geometry_binary(), kBin, kJson);
  EXPECT_EQ(as_json.status, 200);
  EXPECT_NE(as_json.body.find(expected.hex()), std::string::npos);
  Reply as_binary = post(*c, "/geometries", geometry_json(), kJson, kBin);
  EXPECT_EQ(as_binary.body.size(), 16u);

  // Namespaces: another id; URL-encoded names work.
  Reply lab = post(*c, "/geometries?namespace=lab%20one", geometry_binary(), kBin, kJson);
  EXPECT_EQ(lab.status, 201);
  EXPECT_EQ(wire::decode_upload_response_json(lab.body, true)->id, geometry_id(exact_grid(), exact_material(), "lab one"));
  EXPECT_EQ(post(*c, "/geometries?namespace=lab%20one", geometry_json(), kJson).status, 200);

  // GET /geometries lists both.
  Reply list = get(*c, "/geometries");
  EXPECT_EQ(list.status, 200);
  auto infos = wire::decode_geometry_list_json(list.body).value();
  ASSERT_EQ(infos.size(), 2u);
  EXPECT_EQ(infos[0].id, expected);
  EXPECT_EQ(infos[0].name_space, "");
  EXPECT_EQ(infos[1].name_space, "lab one");
  EXPECT_EQ(infos[0].vertices, 25);
  EXPECT_EQ(infos[0].faces, 16);
}

TEST(HttpApiTest, GetGeometryBothFormats) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_ready(server, geometry_binary(), kBin, "?namespace=ns");
  // Binary: exactly the uploaded layout.
  Reply bin = get(*c, "/geometries/" + id, kBin);
  EXPECT_EQ(bin.status, 200);
  EXPECT_EQ(bin.body, geometry_binary());
  // JSON (the default for a GET): upload layout plus geom_id and namespace; re-uploads to the same id.
  Reply js = get(*c, "/geometries/" + id);
  EXPECT_EQ(js.status, 200);
  EXPECT_EQ(js.content_type, kJson);
  EXPECT_NE(js.body.find("\"geom_id\":\"" + id + "\""), std::string::npos);
  EXPECT_NE(js.body.find("\"namespace\":\"ns\""), std::string::npos);
  auto g = wire::decode_geometry_json(js.body).value();
  EXPECT_EQ(g.mesh, exact_grid());
  EXPECT_EQ(post(*c, "/geometries?namespace=ns", js.body, kJson).status, 200);
  // Upper-case hex in the URL is accepted.
  std::string upper = id;
  for (char& ch : upper) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  EXPECT_EQ(get(*c, "/geometries/" + upper).status, 200);
  // A mesh with a triangle has no binary layout: 406 (JSON works).
  const std::string tri = upload_ready(server, geometry_json(load_asset_mesh("catmark_nonquads.obj")), kJson);
  Reply refused = get(*c, "/geometries/" + tri, kBin);
  EXPECT_EQ(refused.status, 406);
  EXPECT_EQ(error_code(refused), "not_acceptable");
  EXPECT_EQ(get(*c, "/geometries/" + tri, kJson).status, 200);
  // Status extension.
  Reply status = get(*c, "/geometries/" + id + "/status");
  EXPECT_EQ(status.status, 200);
  EXPECT_EQ(wire::decode_geometry_info_json(status.body)->status, GeometryStatus::kReady);
}

TEST(HttpApiTest, DeformationsResultsAndHistoryBothFormats) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_ready(server);
  const std::string base = "/geometries/" + id;

  // Binary request -> binary result (u32 res_id + 25 x 3 f32).
  Reply r1 = post(*c, base + "/results", wire::encode_request_binary(pinned_push(1)).value(), kBin);
  ASSERT_EQ(r1.status, 200) << r1.body;
  EXPECT_EQ(r1.content_type, kBin);
  EXPECT_EQ(r1.body.size(), 4u + 25u * 12u);
  auto b1 = wire::decode_result_binary(r1.body, 25).value();
  EXPECT_EQ(b1.res_id, 1u);

  // JSON request -> JSON result; Accept overrides both ways.
  Reply r2 = post(*c, base + "/results", wire::encode_request_json(pinned_push(1)), kJson);
  ASSERT_EQ(r2.status, 200) << r2.body;
  EXPECT_EQ(r2.content_type, kJson);
  auto j2 = wire::decode_result_json(r2.body, 25).value();
  EXPECT_EQ(j2.res_id, 2u);
  for (size_t i = 0; i < 25; ++i) {
    // Same request: the binary result is the JSON one rounded to f32.
    for (int a = 0; a < 3; ++a) EXPECT_EQ(b1.positions[i][a], static_cast<double>(static_cast<float>(j2.positions[i][a])));
  }
  Reply r3 = post(*c, base + "/results", wire::encode_request_json(pinned_push(2)), kJson, kBin);
  EXPECT_EQ(r3.content_type, kBin);
  EXPECT_EQ(wire::decode_result_binary(r3.body)->res_id, 3u);
  Reply r4 = post(*c, base + "/results", wire::encode_request_binary(pinned_push(3)).value(), kBin, kJson);
  EXPECT_EQ(r4.content_type, kJson);
  EXPECT_EQ(wire::decode_result_json(r4.body)->res_id, 4u);

  // History.
  Reply ids = get(*c, base + "/results");
  EXPECT_EQ(ids.status, 200);
  EXPECT_EQ(ids.body, R"({"res_ids":[1,2,3,4]})");
  Reply one_json = get(*c, base + "/results/2");
  EXPECT_EQ(one_json.content_type, kJson);
  EXPECT_EQ(wire::decode_result_json(one_json.body)->positions, j2.positions);
  Reply one_bin = get(*c, base + "/results/1", kBin);
  EXPECT_EQ(one_bin.body, r1.body);
  EXPECT_EQ(get(*c, base + "/results/5").status, 404);
  EXPECT_EQ(get(*c, base + "/results/0").status, 404);
  // The request that produced a result (extension).
  Reply req3 = get(*c, base + "/results/3/request");
  EXPECT_EQ(req3.status, 200);
  auto decoded = wire::decode_request_json(req3.body).value();
  EXPECT_EQ(decoded.forces[0].force, Vec3(0, 0, -0.5));
  EXPECT_EQ(decoded.vertex_constraints.size(), 4u);
}

// The nonlinear model over HTTP (PROTOCOL.md): the JSON field, or model=nonlinear with either
// body layout; the answer says which model and how Newton went; a query that contradicts the body
// or names no model is a 400. (Its accuracy is the engine's tests'.)
TEST(HttpApiTest, NonlinearModelByFieldOrQueryParameter) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_ready(server);
  const std::string base = "/geometries/" + id;
  DeformationRequest nonlinear = pinned_push(1);
  nonlinear.model = DeformationModel::kNonlinear;

  Reply by_field = post(*c, base + "/results", wire::encode_request_json(nonlinear), kJson);
  ASSERT_EQ(by_field.status, 200) << by_field.body;
  const DeformationResult field_result = wire::decode_result_json(by_field.body, 25).value();
  EXPECT_EQ(field_result.model, DeformationModel::kNonlinear);
  EXPECT_GE(field_result.iterations, 1);
  EXPECT_NE(by_field.body.find("\"model\":\"nonlinear\""), std::string::npos) << by_field.body;

  Reply by_query = post(*c, base + "/results?model=nonlinear", wire::encode_request_binary(pinned_push(1)).value(), kBin,
                        kJson);
  ASSERT_EQ(by_query.status, 200) << by_query.body;
  const DeformationResult query_result = wire::decode_result_json(by_query.body, 25).value();
  EXPECT_EQ(query_result.model, DeformationModel::kNonlinear);
  for (size_t i = 0; i < 25; ++i) EXPECT_LT((query_result.positions[i] - field_result.positions[i]).norm(), 1e-6);

  Reply linear = post(*c, base + "/results?model=linear", wire::encode_request_json(pinned_push(1)), kJson);
  ASSERT_EQ(linear.status, 200) << linear.body;
  EXPECT_EQ(linear.body.find("\"model\""), std::string::npos);  // linear answers keep the version 1 layout
  EXPECT_EQ(post(*c, base + "/results?model=linear", wire::encode_request_json(nonlinear), kJson).status, 400);
  EXPECT_EQ(post(*c, base + "/results?model=quadratic", wire::encode_request_json(pinned_push(1)), kJson).status, 400);
}

TEST(HttpApiTest, LatestResultLongPoll) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_ready(server);
  const std::string base = "/geometries/" + id;
  EXPECT_EQ(get(*c, base + "/latest_result?wait=0").status, 204);
  auto start = std::chrono::steady_clock::now();
  Reply timed_out = get(*c, base + "/latest_result?have=0&wait=0.2");
  EXPECT_EQ(timed_out.status, 204);
  EXPECT_TRUE(timed_out.body.empty());
  EXPECT_GE(seconds_since(start), 0.19);

  // A waiter is answered when a result is stored.
  Reply woken;
  std::thread waiter([&] {
    auto wc = server.client();
    woken = get(*wc, base + "/latest_result?have=0&wait=30", kBin);
  });
  while (server.http().waiting_long_polls() < 1) std::this_thread::sleep_for(Ms(1));
  ASSERT_EQ(post(*c, base + "/results", wire::encode_request_json(pinned_push(1)), kJson).status, 200);
  waiter.join();
  EXPECT_EQ(woken.status, 200);
  EXPECT_EQ(woken.content_type, kBin);
  EXPECT_EQ(wire::decode_result_binary(woken.body)->res_id, 1u);

  ASSERT_EQ(post(*c, base + "/results", wire::encode_request_json(pinned_push(2)), kJson).status, 200);
  Reply newest = get(*c, base + "/latest_result?have=0");  // newer exists: at once, the newest
  EXPECT_EQ(newest.status, 200);
  EXPECT_EQ(wire::decode_result_json(newest.body)->res_id, 2u);
  EXPECT_EQ(get(*c, base + "/latest_result?have=2&wait=0").status, 204);
}

TEST(HttpApiTest, LimitCombBothFormats) {
  TestServer server;
  auto c = server.client();
  const std::string id = upload_ready(server, geometry_json(load_asset_mesh("catmark_nonquads.obj")), kJson);
  const std::string base = "/geometries/" + id + "/limit_comb";
  Reply js = get(*c, base + "?u=0.25&v=0.5&face-index=0&subface=1");
  ASSERT_EQ(js.status, 200) << js.body;
  auto comb = wire::decode_limit_comb_json(js.body).value();
  EXPECT_EQ(comb.point, (SurfacePoint{0, 1, 0.25, 0.5}));
  double sp = 0, su = 0, sv = 0;
  for (size_t i = 0; i < comb.indices.size(); ++i) {
    sp += comb.position[i];
    su += comb.du[i];
    sv += comb.dv[i];
  }
  EXPECT_NEAR(sp, 1.0, 1e-12);
  EXPECT_NEAR(su, 0.0, 1e-12);
  EXPECT_NEAR(sv, 0.0, 1e-12);
  Reply bin = get(*c, base + "?u=0.25&v=0.5&face-index=0&subface=1", kBin);
  EXPECT_EQ(bin.content_type, kBin);
  auto b = wire::decode_limit_comb_binary(bin.body, comb.point).value();
  EXPECT_EQ(b.indices, comb.indices);
  for (size_t i = 0; i < b.indices.size(); ++i) EXPECT_NEAR(b.position[i], comb.position[i], 1e-7);
  // Sub-face defaults to 0.
  EXPECT_EQ(wire::decode_limit_comb_json(get(*c, base + "?u=0&v=1&face-index=0").body)->point.subface, 0);
}

TEST(HttpApiTest, LagrangeAndLimitConstraintsDisplaceTheLimitPointExactly) {
  TestServer server;
  auto c = server.client();
  const ControlMesh mesh = exact_grid(4);
  const std::string id = upload_ready(server);
  const std::string base = "/geometries/" + id;
  const SurfacePoint p{6, 0, 0.75, 0.25};
  const Vec3 target(-0.02, 0.03, 0.1);
  auto evaluator = LimitEvaluator::create(mesh).value();
  const Vec3 rest = limit_point(evaluator, mesh.positions(), p);

  auto comb = wire::decode_limit_comb_json(get(*c, base + "/limit_comb?u=0.75&v=0.25&face-index=6").body).value();
  DeformationRequest lagrange;
  lagrange.vertex_constraints = pinned_corners(4);
  LagrangeConstraint lc;
  lc.indices = comb.indices;
  for (double w : comb.position) lc.coefficients.push_back(Vec3(w, w, w));
  lc.values = target;
  lagrange.lagrange_constraints.push_back(lc);
  Reply r1 = post(*c, base + "/results", wire::encode_request_json(lagrange), kJson);
  ASSERT_EQ(r1.status, 200) << r1.body;
  EXPECT_LT((limit_point(evaluator, wire::decode_result_json(r1.body)->positions, p) - (rest + target)).norm(), 1e-10);

  DeformationRequest limit;
  limit.vertex_constraints = pinned_corners(4);
  limit.limit_constraints.push_back({p, target, {}, {}});
  Reply r2 = post(*c, base + "/results", wire::encode_request_json(limit), kJson);
  ASSERT_EQ(r2.status, 200) << r2.body;
  EXPECT_LT((limit_point(evaluator, wire::decode_result_json(r2.body)->positions, p) - (rest + target)).norm(), 1e-10);
}

TEST(HttpApiTest, UnroutedPathsAndMethods) {
  TestServer server;
  auto c = server.client();
  Reply missing = get(*c, "/nothing/here");
  EXPECT_EQ(missing.status, 404);
  EXPECT_EQ(error_code(missing), "not_found");
  auto del = c->Delete("/geometries");
  ASSERT_TRUE(del);
  EXPECT_EQ(del->status, 405);
  EXPECT_EQ(del->get_header_value("Allow"), "POST, GET");
  EXPECT_NE(del->body.find("method_not_allowed"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Negotiation rules (pure functions).

TEST(NegotiationTest, ResponseFormat) {
  using wire::Format;
  EXPECT_EQ(http::response_format("", Format::kJson), Format::kJson);
  EXPECT_EQ(http::response_format("", Format::kBinary), Format::kBinary);
  EXPECT_EQ(http::response_format("application/octet-stream", Format::kJson), Format::kBinary);
  EXPECT_EQ(http::response_format("application/json", Format::kBinary), Format::kJson);
  EXPECT_EQ(http::response_format("*/*", Format::kBinary), Format::kBinary);
  EXPECT_EQ(http::response_format("text/html, application/*", Format::kJson), Format::kJson);
  EXPECT_EQ(http::response_format("application/json;q=0.5, application/octet-stream", Format::kJson), Format::kBinary);
  EXPECT_EQ(http::response_format("application/json, application/octet-stream", Format::kBinary), Format::kBinary);
  EXPECT_EQ(http::response_format("application/json, application/octet-stream", Format::kJson), Format::kJson);
  EXPECT_EQ(http::response_format("Application/JSON ; charset=utf-8", Format::kBinary), Format::kJson);
  EXPECT_EQ(http::response_format("application/octet-stream;q=0, */*", Format::kBinary), Format::kBinary);
  EXPECT_EQ(http::response_format("application/octet-stream;q=0, application/json;q=0.1", Format::kBinary),
            Format::kJson);
  EXPECT_EQ(http::response_format("application/json;q=bogus", Format::kBinary), Format::kBinary);
}

TEST(NegotiationTest, BodyFormatAndParameters) {
  EXPECT_EQ(http::body_format("application/json").value(), wire::Format::kJson);
  EXPECT_EQ(http::body_format("application/json; charset=utf-8").value(), wire::Format::kJson);
  EXPECT_EQ(http::body_format("APPLICATION/OCTET-STREAM").value(), wire::Format::kBinary);
  EXPECT_EQ(http::body_format("text/plain").error().code, ErrorCode::kUnsupportedMediaType);
  EXPECT_EQ(http::body_format("").error().code, ErrorCode::kUnsupportedMediaType);
  EXPECT_EQ(http::parse_u32("42", "have").value(), 42u);
  EXPECT_FALSE(http::parse_u32("-1", "have"));
  EXPECT_FALSE(http::parse_u32("4294967296", "have"));
  EXPECT_FALSE(http::parse_u32("1e3", "have"));
  EXPECT_FALSE(http::parse_u32("", "have"));
  EXPECT_EQ(http::parse_number("0.25", "u").value(), 0.25);
  EXPECT_EQ(http::parse_number("+1", "u").value(), 1.0);
  EXPECT_FALSE(http::parse_number("nan", "u"));
  EXPECT_FALSE(http::parse_number("inf", "u"));
  EXPECT_FALSE(http::parse_number("0.5x", "u"));
}

}  // namespace
}  // namespace softshell
