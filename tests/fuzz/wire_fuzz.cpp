// libFuzzer entry for the wire decoders: the first byte picks the decoder, the rest is the body.
// Every decoder must return a value or kInvalidArgument (never crash, hang, or report another
// code), and whatever decodes must encode and decode again to the same bytes.
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <string_view>

#include "softshell/wire.h"

namespace {

using namespace softshell;

void check(const Error& e) {
  if (e.code != ErrorCode::kInvalidArgument) {
    std::fprintf(stderr, "decoder returned code %d: %s\n", static_cast<int>(e.code), e.message.c_str());
    std::abort();
  }
}

template <class T>
void expect(bool ok, const Result<T>& r) {
  if (!ok) {
    std::fprintf(stderr, "round trip failed%s\n", r ? "" : (": " + r.error().message).c_str());
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string_view body(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 8) {
    case 0: {
      auto g = wire::decode_geometry_binary(body);
      if (!g) return check(g.error()), 0;
      auto again = wire::encode_geometry_binary(g->mesh, g->material);
      expect(again && *again == body, again);
      break;
    }
    case 1: {
      auto r = wire::decode_request_binary(body);
      if (!r) return check(r.error()), 0;
      auto again = wire::encode_request_binary(*r);
      expect(bool(again), again);
      // The decoder drops Lagrange constraints that say nothing (no terms, zero values), so
      // only such a body re-encodes shorter; what it re-encodes to is a fixed point.
      if (again->size() == body.size()) {
        expect(*again == body, again);
      } else {
        expect(again->size() < body.size(), again);
        auto canonical = wire::decode_request_binary(*again);
        expect(bool(canonical), canonical);
        auto twice = wire::encode_request_binary(*canonical);
        expect(twice && *twice == *again, twice);
      }
      break;
    }
    case 2: {
      auto r = wire::decode_result_binary(body);
      if (!r) return check(r.error()), 0;
      auto again = wire::encode_result_binary(*r);
      expect(again && *again == body, again);
      break;
    }
    case 3: {
      auto c = wire::decode_limit_comb_binary(body, {});
      if (!c) return check(c.error()), 0;
      auto again = wire::encode_limit_comb_binary(*c);
      expect(again && *again == body, again);
      break;
    }
    case 4: {
      auto g = wire::decode_geometry_json(body);
      if (!g) return check(g.error()), 0;
      auto again = wire::decode_geometry_json(wire::encode_geometry_json(g->mesh, g->material));
      expect(again && again->mesh == g->mesh && again->material == g->material, again);
      break;
    }
    case 5: {
      auto r = wire::decode_request_json(body);
      if (!r) return check(r.error()), 0;
      const std::string text = wire::encode_request_json(*r);
      auto again = wire::decode_request_json(text);
      expect(again && wire::encode_request_json(*again) == text, again);
      break;
    }
    case 6: {
      auto r = wire::decode_result_json(body);
      if (!r) return check(r.error()), 0;
      break;
    }
    default: {
      auto l = wire::decode_geometry_list_json(body);
      if (!l) check(l.error());
      (void)wire::decode_error_json(body, 400);
      break;
    }
  }
  return 0;
}
