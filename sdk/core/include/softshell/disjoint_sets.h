#pragma once
/// \file
/// \brief `DisjointSets`: union-find over 0..n-1, for the connected parts of a mesh (by shared
/// control points, edges or any other relation).

#include <cstdint>
#include <numeric>
#include <utility>
#include <vector>

namespace softshell {

/// Disjoint sets of the integers 0..n-1. A set's representative is its smallest member, so
/// labels and messages do not depend on the order of the unions.
class DisjointSets {
 public:
  explicit DisjointSets(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), int32_t{0}); }

  size_t size() const { return parent_.size(); }

  /// The smallest member of x's set.
  int32_t find(int32_t x) {
    while (parent_[static_cast<size_t>(x)] != x) {  // path halving
      parent_[static_cast<size_t>(x)] = parent_[static_cast<size_t>(parent_[static_cast<size_t>(x)])];
      x = parent_[static_cast<size_t>(x)];
    }
    return x;
  }

  /// Joins the sets of a and b.
  void unite(int32_t a, int32_t b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (b < a) std::swap(a, b);
    parent_[static_cast<size_t>(b)] = a;
  }

  /// Every element's set as a label 0..count-1, numbered in order of the sets' smallest members.
  std::vector<int32_t> labels(int32_t& count) {
    std::vector<int32_t> label(parent_.size(), -1), out(parent_.size());
    count = 0;
    for (size_t x = 0; x < parent_.size(); ++x) {
      int32_t& l = label[static_cast<size_t>(find(static_cast<int32_t>(x)))];
      if (l < 0) l = count++;
      out[x] = l;
    }
    return out;
  }

 private:
  std::vector<int32_t> parent_;
};

}  // namespace softshell
