// Before listener.h: httplib.h (through <resolv.h>) defines a macro `_res` that breaks the Eigen
// headers softshell/wire.h includes.
#include "softshell/wire.h"
#include "listener.h"

#include <netdb.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "server_header.h"

namespace softshell::http::internal {

namespace {

thread_local Connection* t_connection = nullptr;

using Clock = std::chrono::steady_clock;

// An answer the connection writes itself (the library never saw the request), then closes.
std::string plain_answer(int status, const char* reason, const char* code, const std::string& message,
                         const char* extra_header = "") {
  const std::string body = wire::encode_error_json(code, message);
  return "HTTP/1.1 " + std::to_string(status) + " " + reason + "\r\nServer: " + kServerHeader +
         "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
         "\r\nConnection: close\r\n" + extra_header + "\r\n" + body;
}

int millis(std::chrono::milliseconds ms) {
  return static_cast<int>(std::min<int64_t>(ms.count(), std::numeric_limits<int>::max()));
}

void address_of(int sock, bool peer, std::string& ip, int& port) {
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  auto* sa = reinterpret_cast<sockaddr*>(&addr);
  if ((peer ? ::getpeername(sock, sa, &len) : ::getsockname(sock, sa, &len)) != 0) return;
  std::array<char, NI_MAXHOST> host{};
  std::array<char, NI_MAXSERV> serv{};
  if (::getnameinfo(sa, len, host.data(), host.size(), serv.data(), serv.size(), NI_NUMERICHOST | NI_NUMERICSERV) == 0) {
    ip = host.data();
    port = std::atoi(serv.data());
  }
}

}  // namespace

Connection* current_connection() { return t_connection; }

Connection::Connection(int sock, int stop_fd, std::chrono::milliseconds read_timeout,
                       std::chrono::milliseconds write_timeout)
    : sock_(sock), stop_fd_(stop_fd), read_timeout_(read_timeout), write_timeout_(write_timeout) {}

int Connection::wait(short events, std::chrono::milliseconds timeout, bool stop_aborts) const {
  pollfd fds[2] = {{sock_, events, 0}, {stop_fd_, POLLIN, 0}};
  const nfds_t n = stop_aborts && stop_fd_ >= 0 ? 2 : 1;
  for (;;) {
    const int r = ::poll(fds, n, millis(timeout));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return r;
    if (n == 2 && (fds[1].revents & POLLIN)) return -1;
    return 1;
  }
}

bool Connection::is_readable() const {
  if (taken_ || head_refused_) return false;
  // While the head arrives, read() does the waiting, so that a deadline is answered with 408.
  return in_head_ || begin_ < end_ || wait(POLLIN, read_timeout_, true) > 0;
}

bool Connection::is_writable() const { return taken_ || wait(POLLOUT, write_timeout_, false) > 0; }

std::chrono::milliseconds Connection::read_wait() const {
  if (!in_head_) return read_timeout_;
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(head_deadline_ - Clock::now());
  return std::max(std::chrono::milliseconds(0), std::min(read_timeout_, left));
}

void Connection::begin_request(std::chrono::milliseconds timeout, size_t max_bytes) {
  in_head_ = true;
  head_deadline_ = Clock::now() + timeout;
  head_bytes_ = 0;
  max_head_bytes_ = max_bytes;
}

void Connection::refuse_head(int status) {
  const std::string answer =
      status == 431 ? plain_answer(431, "Request Header Fields Too Large", "header_too_large",
                                   "the request line and headers are larger than this server's limit of " +
                                       std::to_string(max_head_bytes_ / 1024) + " KiB")
                    : plain_answer(408, "Request Timeout", "request_timeout",
                                   "the request line and headers did not arrive in time; send them at once");
  for (size_t sent = 0; sent < answer.size();) {
    if (wait(POLLOUT, write_timeout_, true) <= 0) break;
    const ssize_t n = ::send(sock_, answer.data() + sent, answer.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;
    sent += static_cast<size_t>(n);
  }
  in_head_ = false;
  head_refused_ = true;
  closing_ = true;
}

ssize_t Connection::read(char* ptr, size_t size) {
  if (taken_ || head_refused_) return -1;
  if (in_head_ && (head_bytes_ >= max_head_bytes_ || Clock::now() >= head_deadline_)) {
    refuse_head(head_bytes_ >= max_head_bytes_ ? 431 : 408);
    return -1;
  }
  if (begin_ == end_) {
    const int ready = wait(POLLIN, read_wait(), true);
    if (ready == 0 && in_head_) {  // the head's deadline (or the read timeout) passed
      refuse_head(408);
      return -1;
    }
    if (ready <= 0) return -1;
    ssize_t n;
    do {
      n = ::recv(sock_, buffer_.data(), buffer_.size(), 0);
    } while (n < 0 && errno == EINTR);
    if (n <= 0) return n;
    begin_ = 0;
    end_ = static_cast<size_t>(n);
  }
  size_t n = std::min(size, end_ - begin_);
  if (in_head_) n = std::min(n, max_head_bytes_ - head_bytes_);
  std::memcpy(ptr, buffer_.data() + begin_, n);
  begin_ += n;
  if (in_head_) head_bytes_ += n;
  return static_cast<ssize_t>(n);
}

ssize_t Connection::write(const char* ptr, size_t size) {
  // The answer of a handed-off request goes nowhere; so does the library's answer to a head
  // this connection refused and answered itself.
  if (taken_ || head_refused_) return static_cast<ssize_t>(size);
  if (wait(POLLOUT, write_timeout_, false) <= 0) return -1;
  ssize_t n;
  do {
    n = ::send(sock_, ptr, size, MSG_NOSIGNAL);
  } while (n < 0 && errno == EINTR);
  return n;
}

void Connection::get_remote_ip_and_port(std::string& ip, int& port) const { address_of(sock_, true, ip, port); }
void Connection::get_local_ip_and_port(std::string& ip, int& port) const { address_of(sock_, false, ip, port); }

bool Connection::wait_for_request(std::chrono::milliseconds timeout) const {
  if (taken_) return false;
  if (begin_ < end_) return true;  // a pipelined request is already here
  return wait(POLLIN, timeout, true) > 0;
}

void Connection::linger(std::chrono::milliseconds limit) {
  ::shutdown(sock_, SHUT_WR);
  const auto deadline = std::chrono::steady_clock::now() + limit;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0 || wait(POLLIN, left, true) <= 0) return;
    ssize_t n;
    do {
      n = ::recv(sock_, buffer_.data(), buffer_.size(), 0);
    } while (n < 0 && errno == EINTR);
    if (n <= 0) return;
  }
}

