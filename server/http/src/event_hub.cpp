// (One file of ~700 lines: the frames, streams, topics and writer shards share private structures
// that nothing outside the event writers needs.)
#include "event_hub.h"

#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <string_view>
#include <cerrno>
#include <cstring>
#include <string_view>
#include <thread>

#include "server_header.h"
#include "softshell/wire.h"

namespace softshell::http::internal {

using service::ResultPtr;

namespace {

using Clock = std::chrono::steady_clock;

struct GeomIdKey {
  size_t operator()(const GeomId& id) const noexcept {
    size_t h = 0;
    std::memcpy(&h, id.bytes.data(), sizeof h);  // the id is a cryptographic hash already
    return h;
  }
};

// What goes out on a stream: the chunked form of the bytes (`bytes`), and where the plain bytes
// are inside it (for HTTP/1.0 streams, which have no chunked framing).
struct Frame {
  std::string bytes;
  size_t raw_begin = 0, raw_end = 0;
  uint32_t res_id = 0;  // 0: not a result (head, keep-alive, end)
  Clock::time_point stored{};  // when the result reached the writers (for the delivery lag)
};
using FramePtr = std::shared_ptr<const Frame>;

std::shared_ptr<Frame> chunk(std::string_view payload, uint32_t res_id) {
  auto f = std::make_shared<Frame>();
  char size[24];
  const int n = std::snprintf(size, sizeof size, "%zx\r\n", payload.size());
  f->bytes.reserve(static_cast<size_t>(n) + payload.size() + 2);
  f->bytes.append(size, static_cast<size_t>(n)).append(payload).append("\r\n");
  f->raw_begin = static_cast<size_t>(n);
  f->raw_end = f->raw_begin + payload.size();
  f->res_id = res_id;
  return f;
}

FramePtr whole(std::string bytes) {
  auto f = std::make_shared<Frame>();
  f->bytes = std::move(bytes);
  f->raw_end = f->bytes.size();
  return f;
}

std::string head_text(bool http10, std::string_view extra) {
  std::string h = http10 ? "HTTP/1.0 200 OK\r\n" : "HTTP/1.1 200 OK\r\n";
  h += "Content-Type: text/event-stream\r\nCache-Control: no-cache\r\nX-Accel-Buffering: no\r\n";
  h += std::string("Server: ") + kServerHeader + "\r\n";
  h += extra;
  h += http10 ? "Connection: close\r\n\r\n" : "Transfer-Encoding: chunked\r\n\r\n";
  return h;
}
// The response head; shared by every stream without extra header lines.
FramePtr head(bool http10, const std::string& extra) {
  static const FramePtr h11 = whole(head_text(false, {}));
  static const FramePtr h10 = whole(head_text(true, {}));
  if (extra.empty()) return http10 ? h10 : h11;
  return whole(head_text(http10, extra));
}
const FramePtr& keep_alive_frame() {
  static const FramePtr f = chunk(": keep-alive\n\n", 0);
  return f;
}
const FramePtr& end_frame() {
  static const FramePtr f = [] {
    auto e = std::make_shared<Frame>();
    e->bytes = "0\r\n\r\n";  // the end of a chunked body; nothing for HTTP/1.0
    return FramePtr(std::move(e));
  }();
  return f;
}

// The last frame of a stream whose geometry was deleted: an `event: deleted` with the error
// (the JSON error layout) and, for chunked streams, the end of the body.
FramePtr deleted_frame(const Error& error) {
  std::string payload = "event: deleted\ndata: " + wire::encode_error_json(error) + "\n\n";
  auto f = chunk(payload, 0);
  f->bytes.append("0\r\n\r\n");
  return f;
}

}  // namespace

struct Topic;
struct Shard;

// One open stream (its shard's thread only).
struct Stream {
  int fd = -1;
  std::shared_ptr<Topic> topic;
  bool chunked = true;
  size_t topic_index = 0, all_index = 0;
  FramePtr current;       // being written
  size_t offset = 0;
  FramePtr next;          // waiting (latest wins)
  uint32_t sent_id = 0;   // newest result queued (or the client's `have`)
  bool want_out = false;  // EPOLLOUT registered
  bool blocked = false;
  bool closing = false;   // the end is queued: close once written
  Clock::time_point blocked_since{}, last_write{}, attached{};

