#pragma once
// RemoteSession's private state (remote_session.cpp, remote_holds.cpp, remote_events.cpp): the
// connection pool, the request helpers and the async-call bookkeeping.
#include <charconv>
#include <condition_variable>
#include <functional>
#include <mutex>

#include "softshell/remote_session.h"

// Last: glibc's <resolv.h>, which httplib.h pulls in, defines a macro `_res` that breaks Eigen
// headers included after it.
#include <httplib.h>

namespace softshell {
namespace remote {

inline std::string number_text(double v) {
  char buf[32];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, ptr);
}

inline bool is_binary(const std::string& content_type) {
  return content_type.rfind(wire::kBinaryMediaType, 0) == 0;
}

inline std::string geometry_path(const GeomId& id) { return "/geometries/" + id.hex(); }

// What went wrong on the way, in words a person can act on (httplib's own names, such as
// "Connection", say little).
inline std::string transport_error(httplib::Error e, const std::string& url, const RemoteSessionOptions& options) {
  using E = httplib::Error;
  const auto seconds = [](std::chrono::milliseconds ms) { return number_text(static_cast<double>(ms.count()) / 1000.0); };
  switch (e) {
    case E::Connection:
      return "connection refused: is softshell-server running at " + url + "?";
    case E::ConnectionTimeout:
      return "no connection to " + url + " within " + seconds(options.connect_timeout) +
             " s: is the host reachable and softshell-server running there?";
    case E::Read:
      return "the softshell server at " + url + " closed the connection or did not answer in time";
    case E::Write:
      return "sending the request to the softshell server at " + url + " failed (the connection was closed)";
    default:
      return "no answer from the softshell server at " + url + ": " + httplib::to_string(e);
  }
}

// The error of a server's error answer. A 401 (the server's --auth-token-file) is
// kInvalidArgument, as other refused requests, and also says where the SDK takes the token.
inline Error server_error(std::string_view body, int status, const RemoteSessionOptions& options) {
  Error e = wire::decode_error_json(body, status);
  if (status == 401) {
    e.message += options.auth_token.empty() ? " (RemoteSessionOptions::auth_token is empty)"
                                            : " (RemoteSessionOptions::auth_token was sent and refused)";
  }
  return e;
}

// A client of the server at `url` with the session's timeouts; kInvalidArgument for a bad URL.
Result<std::unique_ptr<httplib::Client>> make_client(const std::string& url, const RemoteSessionOptions& options);

}  // namespace remote

using remote::geometry_path;
using remote::is_binary;
using remote::number_text;

struct RemoteSession::Impl {
  struct Reply {
    int status = 0;
    std::string body;
    std::string content_type;
  };

  Impl(std::string_view u, RemoteSessionOptions o) : url(u), options(std::move(o)) {
    executor = options.executor ? options.executor : std::make_shared<ThreadPool>(std::max(1, options.async_threads));
  }

  // Waits for the deform_async calls still running (on the host's executor they are not ours to
  // join).
  ~Impl() {
    std::unique_lock lock(task_mu);
    task_cv.wait(lock, [&] { return in_flight == 0; });
  }

  // --- connections -------------------------------------------------------------------------
  Result<std::unique_ptr<httplib::Client>> acquire() {
    {
      std::lock_guard lock(pool_mu);
      if (!idle.empty()) {
        auto c = std::move(idle.back());
        idle.pop_back();
        return c;
      }
    }
    return remote::make_client(url, options);
  }

  void release(std::unique_ptr<httplib::Client> c) {
    std::lock_guard lock(pool_mu);
    if (static_cast<int>(idle.size()) < options.max_idle_connections) idle.push_back(std::move(c));
  }

  httplib::Headers headers(std::string_view accept) const {
    httplib::Headers h{{"Accept", std::string(accept)}};
    if (!options.compress) h.emplace("Accept-Encoding", "identity");
    return h;
  }

  Result<Reply> finish(std::unique_ptr<httplib::Client> c, httplib::Result res) {
    if (!res) return Error{ErrorCode::kUnavailable, transport_error(res.error())};
    Reply reply{res->status, std::move(res->body), res->get_header_value("Content-Type")};
    if (res->get_header_value("Connection") != "close") release(std::move(c));
    return reply;
  }