int Connection::take() {
  taken_ = true;
  return sock_;
}

Listener::Listener() : stop_fd_(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)) {}

Listener::~Listener() {
  if (stop_fd_ >= 0) ::close(stop_fd_);
}

void Listener::raise_backlog(int backlog) {
  const auto sock = svr_sock_.load();
  if (sock != INVALID_SOCKET) ::listen(sock, backlog);
}

void Listener::wake_connections() {
  const uint64_t one = 1;
  if (stop_fd_ >= 0) (void)!::write(stop_fd_, &one, sizeof one);
}

bool Listener::admit(const std::string& address) {
  if (max_connections_per_address <= 0) return true;
  std::lock_guard lock(addresses_mu_);
  int& open = open_by_address_[address];
  if (open >= max_connections_per_address) {
    if (open == 0) open_by_address_.erase(address);
    return false;
  }
  ++open;
  return true;
}

void Listener::leave(const std::string& address) {
  if (max_connections_per_address <= 0) return;
  std::lock_guard lock(addresses_mu_);
  auto it = open_by_address_.find(address);
  if (it != open_by_address_.end() && --it->second <= 0) open_by_address_.erase(it);
}

// The library's loop (detail::process_server_socket), with this file's Connection.
bool Listener::process_and_close_socket(socket_t sock) {
  Connection connection(sock, stop_fd_, read_timeout, write_timeout);
  std::string address;
  int peer_port = 0;
  connection.get_remote_ip_and_port(address, peer_port);
  if (!admit(address)) {
    const std::string answer =
        plain_answer(503, "Service Unavailable", "unavailable",
                     "this address has " + std::to_string(max_connections_per_address) +
                         " connections open to the server already (its limit); reuse them or close some",
                     "Retry-After: 1\r\n");
    (void)!::send(sock, answer.data(), answer.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    connection.linger(std::chrono::milliseconds(200));
    ::shutdown(sock, SHUT_RDWR);
    ::close(sock);
    return false;
  }
  t_connection = &connection;
  bool ok = false;
  size_t left = keep_alive_max_count_;
  while (svr_sock_ != INVALID_SOCKET && left > 0 && connection.wait_for_request(keep_alive_timeout)) {
    bool closed = false;
    connection.begin_request(head_timeout, max_head_bytes);
    ok = process_request(connection, left == 1, closed, nullptr);
    if (!ok || closed || connection.taken() || connection.closing()) break;
    --left;
  }
  t_connection = nullptr;
  if (connection.closing() && !connection.taken()) connection.linger(std::chrono::seconds(2));
  if (!connection.taken()) {
    ::shutdown(sock, SHUT_RDWR);
    ::close(sock);
  }
  leave(address);
  return ok;
}

}  // namespace softshell::http::internal