  std::string_view view(const Frame& f) const {
    return chunked ? std::string_view(f.bytes)
                   : std::string_view(f.bytes).substr(f.raw_begin, f.raw_end - f.raw_begin);
  }
};

// A geometry with open streams.
struct Topic {
  explicit Topic(size_t shards) : per_shard(shards) {}
  GeomId id;
  // Set (once) when the geometry is deleted: its streams get `ended` and close, and a new stream
  // of the same id (a new upload) gets a new topic.
  std::atomic<bool> deleted{false};
  FramePtr ended;  // written before `deleted` is set
  // Under Impl::topics_mu:
  std::unique_ptr<service::Subscription> subscription;
  size_t members = 0;  // tickets and streams
  // The newest result serialized, shared by every shard (under frame_mu).
  std::mutex frame_mu;
  FramePtr frame;
  struct PerShard {
    ResultPtr incoming;  // under the shard's inbox_mu
    Clock::time_point incoming_at{};
    bool queued = false;
    bool ending = false;  // under inbox_mu: the geometry was deleted
    ResultPtr latest;    // the shard's thread only, from here on: the newest result it has seen
    Clock::time_point latest_at{};
    std::vector<Stream*> streams;
  };
  std::vector<PerShard> per_shard;

  // The frame of `result`, serialized by the first shard that asks; null if a newer one is
  // already out (this one is then skipped).
  FramePtr frame_of(const ResultPtr& result, Clock::time_point stored, std::atomic<uint64_t>& serialized) {
    std::lock_guard lock(frame_mu);
    if (frame && frame->res_id >= result->res_id) return frame->res_id == result->res_id ? frame : nullptr;
    // A stored result is finite, so only memory can fail here (logged by capture); the frame is
    // then skipped and the next result tried.
    auto json = capture(
        [&] {
          return result->holds ? wire::encode_result_json(result->to_result(), *result->holds)
                               : wire::encode_result_json(result->to_result());
        },
        "encoding an event");
    if (!json) return nullptr;
    std::string payload = "id: " + std::to_string(result->res_id) + "\nevent: result\ndata: ";
    payload.append(*json).append("\n\n");
    auto made = chunk(payload, result->res_id);
    made->stored = stored;
    frame = std::move(made);
    serialized.fetch_add(1, std::memory_order_relaxed);
    return frame;
  }
};

struct Arrival {
  std::shared_ptr<Topic> topic;
  int fd = -1;
  uint32_t have = 0;
  bool http10 = false;
  std::string extra_head;  // header lines ("Name: value\r\n"...) for this stream's head (CORS)
};

// Per shard (no cache line shared between writers); the hub adds them up.
struct Counters {
  std::atomic<size_t> streams{0};
  std::atomic<uint64_t> frames_serialized{0}, frames_sent{0}, frames_replaced{0}, streams_stalled{0};
  service::Histogram delivery;  // seconds from a result reaching the writers to its event written out
};

// One writer thread with its own epoll set, serving a share of the streams.
struct Shard {
  Shard(size_t i, const EventHub::Options& o, std::function<void(const std::shared_ptr<Topic>&)> on_leave)
      : index(i), options(o), leave(std::move(on_leave)) {
    epfd = ::epoll_create1(EPOLL_CLOEXEC);
    wakefd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (epfd < 0 || wakefd < 0) throw Exception(ErrorCode::kUnavailable, "the event writer cannot start (epoll)");
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.ptr = nullptr;  // the wake-up descriptor
    ::epoll_ctl(epfd, EPOLL_CTL_ADD, wakefd, &ev);
    writer = std::thread([this] { run(); });
  }

  ~Shard() {
    stop();
    ::close(epfd);
    ::close(wakefd);
  }

  // --- any thread ----------------------------------------------------------------------------
  void wake() {
    const uint64_t one = 1;
    (void)!::write(wakefd, &one, sizeof one);
  }

  void post(const std::shared_ptr<Topic>& topic, const ResultPtr& result) {
    bool signal = false;
    {
      std::lock_guard lock(inbox_mu);
      auto& mine = topic->per_shard[index];
      if (!mine.incoming || result->res_id > mine.incoming->res_id) {
        mine.incoming = result;
        mine.incoming_at = Clock::now();
      }
      if (!mine.queued) {
        mine.queued = true;
        signal = updated.empty() && arrivals.empty();
        updated.push_back(topic);
      }
    }
    if (signal) wake();
  }