  Result<Reply> get(const std::string& path, std::string_view accept,
                    std::chrono::milliseconds extra_time = std::chrono::milliseconds(0)) {
    auto c = acquire();
    if (!c) return c.error();
    (*c)->set_read_timeout(options.request_timeout + extra_time);
    auto res = (*c)->Get(path, headers(accept));
    return finish(std::move(*c), std::move(res));
  }

  Result<Reply> post(const std::string& path, const std::string& body, wire::Format body_format,
                     std::string_view accept) {
    auto c = acquire();
    if (!c) return c.error();
    (*c)->set_read_timeout(options.request_timeout);
    auto res = (*c)->Post(path, headers(accept), body, std::string(wire::media_type(body_format)));
    return finish(std::move(*c), std::move(res));
  }

  Result<Reply> put(const std::string& path, const std::string& body, wire::Format body_format,
                    std::string_view accept, std::chrono::milliseconds extra_time) {
    auto c = acquire();
    if (!c) return c.error();
    (*c)->set_read_timeout(options.request_timeout + extra_time);
    auto res = (*c)->Put(path, headers(accept), body, std::string(wire::media_type(body_format)));
    return finish(std::move(*c), std::move(res));
  }

  Result<Reply> del(const std::string& path, std::string_view accept, std::chrono::milliseconds extra_time) {
    auto c = acquire();
    if (!c) return c.error();
    (*c)->set_read_timeout(options.request_timeout + extra_time);
    auto res = (*c)->Delete(path, headers(accept));
    return finish(std::move(*c), std::move(res));
  }

  // A deformation request's body: binary when the preferred format is binary and the layout
  // carries the request, JSON otherwise.
  struct Body {
    std::string bytes;
    wire::Format format = wire::Format::kJson;
  };
  Result<Body> encode(const DeformationRequest& request) const {
    Body body;
    if (options.format == wire::Format::kBinary && request.fits_binary_layout()) {
      auto encoded = wire::encode_request_binary(request);
      if (!encoded) return encoded.error();
      body.bytes = std::move(*encoded);
      body.format = wire::Format::kBinary;
      return body;
    }
    auto ok = capture([&] { body.bytes = wire::encode_request_json(request); });
    if (!ok) return ok.error();
    return body;
  }

  std::string transport_error(httplib::Error e) const { return remote::transport_error(e, url, options); }

  Error server_error(const Reply& r) const { return remote::server_error(r.body, r.status, options); }

  std::string_view preferred_accept() const { return wire::media_type(options.format); }

  Result<DeformationResult> decode_result(const Reply& r) {
    if (r.status != 200) return server_error(r);
    return is_binary(r.content_type) ? wire::decode_result_binary(r.body) : wire::decode_result_json(r.body);
  }

  Result<DeformationResult> deform(const GeomId& id, const DeformationRequest& request) {
    auto body = encode(request);
    if (!body) return body.error();
    // A nonlinear answer is read as JSON, the layout that says how it was solved (model,
    // iterations, residual); the binary one is the positions only.
    const std::string_view accept =
        request.model == DeformationModel::kNonlinear ? wire::kJsonMediaType : preferred_accept();
    auto reply = post(geometry_path(id) + "/results", body->bytes, body->format, accept);
    if (!reply) return reply.error();
    return decode_result(*reply);
  }

  // Holds (remote_holds.cpp).
  Result<HeldResult> put_hold(const GeomId& id, const std::string& hold_id, const DeformationRequest& request,
                              std::chrono::milliseconds ttl);
  Result<HeldResult> held_answer(const GeomId& id, const Reply& reply);

  // --- deform_async calls -------------------------------------------------------------------
  void submit(std::function<void()> task) {
    {
      std::lock_guard lock(task_mu);
      ++in_flight;
    }
    executor->post([this, task = std::move(task)] {
      task();
      std::lock_guard lock(task_mu);
      --in_flight;
      task_cv.notify_all();
    });
  }

  std::string url;
  RemoteSessionOptions options;

  std::mutex pool_mu;
  std::vector<std::unique_ptr<httplib::Client>> idle;

  std::shared_ptr<Executor> executor;  // runs deform_async calls
  std::mutex task_mu;
  std::condition_variable task_cv;
  int in_flight = 0;  // deform_async calls posted and not finished (under task_mu)
};

}  // namespace softshell
