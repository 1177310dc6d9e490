// RemoteSession::subscribe: an event-stream client (GET /geometries/{id}/events, Server-Sent
// Events) on a thread of its own, over cpp-httplib's streaming GET. It reconnects after a dropped
// stream with `Last-Event-ID` (bounded backoff) and stops promptly when destroyed: cpp-httplib's
// `stop()` shuts the socket down under a read in progress, and the stream's callbacks refuse to
// go on once stopping.
#include <algorithm>
#include <atomic>
#include <thread>

#include "remote_impl.h"
#include "sse_parser.h"

namespace softshell {
namespace {

using Clock = std::chrono::steady_clock;

// Statuses after which trying again cannot help: the request itself is wrong or the geometry is
// unknown (after a server restart without it, say).
bool terminal(int status) { return status == 400 || status == 401 || status == 404 || status == 405 || status == 406; }

class StreamSource final : public EventSubscription::Source {
 public:
  StreamSource(std::string url, RemoteSessionOptions options, const GeomId& id, std::shared_ptr<EventFeed> feed)
      : url_(std::move(url)), options_(std::move(options)), path_(geometry_path(id) + "/events"), feed_(std::move(feed)) {}

  // Starts the thread and waits for the first answer: the stream's head (ok), an error status or
  // a transport error (returned; the thread has ended then).
  Result<void> start() {
    auto first = first_.get_future();
    thread_ = std::thread([this] { run(); });
    Result<void> ok = first.get();
    if (!ok) join();
    return ok;
  }

  ~StreamSource() override { join(); }

 private:
  void join() {
    if (!thread_.joinable()) return;
    stopping_.store(true);
    std::unique_lock lock(mu_);
    stop_cv_.notify_all();
    // cpp-httplib's stop() aborts a request in flight; one that has not reached its socket yet
    // is caught by the next round (and by the callbacks, which see `stopping_`).
    while (!done_) {
      if (client_) client_->stop();
      done_cv_.wait_for(lock, std::chrono::milliseconds(20));
    }
    lock.unlock();
    thread_.join();
  }

  void report_first(Result<void> r) {
    if (first_reported_) return;
    first_reported_ = true;
    first_.set_value(std::move(r));
  }

  // One connection: true if the stream was up (its head arrived with 200).
  bool connect_once() {
    auto client = remote::make_client(url_, options_);
    if (!client) {
      report_first(client.error());
      feed_->fail(client.error());
      return false;
    }
    (*client)->set_keep_alive(false);
    (*client)->set_read_timeout(options_.events_idle_timeout);
    httplib::Client* c = client->get();
    {
      std::lock_guard lock(mu_);
      if (stopping_.load()) return false;
      client_ = std::move(*client);
    }
    httplib::Headers headers{{"Accept", "text/event-stream"}, {"Accept-Encoding", "identity"}};
    if (const uint32_t newest = feed_->newest_id(); newest > 0) headers.emplace("Last-Event-ID", std::to_string(newest));

    int status = 0;
    std::string error_body;
    bool bad_event = false;
    remote::SseParser parser;
    bool deleted = false;
    const auto on_event = [&](const remote::SseEvent& e) {
      if (e.event == "deleted") {  // the geometry was deleted (DELETE /geometries/{id}): the feed ends
        deleted = true;
        feed_->fail(wire::decode_error_json(e.data, 410));
        return;
      }
      if (!e.event.empty() && e.event != "result") return;  // other kinds are for later versions
      auto held = wire::decode_held_result_json(e.data);
      if (!held) {
        bad_event = true;
        feed_->set_connecting(Error{ErrorCode::kInternal, "an event from " + url_ + " is not a result: " + held.error().message});
        return;
      }
      feed_->offer(std::move(*held));
    };
    auto res = c->Get(
        path_, headers,
        [&](const httplib::Response& r) {
          status = r.status;
          if (status == 200) {
            feed_->set_live();
            report_first({});
          }
          return !stopping_.load();
        },
        [&](const char* data, size_t n) {
          if (stopping_.load()) return false;
          if (status != 200) {
            if (error_body.size() < 65536) error_body.append(data, std::min<size_t>(n, 65536 - error_body.size()));
            return true;
          }
          const bool ok = parser.feed(std::string_view(data, n), on_event);
          return ok && !bad_event && !deleted;
        });
    {
      std::lock_guard lock(mu_);
      client_.reset();
    }
    if (stopping_.load()) return status == 200;
    if (status == 200) {
      if (bad_event || deleted) return true;  // (the reason is set already)
      feed_->set_connecting(Error{ErrorCode::kUnavailable, res ? "the event stream from " + url_ + " ended"
                                                               : remote::transport_error(res.error(), url_, options_)});
      return true;
    }
    const Error why = status != 0 ? remote::server_error(error_body, status, options_)
                                  : Error{ErrorCode::kUnavailable, remote::transport_error(res.error(), url_, options_)};
    report_first(why);
    if (terminal(status)) feed_->fail(why);
    else feed_->set_connecting(why);
    return false;
  }

  void run() {
    auto backoff = options_.events_retry_min;
    bool up_once = false;
    while (!stopping_.load()) {
      const bool was_up = connect_once();
      up_once = up_once || was_up;
      // The first attempt failed (subscribe returns its error), or trying again cannot help.
      if (!up_once || feed_->state() == FeedState::kFailed) break;
      if (was_up) backoff = options_.events_retry_min;
      std::unique_lock lock(mu_);
      if (stop_cv_.wait_for(lock, backoff, [&] { return stopping_.load(); })) break;
      if (!was_up) backoff = std::min(backoff * 2, options_.events_retry_max);
    }
    report_first(Error{ErrorCode::kCancelled, "the subscription was stopped"});  // (if not reported yet)
    std::lock_guard lock(mu_);
    done_ = true;
    done_cv_.notify_all();
  }

  std::string url_;
  RemoteSessionOptions options_;
  std::string path_;
  std::shared_ptr<EventFeed> feed_;

  std::promise<Result<void>> first_;
  bool first_reported_ = false;  // (the stream thread only)

  std::atomic<bool> stopping_{false};
  std::mutex mu_;  // guards client_, done_
  std::condition_variable stop_cv_, done_cv_;
  std::unique_ptr<httplib::Client> client_;
  bool done_ = false;
  std::thread thread_;
};

}  // namespace

Result<std::unique_ptr<EventSubscription>> RemoteSession::subscribe(const GeomId& id, uint32_t after) {
  auto feed = std::make_shared<EventFeed>(after);
  auto source = std::make_unique<StreamSource>(impl_->url, impl_->options, id, feed);
  if (auto ok = source->start(); !ok) return ok.error();
  return std::make_unique<EventSubscription>(feed, std::move(source));
}

}  // namespace softshell
