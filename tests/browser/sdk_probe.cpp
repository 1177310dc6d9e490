// softshell_sdk_probe: the SDK's own answers for the browser tests, which compare the page's
// picture and picking with them. Reads one JSON object on stdin:
//   {"geometry": <GET /geometries/{id} answer>, "level": L,
//    "positions": [[x, y, z], ...] (optional: control positions, default the rest shape),
//    "rays": [{"origin": [x, y, z], "direction": [x, y, z]}, ...] (optional)}
// and prints {"size": <bounding diagonal>, "vertices": [x0, y0, z0, ...] (Tessellation at level L),
// "picks": [{"hit": true, "triangle": t, "face": f, "subface": k, "u": u, "v": v}, ...]}, where a
// pick is the Picker's estimate from the hit triangle's quadtree path (paper Section 5.1, no
// Newton refinement) and its refined point as "refined": {"face", "subface", "u", "v"}.
#include <cstdio>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "softshell/picking.h"
#include "softshell/tessellation.h"
#include "softshell/wire.h"

using namespace softshell;
using nlohmann::json;

namespace {

Vec3 vec3(const json& j) { return Vec3(j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()); }

json point(const SurfacePoint& p) { return {{"face", p.face}, {"subface", p.subface}, {"u", p.u}, {"v", p.v}}; }

}  // namespace

int main() {
  try {
    const json in = json::parse(std::cin);
    const Geometry g = wire::decode_geometry_json(in.at("geometry").dump()).value();
    const LimitEvaluator evaluator = LimitEvaluator::create(g.mesh).value();
    Tessellation tess = Tessellation::create(evaluator, in.at("level").get<int>()).value();
    std::vector<Vec3> control = g.mesh.positions();
    if (in.contains("positions")) {
      control.clear();
      for (const json& p : in.at("positions")) control.push_back(vec3(p));
      tess.update(control);
    }
    Vec3 lo = control[0], hi = control[0];
    for (const Vec3& p : control) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    json out;
    out["size"] = (hi - lo).norm();
    json vertices = json::array();
    for (const Vec3& v : tess.vertices()) {
      for (int a = 0; a < 3; ++a) vertices.push_back(v[a]);
    }
    out["vertices"] = std::move(vertices);
    json picks = json::array();
    if (in.contains("rays")) {
      const Picker picker = Picker::create(tess).value();
      for (const json& r : in.at("rays")) {
        Ray ray;
        ray.origin = vec3(r.at("origin"));
        ray.direction = vec3(r.at("direction"));
        const auto hit = picker.pick(ray).value();
        if (!hit) {
          picks.push_back({{"hit", false}});
          continue;
        }
        json p = point(hit->estimate);
        p["hit"] = true;
        p["triangle"] = hit->hit.triangle;
        p["refined"] = point(hit->point);
        picks.push_back(std::move(p));
      }
    }
    out["picks"] = std::move(picks);
    std::cout << out.dump() << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "softshell_sdk_probe: %s\n", e.what());
    return 1;
  }
}
