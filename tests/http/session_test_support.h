#pragma once
// The sessions of the holds and events tests: an EmbeddedSession on a TestServer's service, or a
// RemoteSession to its port, in either body format.
#include <memory>
#include <string_view>

#include "http_test_support.h"
#include "softshell/embedded_session.h"
#include "softshell/remote_session.h"

namespace softshell::test {

enum class SessionKind { kEmbedded, kRemoteBinary, kRemoteJson };

inline std::string_view name_of(SessionKind k) {
  switch (k) {
    case SessionKind::kEmbedded: return "Embedded";
    case SessionKind::kRemoteBinary: return "RemoteBinary";
    case SessionKind::kRemoteJson: return "RemoteJson";
  }
  return "?";
}

inline RemoteSessionOptions remote_options(SessionKind k) {
  RemoteSessionOptions o;
  o.format = k == SessionKind::kRemoteBinary ? wire::Format::kBinary : wire::Format::kJson;
  o.request_timeout = std::chrono::seconds(60);
  o.events_retry_min = std::chrono::milliseconds(20);
  o.events_retry_max = std::chrono::milliseconds(200);
  return o;
}

inline std::unique_ptr<Session> make_session(SessionKind k, TestServer& server) {
  if (k == SessionKind::kEmbedded) return std::make_unique<EmbeddedSession>(server.service_ptr());
  return std::make_unique<RemoteSession>(server.url(), remote_options(k));
}

inline GeomId upload_ready(Session& s, TestServer& server, const ControlMesh& mesh = exact_grid()) {
  auto up = s.upload(mesh, exact_material());
  EXPECT_TRUE(up) << up.error().message;
  if (!up) return {};
  (void)server.service().wait_until_precomputed(up->id, std::chrono::seconds(60));
  return up->id;
}

inline DeformationRequest pins(int n = 4) {
  DeformationRequest r;
  r.vertex_constraints = pinned_corners(n);
  return r;
}

inline DeformationRequest push(double fz, int n = 4) {
  DeformationRequest r;
  r.forces.push_back({grid_index(n, n / 2, n / 2), Vec3(0.0, 0.0, fz)});
  return r;
}

inline uint64_t version_in(const HeldResult& r, const std::string& hold) {
  return r.holds ? version_of(*r.holds, hold) : 0;
}

}  // namespace softshell::test
