#pragma once
// The event writers (private to the HTTP layer): serve every `GET .../events` stream
// (Server-Sent Events) from a few threads (`Options::writers`, each with its own epoll set and
// a share of the streams) over non-blocking sockets.
//
// A connection thread answers the request's checks (404, 400, 503, 507) and then hands its
// socket over (`Connection::take`); from then on the stream costs no thread. Per geometry
// ("topic") the hub holds one service subscription; each stored result is serialized once into
// a frame shared by all of the topic's streams. Each stream has one frame being written and at
// most one waiting: a newer result replaces the waiting one (latest wins), so a slow follower
// never queues more than that and always gets the newest; the kernel's socket buffer is the
// only other buffer. Idle streams get a keep-alive comment; a stream that takes no bytes for
// `stall_timeout` is closed; on `stop` every stream finishes the frame it is writing, gets the
// end of its chunked body and is closed.

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "softshell/result.h"
#include "softshell/service/metrics.h"
#include "softshell/service/service.h"

namespace softshell::http::internal {

struct Topic;

class EventHub {
 public:
  struct Options {
    std::chrono::milliseconds keep_alive{10000};     // a comment after this long without a frame
    std::chrono::milliseconds stall_timeout{30000};  // a stream that takes nothing this long is closed
    std::chrono::milliseconds drain_timeout{2000};   // how long `stop` lets streams finish their frame
    size_t writers = 1;                              // writer threads (epoll sets); streams are dealt round-robin
  };

  struct Stats {
    size_t streams = 0;              // open streams
    size_t topics = 0;               // geometries with open streams
    uint64_t frames_serialized = 0;  // results serialized (once per result and topic)
    uint64_t frames_sent = 0;        // frames written out completely (over all streams)
    uint64_t frames_replaced = 0;    // frames a slow stream skipped for a newer one
    uint64_t streams_stalled = 0;    // streams closed because they took nothing for stall_timeout
    service::Histogram::Snapshot delivery;  // result reached the writers -> its event written to the socket
  };

  struct Impl;

  // A geometry's follower counted and subscribed, before its socket is handed over (destroying
  // it unhanded releases the follower).
  class Ticket {
   public:
    Ticket(Impl* hub, std::shared_ptr<Topic> topic) : hub_(hub), topic_(std::move(topic)) {}
    ~Ticket();
    Ticket(const Ticket&) = delete;
    Ticket& operator=(const Ticket&) = delete;
    std::shared_ptr<Topic> release() { return std::move(topic_); }

   private:
    Impl* hub_;
    std::shared_ptr<Topic> topic_;
  };

  EventHub(std::shared_ptr<service::Service> service, Options options);
  ~EventHub();
  EventHub(const EventHub&) = delete;
  EventHub& operator=(const EventHub&) = delete;

  // Counts a follower of `id` (the service's memory budget): kNotFound, kResourceExhausted,
  // kUnavailable (stopping).
  Result<std::unique_ptr<Ticket>> open(const GeomId& id);
  // Hands a connected socket over: the hub writes the response head, the newest result if its
  // id is above `have`, then every newer result. `http10`: the client speaks HTTP/1.0 (no
  // chunked body; the stream ends with the connection). `extra_head`: header lines ("Name:
  // value\r\n"...) for the response head, e.g. CORS. Never fails; the hub owns `fd`.
  void attach(std::unique_ptr<Ticket> ticket, int fd, uint32_t have, bool http10, std::string extra_head = {});

  // Ends every stream (see the file comment) and joins the writer. Idempotent.
  void stop();

  Stats stats() const;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace softshell::http::internal
