#include "listener.h"

#include <netdb.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace softshell::http::internal {

namespace {

thread_local Connection* t_connection = nullptr;

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

bool Connection::is_readable() const { return taken_ ? false : begin_ < end_ || wait(POLLIN, read_timeout_, true) > 0; }

bool Connection::is_writable() const { return taken_ || wait(POLLOUT, write_timeout_, false) > 0; }

ssize_t Connection::read(char* ptr, size_t size) {
  if (taken_) return -1;
  if (begin_ == end_) {
    if (wait(POLLIN, read_timeout_, true) <= 0) return -1;
    ssize_t n;
    do {
      n = ::recv(sock_, buffer_.data(), buffer_.size(), 0);
    } while (n < 0 && errno == EINTR);
    if (n <= 0) return n;
    begin_ = 0;
    end_ = static_cast<size_t>(n);
  }
  const size_t n = std::min(size, end_ - begin_);
  std::memcpy(ptr, buffer_.data() + begin_, n);
  begin_ += n;
  return static_cast<ssize_t>(n);
}

ssize_t Connection::write(const char* ptr, size_t size) {
  if (taken_) return static_cast<ssize_t>(size);  // the answer of a handed-off request goes nowhere
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

// The library's loop (detail::process_server_socket), with this file's Connection.
bool Listener::process_and_close_socket(socket_t sock) {
  Connection connection(sock, stop_fd_, read_timeout, write_timeout);
  t_connection = &connection;
  bool ok = false;
  size_t left = keep_alive_max_count_;
  while (svr_sock_ != INVALID_SOCKET && left > 0 && connection.wait_for_request(keep_alive_timeout)) {
    bool closed = false;
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
  return ok;
}

}  // namespace softshell::http::internal