  // The topic's geometry was deleted: its streams of this shard end (after the frame each writes).
  void post_end(const std::shared_ptr<Topic>& topic) {
    bool signal = false;
    {
      std::lock_guard lock(inbox_mu);
      auto& mine = topic->per_shard[index];
      mine.ending = true;
      if (!mine.queued) {
        mine.queued = true;
        signal = updated.empty() && arrivals.empty();
        updated.push_back(topic);
      }
    }
    if (signal) wake();
  }

  // False if the shard stops (the caller answers the client).
  bool attach(Arrival a) {
    bool signal = false;
    {
      std::lock_guard lock(inbox_mu);
      if (stop_requested) return false;
      signal = updated.empty() && arrivals.empty();
      arrivals.push_back(std::move(a));
    }
    if (signal) wake();
    return true;
  }

  void request_stop() {
    {
      std::lock_guard lock(inbox_mu);
      stop_requested = true;
    }
    wake();
  }

  void stop() {
    request_stop();
    std::lock_guard join_lock(join_mu);
    if (writer.joinable()) writer.join();
  }

  // --- the writer thread ---------------------------------------------------------------------
  void run() {
    std::vector<epoll_event> events(512);
    auto next_sweep = Clock::now() + std::chrono::seconds(1);
    bool draining = false;
    Clock::time_point drain_deadline{};
    for (;;) {
      const auto now = Clock::now();
      auto until = draining ? std::min(next_sweep, drain_deadline) : next_sweep;
      const int timeout = static_cast<int>(std::max<int64_t>(
          0, std::chrono::duration_cast<std::chrono::milliseconds>(until - now).count() + 1));
      const int n = ::epoll_wait(epfd, events.data(), static_cast<int>(events.size()), timeout);
      for (int i = 0; i < n; ++i) {
        if (events[static_cast<size_t>(i)].data.ptr == nullptr) {
          uint64_t count;
          (void)!::read(wakefd, &count, sizeof count);
          continue;
        }
        auto* s = static_cast<Stream*>(events[static_cast<size_t>(i)].data.ptr);
        if (s->fd < 0) continue;  // closed earlier in this batch
        handle(*s, events[static_cast<size_t>(i)].events);
      }
      if (!draining && take_inbox()) {
        draining = true;
        drain_deadline = Clock::now() + options.drain_timeout;
        for (Stream* s : std::vector<Stream*>(all)) finish(*s);
      }
      if (Clock::now() >= next_sweep) {
        sweep();
        next_sweep = Clock::now() + std::chrono::seconds(1);
      }
      bury();
      if (draining && (all.empty() || Clock::now() >= drain_deadline)) break;
    }
    for (Stream* s : std::vector<Stream*>(all)) close(*s);
    bury();
  }

  // Takes what other threads queued; true if stopping was asked for.
  bool take_inbox() {
    std::vector<std::shared_ptr<Topic>> topics_now;
    std::vector<Arrival> arrived;
    std::vector<std::pair<ResultPtr, Clock::time_point>> results;
    std::vector<bool> ending;
    bool stop_now = false;
    {
      std::lock_guard lock(inbox_mu);
      topics_now.swap(updated);
      arrived.swap(arrivals);
      for (const auto& t : topics_now) {
        auto& mine = t->per_shard[index];
        results.emplace_back(std::move(mine.incoming), mine.incoming_at);
        ending.push_back(mine.ending);
        mine.incoming.reset();
        mine.queued = false;
      }
      stop_now = stop_requested;
    }
    for (size_t i = 0; i < topics_now.size(); ++i) {
      publish(*topics_now[i], results[i].first, results[i].second);
      if (ending[i]) {
        for (Stream* s : std::vector<Stream*>(topics_now[i]->per_shard[index].streams)) end_deleted(*s);
      }
    }
    for (auto& a : arrived) add(std::move(a));
    return stop_now;
  }

  void publish(Topic& topic, const ResultPtr& result, Clock::time_point stored) {
    auto& mine = topic.per_shard[index];
    if (!result || (mine.latest && result->res_id <= mine.latest->res_id)) return;
    mine.latest = result;
    mine.latest_at = stored;
    if (mine.streams.empty()) return;  // (serialized when a stream of this shard needs it)
    // Null when another shard already serialized a newer one: it is in this shard's inbox too.
    FramePtr frame = topic.frame_of(result, stored, counters.frames_serialized);
    if (!frame) return;
    for (Stream* s : std::vector<Stream*>(mine.streams)) deliver(*s, frame);
  }

