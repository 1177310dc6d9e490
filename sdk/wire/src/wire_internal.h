#pragma once
// Private helpers shared by the wire codecs (binary, JSON, validation). Not installed.

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>

#include "softshell/request_validation.h"
#include "softshell/result.h"

namespace softshell::wire::internal {

static_assert(std::endian::native == std::endian::little || std::endian::native == std::endian::big,
              "mixed-endian hosts are not supported");

/// Appends little-endian u32 / f32 values to a body.
class ByteWriter {
 public:
  explicit ByteWriter(size_t reserve = 0) { out_.reserve(reserve); }
  void u32(uint32_t v) {
    if constexpr (std::endian::native == std::endian::big) v = byteswap(v);
    char b[4];
    std::memcpy(b, &v, 4);
    out_.append(b, 4);
  }
  void f32(float v) { u32(std::bit_cast<uint32_t>(v)); }
  void bytes(const void* data, size_t n) { out_.append(static_cast<const char*>(data), n); }
  std::string take() { return std::move(out_); }
  size_t size() const { return out_.size(); }

  static uint32_t byteswap(uint32_t v) {
    return (v >> 24) | ((v >> 8) & 0xff00u) | ((v << 8) & 0xff0000u) | (v << 24);
  }

 private:
  std::string out_;
};

/// Reads little-endian u32 / f32 values; the caller checks `remaining()` before reading (reads
/// past the end are a bug and throw kInternal rather than read out of bounds).
class ByteReader {
 public:
  explicit ByteReader(std::string_view data) : data_(data) {}
  size_t remaining() const { return data_.size() - pos_; }
  size_t position() const { return pos_; }
  uint32_t u32() {
    if (remaining() < 4) fail(ErrorCode::kInternal, "wire decoder read past the end of the body");
    uint32_t v;
    std::memcpy(&v, data_.data() + pos_, 4);
    pos_ += 4;
    if constexpr (std::endian::native == std::endian::big) v = ByteWriter::byteswap(v);
    return v;
  }
  float f32() { return std::bit_cast<float>(u32()); }

 private:
  std::string_view data_;
  size_t pos_ = 0;
};

/// True if `v` is finite and within the range of f32 (so that converting it is defined and finite).
inline bool fits_f32(double v) {
  return std::isfinite(v) && std::fabs(v) <= static_cast<double>(std::numeric_limits<float>::max());
}

/// True if `v` converts to f32 and back without change.
inline bool exact_f32(double v) { return fits_f32(v) && static_cast<double>(static_cast<float>(v)) == v; }


}  // namespace softshell::wire::internal
