// GET /geometries/{id}/render?level=L (render tables) and GET|POST
// /geometries/{id}/results/{res_id}/stresses, extensions for thin clients (docs/api-notes.md).
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <tuple>

#include "softshell/service/render_table.h"  // Eigen before httplib.h (extensions.h)
#include "extensions.h"
#include "softshell/http/negotiation.h"
#include "softshell/wire.h"

namespace softshell::http::internal {

namespace {

template <class T>
T value_or_throw(Result<T> r) {
  if (!r) throw Exception(r.error());
  return std::move(r).value();
}

// Encoded tables by (geometry, level, evaluator options, format). Geometry ids are content
// hashes, so a table stays valid for as long as the process runs; the cache only bounds memory
// (least recently used first out).
class TableCache {
 public:
  static constexpr size_t kBudget = size_t{256} << 20;
  using Key = std::tuple<std::string, int, int, int, bool, bool>;

  std::shared_ptr<const std::string> get(const Key& key) {
    std::lock_guard lock(mu_);
    auto it = map_.find(key);
    if (it == map_.end()) return nullptr;
    order_.splice(order_.begin(), order_, it->second.second);
    return it->second.first;
  }
  void put(const Key& key, std::shared_ptr<const std::string> body) {
    if (body->size() > kBudget / 2) return;
    std::lock_guard lock(mu_);
    if (map_.count(key)) return;
    order_.push_front(key);
    bytes_ += body->size();
    map_.emplace(key, std::make_pair(std::move(body), order_.begin()));
    while (bytes_ > kBudget && !order_.empty()) {
      auto last = map_.find(order_.back());
      bytes_ -= last->second.first->size();
      map_.erase(last);
      order_.pop_back();
    }
  }

 private:
  std::mutex mu_;
  std::list<Key> order_;
  std::map<Key, std::pair<std::shared_ptr<const std::string>, std::list<Key>::iterator>> map_;
  size_t bytes_ = 0;
};

TableCache& table_cache() {
  static TableCache cache;
  return cache;
}

GeomId parse_geom_id(const std::string& text) { return value_or_throw(GeomId::from_hex(text)); }

}  // namespace

void render_route(const service::Service& service, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_geom_id(req.matches[1].str());
  value_or_throw(service.info(id));  // 404 first
  if (!req.has_param("level")) {
    throw Exception(ErrorCode::kInvalidArgument, "render needs the query parameter 'level' (1..6)");
  }
  const uint32_t level = value_or_throw(parse_u32(req.get_param_value("level"), "level"));
  if (level < service::RenderTable::kMinLevel || level > service::RenderTable::kMaxLevel) {
    throw Exception(ErrorCode::kInvalidArgument,
                    "render: level must be between 1 and 6, got " + std::to_string(level));
  }
  const bool binary = response_format(req.get_header_value("Accept"), wire::Format::kJson) == wire::Format::kBinary;
  const auto& ev = service.options().precompute.evaluator;
  const TableCache::Key key{id.hex(), static_cast<int>(level), ev.approx_level_smooth, ev.approx_level_sharp,
                            ev.sharp_features, binary};
  // The table is a function of the content id and level: clients may cache it for good.
  const std::string etag = "\"" + id.hex() + "-" + std::to_string(level) + "-" + std::to_string(ev.approx_level_smooth) +
                           "-" + std::to_string(ev.approx_level_sharp) + (binary ? "-b" : "-j") + "\"";
  res.set_header("ETag", etag);
  res.set_header("Cache-Control", "max-age=86400");
  if (req.get_header_value("If-None-Match") == etag) {
    res.status = 304;
    return;
  }
  auto body = table_cache().get(key);
  if (!body) {
    const service::RenderTable table = value_or_throw(service::render_table(service, id, static_cast<int>(level)));
    body = std::make_shared<const std::string>(binary ? service::encode_render_table_binary(table)
                                                      : service::encode_render_table_json(table));
    table_cache().put(key, body);
  }
  res.set_content(*body, std::string(binary ? wire::kBinaryMediaType : wire::kJsonMediaType));
}

void stresses_route(const service::Service& service, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_geom_id(req.matches[1].str());
  const uint32_t res_id = value_or_throw(parse_u32(req.matches[2].str(), "res_id"));
  value_or_throw(service.info(id));
  StressQuery query;
  if (req.method == "POST") {
    const wire::Format format = value_or_throw(body_format(req.get_header_value("Content-Type")));
    if (format != wire::Format::kJson) {
      throw Exception(ErrorCode::kUnsupportedMediaType, "stresses: the query body must be application/json");
    }
    query = value_or_throw(wire::decode_stress_query_json(req.body));
  } else {
    if (!req.has_param("level")) {
      throw Exception(ErrorCode::kInvalidArgument,
                      "stresses: GET needs the query parameter 'level' (1..4); POST a JSON body for points");
    }
    query.level = static_cast<int>(std::min<uint32_t>(value_or_throw(parse_u32(req.get_param_value("level"), "level")), 1000));
  }
  if (req.has_param("yield_strength")) {
    query.yield_strength = value_or_throw(parse_number(req.get_param_value("yield_strength"), "yield_strength"));
  }
  const StressField field = value_or_throw(service.stresses(id, res_id, query));
  res.set_content(wire::encode_stress_field_json(field, query.level == 0), std::string(wire::kJsonMediaType));
}

}  // namespace softshell::http::internal