  void add(Arrival a) {
    auto* s = new Stream;
    s->fd = a.fd;
    s->topic = std::move(a.topic);
    s->chunked = !a.http10;
    s->sent_id = a.have;
    s->last_write = s->attached = Clock::now();
    epoll_event ev{};
    ev.events = EPOLLIN | EPOLLRDHUP;
    ev.data.ptr = s;
    if (::epoll_ctl(epfd, EPOLL_CTL_ADD, s->fd, &ev) != 0) {
      ::close(s->fd);
      leave(s->topic);
      delete s;
      return;
    }
    auto& mine = s->topic->per_shard[index];
    s->topic_index = mine.streams.size();
    mine.streams.push_back(s);
    s->all_index = all.size();
    all.push_back(s);
    counters.streams.fetch_add(1, std::memory_order_relaxed);
    s->current = head(a.http10, a.extra_head);
    // The newest result: this shard's (serialized now if none of its streams needed it yet), or
    // a newer one another shard serialized already.
    FramePtr newest = mine.latest ? s->topic->frame_of(mine.latest, mine.latest_at, counters.frames_serialized) : nullptr;
    if (!newest) {
      std::lock_guard lock(s->topic->frame_mu);
      newest = s->topic->frame;
    }
    if (newest) deliver(*s, newest);
    flush(*s);
    if (s->fd >= 0 && s->topic->deleted.load()) end_deleted(*s);  // deleted while it was handed over
  }

  // The geometry was deleted: the `deleted` event and the end of the stream go after the frame
  // being written (a waiting result is dropped; nothing newer can come).
  void end_deleted(Stream& s) {
    if (s.closing || s.fd < 0) return;
    s.closing = true;
    if (s.current) {
      s.next = s.topic->ended;
    } else {
      s.current = s.topic->ended;
      s.offset = 0;
    }
    flush(s);
  }

  void deliver(Stream& s, const FramePtr& frame) {
    if (s.closing || frame->res_id <= s.sent_id) return;
    s.sent_id = frame->res_id;
    if (!s.current) {
      s.current = frame;
      s.offset = 0;
      flush(s);
    } else {
      if (s.next && s.next->res_id) counters.frames_replaced.fetch_add(1, std::memory_order_relaxed);
      s.next = frame;
    }
  }

  void flush(Stream& s) {
    while (s.current && s.fd >= 0) {
      const std::string_view data = s.view(*s.current);
      if (s.offset < data.size()) {
        const ssize_t n = ::send(s.fd, data.data() + s.offset, data.size() - s.offset, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n < 0) {
          if (errno == EINTR) continue;
          if (errno == EAGAIN || errno == EWOULDBLOCK) {
            if (!s.blocked) {
              s.blocked = true;
              s.blocked_since = Clock::now();
            }
            watch_out(s, true);
            return;
          }
          close(s);
          return;
        }
        s.offset += static_cast<size_t>(n);
        continue;
      }
      const auto now = Clock::now();
      if (s.current->res_id) {
        counters.frames_sent.fetch_add(1, std::memory_order_relaxed);
        // Stored -> written out: the lag of a result stored while the stream was open.
        if (s.current->stored > s.attached) {
          counters.delivery.observe(std::chrono::duration<double>(now - s.current->stored).count());
        }
      }
      s.current = std::move(s.next);
      s.next.reset();
      s.offset = 0;
      s.blocked = false;
      s.last_write = now;
    }
    if (s.fd < 0) return;
    watch_out(s, false);
    if (s.closing && !s.current) {
      ::shutdown(s.fd, SHUT_WR);
      close(s);
    }
  }

  void watch_out(Stream& s, bool on) {
    if (s.want_out == on) return;
    s.want_out = on;
    epoll_event ev{};
    ev.events = EPOLLIN | EPOLLRDHUP | (on ? EPOLLOUT : 0u);
    ev.data.ptr = &s;
    ::epoll_ctl(epfd, EPOLL_CTL_MOD, s.fd, &ev);
  }

