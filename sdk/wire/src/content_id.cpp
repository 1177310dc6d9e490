#include "softshell/content_id.h"

#include <bit>
#include <cstring>
#include <memory>

#include <openssl/evp.h>

namespace softshell {
namespace {

// Writes the canonical encoding into `Sink` (anything with `append(const char*, size_t)`).
template <class Sink>
class Canonical {
 public:
  explicit Canonical(Sink& sink) : out_(sink) {}
  void u32(uint32_t v) { put(&v, 4); }
  void u64(uint64_t v) { put(&v, 8); }
  void f64(double v) {
    if (v == 0.0) v = 0.0;  // -0.0 and +0.0 simulate the same
    u64(std::bit_cast<uint64_t>(v));
  }
  void bytes(std::string_view s) { out_.append(s.data(), s.size()); }

 private:
  // Little-endian whatever the host.
  void put(const void* p, size_t n) {
    unsigned char b[8];
    std::memcpy(b, p, n);
    if constexpr (std::endian::native == std::endian::big) {
      for (size_t i = 0; i < n / 2; ++i) std::swap(b[i], b[n - 1 - i]);
    }
    out_.append(reinterpret_cast<const char*>(b), n);
  }
  Sink& out_;
};

struct StringSink {
  std::string data;
  void append(const char* p, size_t n) { data.append(p, n); }
};

// Feeds SHA-256 in 64 KiB blocks, so hashing a large mesh needs no copy of it.
class DigestSink {
 public:
  DigestSink() : ctx_(EVP_MD_CTX_new(), &EVP_MD_CTX_free) {
    if (!ctx_ || EVP_DigestInit_ex(ctx_.get(), EVP_sha256(), nullptr) != 1) fail_openssl();
    buffer_.reserve(kBlock);
  }
  void append(const char* p, size_t n) {
    buffer_.append(p, n);
    if (buffer_.size() >= kBlock) flush();
  }
  std::array<uint8_t, 32> finish() {
    flush();
    std::array<uint8_t, 32> digest{};
    unsigned int len = 0;
    if (EVP_DigestFinal_ex(ctx_.get(), digest.data(), &len) != 1 || len != digest.size()) fail_openssl();
    return digest;
  }

 private:
  static constexpr size_t kBlock = 64 * 1024;
  [[noreturn]] static void fail_openssl() { fail(ErrorCode::kInternal, "OpenSSL could not compute a SHA-256 digest"); }
  void flush() {
    if (!buffer_.empty() && EVP_DigestUpdate(ctx_.get(), buffer_.data(), buffer_.size()) != 1) fail_openssl();
    buffer_.clear();
  }
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx_;
  std::string buffer_;
};

template <class Sink>
void write_canonical(const ControlMesh& mesh, const Material& material, std::string_view name_space, Sink& sink) {
  Canonical<Sink> c(sink);
  c.bytes(std::string_view("softshell.geometry.v1\0", 22));
  c.u64(name_space.size());
  c.bytes(name_space);
  c.u32(mesh.boundary() == BoundaryMode::kNone ? 1u : 0u);
  c.f64(material.youngs_modulus);
  c.f64(material.poisson_ratio);
  c.f64(material.thickness);
  c.u64(mesh.positions().size());
  for (const Vec3& p : mesh.positions()) {
    c.f64(p.x());
    c.f64(p.y());
    c.f64(p.z());
  }
  c.u64(static_cast<uint64_t>(mesh.num_faces()));
  for (int32_t f = 0; f < mesh.num_faces(); ++f) c.u32(static_cast<uint32_t>(mesh.face_size(f)));
  for (int32_t i : mesh.face_indices()) c.u32(static_cast<uint32_t>(i));
  c.u64(mesh.creases().size());
  for (const Crease& k : mesh.creases()) {
    c.u32(static_cast<uint32_t>(k.v0));
    c.u32(static_cast<uint32_t>(k.v1));
    c.f64(static_cast<double>(k.sharpness));
  }
  c.u64(mesh.corners().size());
  for (const Corner& k : mesh.corners()) {
    c.u32(static_cast<uint32_t>(k.vertex));
    c.f64(static_cast<double>(k.sharpness));
  }
}

}  // namespace

std::string canonical_geometry_encoding(const ControlMesh& mesh, const Material& material,
                                        std::string_view name_space) {
  StringSink sink;
  write_canonical(mesh, material, name_space, sink);
  return std::move(sink.data);
}

std::array<uint8_t, 32> sha256(std::string_view data) {
  DigestSink sink;
  sink.append(data.data(), data.size());
  return sink.finish();
}

GeomId geometry_id(const ControlMesh& mesh, const Material& material, std::string_view name_space) {
  DigestSink sink;
  write_canonical(mesh, material, name_space, sink);
  const auto digest = sink.finish();
  GeomId id;
  std::memcpy(id.bytes.data(), digest.data(), id.bytes.size());
  return id;
}

}  // namespace softshell
