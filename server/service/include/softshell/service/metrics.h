#pragma once
/// \file
/// \brief Lock-free counters and latency histograms, and their Prometheus text form.

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace softshell::service {

/// A latency histogram with fixed bucket bounds (seconds, 50 µs .. 60 s, roughly x2.5 apart).
/// Thread-safety: `observe` and `snapshot` may be called concurrently (relaxed atomics; a
/// snapshot taken during updates may be off by the updates in flight).
class Histogram {
 public:
  /// Upper bounds of the buckets in seconds (the last bucket, +Inf, is implicit).
  static constexpr std::array<double, 16> kBounds = {5e-5, 1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2,
                                                     2.5e-2, 5e-2, 0.1, 0.25, 0.5, 1.0, 5.0, 60.0};

  struct Snapshot {
    std::array<uint64_t, kBounds.size() + 1> buckets{};  ///< per bucket (not cumulative); last = +Inf
    uint64_t count = 0;
    double sum = 0.0;  ///< seconds
  };

  void observe(double seconds);
  Snapshot snapshot() const;

 private:
  std::array<std::atomic<uint64_t>, kBounds.size() + 1> buckets_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<uint64_t> sum_ns_{0};
};

/// Builds Prometheus text exposition format (version 0.0.4).
class PrometheusText {
 public:
  /// `# HELP` and `# TYPE` lines of a metric family (type: counter, gauge, histogram).
  void family(std::string_view name, std::string_view type, std::string_view help);
  /// One sample: `name{labels} value`. `labels` is the inside of the braces, already formatted
  /// (use `label`), or empty.
  void sample(std::string_view name, std::string_view labels, double value);
  /// The `_bucket`, `_sum` and `_count` samples of a histogram.
  void histogram(std::string_view name, std::string_view labels, const Histogram::Snapshot& h);
  /// `key="value"` with the value escaped.
  static std::string label(std::string_view key, std::string_view value);
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

}  // namespace softshell::service
