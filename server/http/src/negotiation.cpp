#include "softshell/http/negotiation.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <string>

namespace softshell::http {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

std::string shown(std::string_view s) {
  std::string out(s.substr(0, 60));
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = '?';
  }
  return "'" + out + (s.size() > 60 ? "...'" : "'");
}

}  // namespace

Result<wire::Format> body_format(std::string_view content_type) {
  const std::string type = lower(trim(content_type.substr(0, content_type.find(';'))));
  if (type == wire::kBinaryMediaType) return wire::Format::kBinary;
  if (type == wire::kJsonMediaType) return wire::Format::kJson;
  return Error{ErrorCode::kUnsupportedMediaType,
               "a request body must be application/octet-stream or application/json, got " +
                   (content_type.empty() ? std::string("no Content-Type") : "Content-Type " + shown(content_type))};
}

wire::Format response_format(std::string_view accept, wire::Format fallback) {
  struct Candidate {
    wire::Format format;
    double q;
    size_t order;
  };
  std::vector<Candidate> found;
  size_t order = 0;
  while (!accept.empty()) {
    const size_t comma = accept.find(',');
    std::string_view range = accept.substr(0, comma);
    accept = comma == std::string_view::npos ? std::string_view() : accept.substr(comma + 1);
    const std::string type = lower(trim(range.substr(0, range.find(';'))));
    double q = 1.0;
    for (size_t semi = range.find(';'); semi != std::string_view::npos;) {
      std::string_view param = range.substr(semi + 1);
      const size_t next = param.find(';');
      if (next != std::string_view::npos) param = param.substr(0, next);
      param = trim(param);
      if (param.size() > 2 && (param[0] == 'q' || param[0] == 'Q') && param[1] == '=') {
        double v = 0;
        auto value = param.substr(2);
        auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
        q = (ec == std::errc() && ptr == value.data() + value.size() && v >= 0 && v <= 1) ? v : 0.0;
      }
      semi = next == std::string_view::npos ? next : semi + 1 + next;
    }
    if (q <= 0) continue;
    if (type == wire::kBinaryMediaType) found.push_back({wire::Format::kBinary, q, order++});
    else if (type == wire::kJsonMediaType) found.push_back({wire::Format::kJson, q, order++});
  }
  if (found.empty()) return fallback;
  const Candidate* best = &found.front();
  for (const Candidate& c : found) {
    const bool better = c.q > best->q || (c.q == best->q && c.format == fallback && best->format != fallback);
    if (better) best = &c;
  }
  return best->format;
}

Result<uint32_t> parse_u32(std::string_view text, std::string_view name) {
  uint32_t v = 0;
  const bool digits = !text.empty() && std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
  auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (!digits || ec != std::errc() || ptr != text.data() + text.size()) {
    return Error{ErrorCode::kInvalidArgument, "'" + std::string(name) + "' must be a non-negative integer below 2^32, got " + shown(text)};
  }
  return v;
}

Result<double> parse_number(std::string_view text, std::string_view name) {
  double v = 0;
  std::string_view t = text;
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
  if (t.empty() || ec != std::errc() || ptr != t.data() + t.size() || !std::isfinite(v)) {
    return Error{ErrorCode::kInvalidArgument, "'" + std::string(name) + "' must be a finite number, got " + shown(text)};
  }
  return v;
}

}  // namespace softshell::http
