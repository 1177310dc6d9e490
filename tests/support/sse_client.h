#pragma once
// A small Server-Sent Events client over a raw POSIX socket (tests and benchmarks): it sees
// exactly the bytes the server sends (status line, headers, chunked framing, event fields).
// `SseParser` is incremental, so the fan-out benchmark can feed it from non-blocking sockets.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace softshell::test {

/// One thing a stream carried: an event (`id`, `event`, `data`) or a comment line.
struct SseEvent {
  bool comment = false;
  std::string text;  // the comment (without ':') for comments
  std::string id;
  std::string event;
  std::string data;
};

/// Parses an HTTP response carrying an event stream, bytes in as they arrive.
class SseParser {
 public:
  void feed(const char* data, size_t n) {
    raw_.append(data, n);
    if (!head_done_) parse_head();
    if (head_done_) parse_body();
  }
  void feed_eof() { eof_ = true; }

  bool head_done() const { return head_done_; }
  int status() const { return status_; }
  std::string header(std::string name) const {
    for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    auto it = headers_.find(name);
    return it == headers_.end() ? "" : it->second;
  }
  bool chunked() const { return chunked_; }
  /// The body of a response that is not an event stream (e.g. a JSON error), once complete.
  const std::string& body() const { return body_; }
  /// The chunked body ended with its last chunk (a clean end of the stream).
  bool clean_end() const { return last_chunk_; }
  bool eof() const { return eof_; }

  std::deque<SseEvent>& events() { return events_; }

 private:
  void parse_head() {
    const size_t end = raw_.find("\r\n\r\n");
    if (end == std::string::npos) return;
    const std::string head = raw_.substr(0, end);
    raw_.erase(0, end + 4);
    size_t pos = head.find("\r\n");
    const std::string status_line = head.substr(0, pos);
    const size_t sp = status_line.find(' ');
    status_ = sp == std::string::npos ? 0 : std::atoi(status_line.c_str() + sp + 1);
    while (pos != std::string::npos && pos < head.size()) {
      const size_t next = head.find("\r\n", pos + 2);
      const std::string line = head.substr(pos + 2, next == std::string::npos ? std::string::npos : next - pos - 2);
      const size_t colon = line.find(':');
      if (colon != std::string::npos) {
        std::string key = line.substr(0, colon);
        for (auto& c : key) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        std::string value = line.substr(colon + 1);
        while (!value.empty() && value.front() == ' ') value.erase(0, 1);
        headers_[key] = value;
      }
      pos = next;
    }
    chunked_ = header("Transfer-Encoding") == "chunked";
    event_stream_ = header("Content-Type").rfind("text/event-stream", 0) == 0;
    head_done_ = true;
  }

  void parse_body() {
    if (chunked_) {
      while (!last_chunk_) {
        const size_t crlf = raw_.find("\r\n");
        if (crlf == std::string::npos) break;
        const size_t size = std::strtoul(raw_.substr(0, crlf).c_str(), nullptr, 16);
        if (raw_.size() < crlf + 2 + size + 2) break;
        if (size == 0) {
          last_chunk_ = true;
          raw_.clear();
          break;
        }
        text_.append(raw_, crlf + 2, size);
        raw_.erase(0, crlf + 2 + size + 2);
      }
    } else {
      text_.append(raw_);
      raw_.clear();
    }
    if (!event_stream_) {
      body_ = text_;
      return;
    }
    // Lines; an empty line ends an event.
    for (;;) {
      const size_t nl = text_.find('\n');
      if (nl == std::string::npos) return;
      std::string line = text_.substr(0, nl);
      text_.erase(0, nl + 1);
      if (line.empty()) {
        if (!current_.data.empty() || !current_.id.empty()) events_.push_back(std::move(current_));
        current_ = {};
      } else if (line[0] == ':') {
        SseEvent c;
        c.comment = true;
        c.text = line.substr(1);
        events_.push_back(std::move(c));
      } else {
        const size_t colon = line.find(':');
        const std::string field = line.substr(0, colon);
        std::string value = colon == std::string::npos ? "" : line.substr(colon + 1);
        if (!value.empty() && value[0] == ' ') value.erase(0, 1);
        if (field == "id") current_.id = value;
        else if (field == "event") current_.event = value;
        else if (field == "data") current_.data += (current_.data.empty() ? "" : "\n") + value;
      }
    }
  }

  std::string raw_, text_, body_;
  bool head_done_ = false, chunked_ = false, event_stream_ = false, last_chunk_ = false, eof_ = false;
  int status_ = 0;
  std::map<std::string, std::string> headers_;
  SseEvent current_;
  std::deque<SseEvent> events_;
};

/// Connects to 127.0.0.1:port; -1 on failure. `rcvbuf` > 0 sets SO_RCVBUF before connecting.
inline int connect_loopback(int port, int rcvbuf = 0) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  if (rcvbuf > 0) ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
  int yes = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

/// A blocking client of one event stream.
class SseClient {
 public:
  /// Connects and sends `GET path` with `extra_headers` (full lines without CRLF).
  SseClient(int port, const std::string& path, const std::vector<std::string>& extra_headers = {}, int rcvbuf = 0,
            const std::string& version = "HTTP/1.1")
      : fd_(connect_loopback(port, rcvbuf)) {
    if (fd_ < 0) return;
    std::string request = "GET " + path + " " + version + "\r\nHost: 127.0.0.1\r\nAccept: text/event-stream\r\n";
    for (const auto& h : extra_headers) request += h + "\r\n";
    request += "\r\n";
    (void)!::send(fd_, request.data(), request.size(), MSG_NOSIGNAL);
  }
  ~SseClient() {
    if (fd_ >= 0) ::close(fd_);
  }
  SseClient(const SseClient&) = delete;
  SseClient& operator=(const SseClient&) = delete;

  bool connected() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  SseParser& parser() { return parser_; }

  /// Reads until the response head is in (false on timeout or EOF first).
  bool read_head(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!parser_.head_done()) {
      if (!read_some(deadline)) return false;
    }
    return true;
  }

  /// The next event or comment; nullopt on timeout or at the end of the stream.
  std::optional<SseEvent> next(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (parser_.events().empty()) {
      if (!read_some(deadline)) return std::nullopt;
    }
    SseEvent e = std::move(parser_.events().front());
    parser_.events().pop_front();
    return e;
  }

  /// The next result event (comments skipped).
  std::optional<SseEvent> next_result(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      auto e = next(left);
      if (!e || !e->comment) return e;
    }
  }

  /// Reads until the server closes the connection (true) or `timeout` passes (false).
  bool read_to_end(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!parser_.eof()) {
      if (!read_some(deadline) && !parser_.eof()) return false;
    }
    return true;
  }

 private:
  bool read_some(std::chrono::steady_clock::time_point deadline) {
    if (fd_ < 0 || parser_.eof()) return false;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return false;
    char buf[65536];
    const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
    if (n <= 0) {
      parser_.feed_eof();
      return false;
    }
    parser_.feed(buf, static_cast<size_t>(n));
    return true;
  }

  int fd_;
  SseParser parser_;
};

}  // namespace softshell::test