  void handle(Stream& s, uint32_t ev) {
    if (ev & (EPOLLERR | EPOLLHUP)) {
      close(s);
      return;
    }
    if (ev & (EPOLLIN | EPOLLRDHUP)) {
      // Followers send nothing after their request; anything is read and dropped, and the end
      // of their side means they are gone.
      char scratch[4096];
      for (;;) {
        const ssize_t n = ::recv(s.fd, scratch, sizeof scratch, MSG_DONTWAIT);
        if (n > 0) continue;
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
        close(s);
        return;
      }
    }
    if (ev & EPOLLOUT) flush(s);
  }

  // Queues the end of the stream after the frame being written (a newer waiting one is dropped).
  void finish(Stream& s) {
    if (s.closing || s.fd < 0) return;
    s.closing = true;
    if (s.current) {
      s.next = end_frame();
    } else {
      s.current = end_frame();
      s.offset = 0;
    }
    flush(s);
  }

  void sweep() {
    const auto now = Clock::now();
    for (Stream* s : std::vector<Stream*>(all)) {
      if (s->fd < 0) continue;
      if (s->current && s->blocked && now - s->blocked_since > options.stall_timeout) {
        counters.streams_stalled.fetch_add(1, std::memory_order_relaxed);
        close(*s);
      } else if (!s->current && !s->closing && now - s->last_write >= options.keep_alive) {
        s->current = keep_alive_frame();
        s->offset = 0;
        flush(*s);
      }
    }
  }

  void close(Stream& s) {
    if (s.fd < 0) return;
    ::epoll_ctl(epfd, EPOLL_CTL_DEL, s.fd, nullptr);
    ::close(s.fd);
    s.fd = -1;
    auto& list = s.topic->per_shard[index].streams;
    list[s.topic_index] = list.back();
    list[s.topic_index]->topic_index = s.topic_index;
    list.pop_back();
    all[s.all_index] = all.back();
    all[s.all_index]->all_index = s.all_index;
    all.pop_back();
    counters.streams.fetch_sub(1, std::memory_order_relaxed);
    graveyard.push_back(&s);
  }

  // Frees streams closed in this round (events of the same epoll batch may still name them).
  void bury() {
    for (Stream* s : graveyard) {
      leave(s->topic);
      delete s;
    }
    graveyard.clear();
  }

  const size_t index;
  const EventHub::Options options;
  alignas(64) Counters counters;
  const std::function<void(const std::shared_ptr<Topic>&)> leave;
  int epfd = -1, wakefd = -1;

  std::mutex inbox_mu;
  std::vector<std::shared_ptr<Topic>> updated;
  std::vector<Arrival> arrivals;
  bool stop_requested = false;

  // Writer thread only.
  std::vector<Stream*> all;
  std::vector<Stream*> graveyard;

  std::mutex join_mu;
  std::thread writer;  // last: starts once everything above exists
};

struct EventHub::Impl {
  Impl(std::shared_ptr<service::Service> s, Options o) : service(std::move(s)), options(o) {
    const size_t n = std::max<size_t>(1, options.writers);
    for (size_t i = 0; i < n; ++i) {
      shards.push_back(std::make_unique<Shard>(i, options, [this](const std::shared_ptr<Topic>& t) { leave(t); }));
    }
  }

  ~Impl() {
    stop();
    // The subscriptions end before the shards go (a listener call would post to them).
    std::lock_guard lock(topics_mu);
    for (auto& [id, topic] : topics) topic->subscription.reset();
    topics.clear();
  }

  void post(const std::shared_ptr<Topic>& topic, const ResultPtr& result) {
    for (auto& shard : shards) shard->post(topic, result);
  }

  void leave(const std::shared_ptr<Topic>& topic) {
    std::lock_guard lock(topics_mu);
    if (--topic->members > 0) {
      if (topic->subscription) (void)topic->subscription->set_followers(topic->members);  // fewer: never refused
      return;
    }
    if (auto it = topics.find(topic->id); it != topics.end() && it->second == topic) topics.erase(it);
    topic->subscription.reset();
  }

