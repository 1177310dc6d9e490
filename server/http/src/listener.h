#pragma once
// The cpp-httplib server with softshell's connection loop (private to the HTTP layer).
//
// cpp-httplib 0.11 serves a connection on one of its task-queue threads through the (virtual)
// `process_and_close_socket`; `Listener` overrides it with its own loop over its own
// `httplib::Stream`, which cpp-httplib's request parser, router and response writer use
// unchanged. Owning the loop and the socket gives:
//  - hand-off: a handler can take the connection's socket (`Connection::take`), e.g. to pass an
//    event stream to the event writer, which serves thousands of them from one thread; the
//    library's answer to that request is then discarded and the socket is not closed;
//  - idle keep-alive connections that sleep in poll() (the library's loop wakes every 10 ms)
//    and wake at once when the server stops, as do reads of requests still arriving;
//  - one read buffer per connection, so pipelined requests are not lost between requests;
//  - limits cpp-httplib 0.11 does not have: a request head (request line and headers) must
//    arrive within a deadline and a size (408 or 431 otherwise, answered here), so a slow or
//    endless sender holds a thread for seconds, not forever; and a cap on the connections
//    one peer address has open at once (503 beyond it), so one client cannot take every thread.
// Every wait is poll(), never select() (no limit on descriptor numbers; cpp-httplib's select()
// path corrupts memory above 1024, upstream issue #754).

#include <sys/types.h>

#include <array>
#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <unordered_map>

// Last among the includes of a header: glibc's <resolv.h>, which httplib.h pulls in, defines a
// macro `_res` that breaks Eigen headers included after it.
#include <httplib.h>

namespace softshell::http::internal {

/// One accepted connection, as the `httplib::Stream` the library reads requests from and writes
/// answers to.
class Connection final : public httplib::Stream {
 public:
  Connection(int sock, int stop_fd, std::chrono::milliseconds read_timeout, std::chrono::milliseconds write_timeout);

  bool is_readable() const override;
  bool is_writable() const override;
  ssize_t read(char* ptr, size_t size) override;
  ssize_t write(const char* ptr, size_t size) override;
  void get_remote_ip_and_port(std::string& ip, int& port) const override;
  void get_local_ip_and_port(std::string& ip, int& port) const override;
  socket_t socket() const override { return sock_; }

  /// Waits up to `timeout` for the next request; false if none comes, the peer closed, or the
  /// server stops.
  bool wait_for_request(std::chrono::milliseconds timeout) const;

  /// A request starts: its head must be read within `timeout` and `max_bytes`. Past either,
  /// the connection answers 408 or 431 itself, then reads nothing more and discards what the
  /// library writes.
  void begin_request(std::chrono::milliseconds timeout, size_t max_bytes);
  /// The request's head was parsed (called by the first handler that sees it): the limits end.
  void head_complete() { in_head_ = false; }
  /// The head broke a limit and was answered (the request is over).
  bool head_refused() const { return head_refused_; }

  /// Hands the socket to the caller: from now on this connection reads nothing, discards what
  /// the library writes, and neither closes nor shuts the socket down.
  int take();
  bool taken() const { return taken_; }

  /// Ends the connection after the answer being written: its request's body was refused unread,
  /// so what follows on the socket cannot be parsed as a request.
  void close_after_answer() { closing_ = true; }
  bool closing() const { return closing_; }
  /// Stops sending, then reads and discards what the peer still sends until it closes or
  /// `limit` has passed: closing a socket with unread bytes resets the connection, and the reset
  /// can destroy the answer before the peer reads it.
  void linger(std::chrono::milliseconds limit);

 private:
  // poll() for `events` on the socket and the stop descriptor; > 0 ready, 0 timeout, < 0 error
  // or stop.
  int wait(short events, std::chrono::milliseconds timeout, bool stop_aborts) const;
  // How long a read may wait: the read timeout, shortened to the head's deadline.
  std::chrono::milliseconds read_wait() const;
  // Answers a head over a limit (status 408 or 431) and ends the request.
  void refuse_head(int status);

  int sock_;
  int stop_fd_;
  std::chrono::milliseconds read_timeout_, write_timeout_;
  std::array<char, 4096> buffer_{};
  size_t begin_ = 0, end_ = 0;  // unread bytes in buffer_
  bool taken_ = false;
  bool closing_ = false;
  bool in_head_ = false, head_refused_ = false;
  std::chrono::steady_clock::time_point head_deadline_{};
  size_t head_bytes_ = 0, max_head_bytes_ = 0;
};

/// The connection this thread serves right now (null outside a request).
Connection* current_connection();

/// cpp-httplib's server with softshell's connection loop.
class Listener final : public httplib::Server {
 public:
  Listener();
  ~Listener() override;

  /// cpp-httplib 0.11 listens with a backlog of 5: a burst of clients (hundreds of long polls
  /// or event streams connecting at once) overflows it and the dropped SYNs cost the clients a
  /// second or more. Calling listen() again on the bound socket raises it (Linux updates it in
  /// place).
  void raise_backlog(int backlog);
  /// Wakes idle keep-alive connections and requests still being read, so that `stop()` does not
  /// wait for them. Call before `stop()`.
  void wake_connections();

  std::chrono::milliseconds read_timeout{30000}, write_timeout{30000}, keep_alive_timeout{5000};
  /// Limits of a request head (see Connection::begin_request).
  std::chrono::milliseconds head_timeout{10000};
  size_t max_head_bytes = 64 * 1024;
  /// Connections one peer address may have open at once (0: no limit); beyond it a connection
  /// gets 503 and is closed.
  int max_connections_per_address = 0;

 private:
  bool process_and_close_socket(socket_t sock) override;
  // Counts a connection of `address`; false (not counted) if it has its limit already.
  bool admit(const std::string& address);
  void leave(const std::string& address);

  int stop_fd_ = -1;  // an eventfd, readable once wake_connections() ran
  std::mutex addresses_mu_;
  std::unordered_map<std::string, int> open_by_address_;
};

}  // namespace softshell::http::internal
