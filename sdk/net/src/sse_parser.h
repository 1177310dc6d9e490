#pragma once
// An incremental Server-Sent Events parser (the WHATWG "event stream interpretation"): bytes in as
// they arrive, split anywhere; events out. Lines end with CRLF, LF or CR; `:` lines are comments
// (keep-alives) and are dropped; `id`, `event` and `data` fields are kept, other fields ignored;
// an empty line ends an event, which is dispatched if it has data.
#include <cstddef>
#include <string>
#include <string_view>

namespace softshell::remote {

struct SseEvent {
  std::string id;     // the event's `id` ("" if it had none)
  std::string event;  // its type ("" means "message")
  std::string data;   // its `data` lines joined by '\n'
};

class SseParser {
 public:
  // Longest event (and line) taken; a longer one makes `feed` return false (the stream is bad).
  explicit SseParser(size_t max_event_bytes = size_t{256} << 20) : max_(max_event_bytes) {}

  // Feeds bytes; calls `on_event(const SseEvent&)` for each completed event. False if an event
  // is over the limit (the caller drops the stream).
  template <class OnEvent>
  bool feed(std::string_view bytes, OnEvent&& on_event) {
    for (char ch : bytes) {
      if (after_cr_ && ch == '\n') {  // the LF of a CRLF
        after_cr_ = false;
        continue;
      }
      after_cr_ = ch == '\r';
      if (ch == '\r' || ch == '\n') {
        if (!line(on_event)) return false;
        continue;
      }
      line_.push_back(ch);
      if (line_.size() + current_.data.size() > max_) return false;
    }
    return true;
  }

 private:
  template <class OnEvent>
  bool line(OnEvent& on_event) {
    std::string_view l(line_);
    if (l.empty()) {
      if (has_data_) on_event(static_cast<const SseEvent&>(current_));
      current_ = {};
      has_data_ = false;
    } else if (l.front() != ':') {
      const size_t colon = l.find(':');
      const std::string_view field = l.substr(0, colon);
      std::string_view value = colon == std::string_view::npos ? std::string_view() : l.substr(colon + 1);
      if (!value.empty() && value.front() == ' ') value.remove_prefix(1);
      if (field == "data") {
        if (has_data_) current_.data.push_back('\n');
        current_.data.append(value);
        has_data_ = true;
      } else if (field == "id") {
        if (value.find('\0') == std::string_view::npos) current_.id.assign(value);
      } else if (field == "event") {
        current_.event.assign(value);
      }
    }
    line_.clear();
    return true;
  }

  size_t max_;
  std::string line_;
  SseEvent current_;
  bool has_data_ = false;
  bool after_cr_ = false;
};

}  // namespace softshell::remote