  Result<std::shared_ptr<Topic>> join(const GeomId& id) {
    std::lock_guard lock(topics_mu);
    if (stopping) return Error{ErrorCode::kUnavailable, "the server is shutting down"};
    if (auto it = topics.find(id); it != topics.end() && !it->second->deleted.load()) {
      const auto& topic = it->second;
      if (auto ok = topic->subscription->set_followers(topic->members + 1); !ok) return ok.error();
      ++topic->members;
      return topic;
    }
    auto topic = std::make_shared<Topic>(shards.size());
    topic->id = id;
    std::weak_ptr<Topic> weak = topic;
    auto subscription = service->subscribe(
        id, [this, weak](const ResultPtr& r) {
          if (auto t = weak.lock()) post(t, r);
        },
        1, [this, weak](const Error& error) {
          // Called under the subscription's slot lock: only flags and the shards' inboxes here
          // (topics_mu is taken by leave() while it destroys subscriptions).
          auto t = weak.lock();
          if (!t) return;
          t->ended = deleted_frame(error);
          t->deleted.store(true);
          for (auto& shard : shards) shard->post_end(t);
        });
    if (!subscription) return subscription.error();
    topic->subscription = std::move(*subscription);
    topic->members = 1;
    topics[id] = topic;  // (replaces a deleted geometry's topic, which lives on until its streams end)
    // The newest result stored before the subscription (after it, so that none falls between).
    if (auto newest = service->latest_result(id, 0, std::chrono::milliseconds(0)); newest && *newest) post(topic, *newest);
    return topic;
  }

  void attach(std::shared_ptr<Topic> topic, int fd, uint32_t have, bool http10, std::string extra_head) {
    const int flags = ::fcntl(fd, F_GETFL, 0);
    ::fcntl(fd, F_SETFL, flags | O_NONBLOCK);
    int yes = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
    Shard& shard = *shards[next_shard.fetch_add(1, std::memory_order_relaxed) % shards.size()];
    if (shard.attach({topic, fd, have, http10, std::move(extra_head)})) return;
    // Stopping: the stream would end at once.
    static constexpr std::string_view kBusy =
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nContent-Length: 61\r\n"
        "Connection: close\r\n\r\n{\"error\":\"unavailable\",\"message\":\"the server is shutting down\"}";
    (void)!::send(fd, kBusy.data(), kBusy.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    ::shutdown(fd, SHUT_WR);
    ::close(fd);
    leave(topic);
  }

  void stop() {
    {
      std::lock_guard lock(topics_mu);
      stopping = true;
    }
    for (auto& shard : shards) shard->request_stop();  // all drain at once
    for (auto& shard : shards) shard->stop();
  }

  std::shared_ptr<service::Service> service;
  Options options;

  mutable std::mutex topics_mu;
  std::unordered_map<GeomId, std::shared_ptr<Topic>, GeomIdKey> topics;
  bool stopping = false;

  std::atomic<size_t> next_shard{0};
  std::vector<std::unique_ptr<Shard>> shards;  // last: their threads use everything above
};

EventHub::Ticket::~Ticket() {
  if (topic_) hub_->leave(topic_);
}

EventHub::EventHub(std::shared_ptr<service::Service> service, Options options)
    : impl_(std::make_unique<Impl>(std::move(service), options)) {}

EventHub::~EventHub() = default;

Result<std::unique_ptr<EventHub::Ticket>> EventHub::open(const GeomId& id) {
  auto topic = impl_->join(id);
  if (!topic) return topic.error();
  return std::make_unique<Ticket>(impl_.get(), std::move(*topic));
}

void EventHub::attach(std::unique_ptr<Ticket> ticket, int fd, uint32_t have, bool http10, std::string extra_head) {
  impl_->attach(ticket->release(), fd, have, http10, std::move(extra_head));
}

void EventHub::stop() { impl_->stop(); }

EventHub::Stats EventHub::stats() const {
  Stats s;
  for (const auto& shard : impl_->shards) {
    const Counters& c = shard->counters;
    s.streams += c.streams.load(std::memory_order_relaxed);
    s.frames_serialized += c.frames_serialized.load(std::memory_order_relaxed);
    s.frames_sent += c.frames_sent.load(std::memory_order_relaxed);
    s.frames_replaced += c.frames_replaced.load(std::memory_order_relaxed);
    s.streams_stalled += c.streams_stalled.load(std::memory_order_relaxed);
    const auto d = c.delivery.snapshot();
    for (size_t b = 0; b < d.buckets.size(); ++b) s.delivery.buckets[b] += d.buckets[b];
    s.delivery.count += d.count;
    s.delivery.sum += d.sum;
  }
  std::lock_guard lock(impl_->topics_mu);
  s.topics = impl_->topics.size();
  return s;
}

}  // namespace softshell::http::internal
