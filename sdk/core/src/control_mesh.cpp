#include "softshell/control_mesh.h"

#include <limits>
#include <string>

namespace softshell {

ControlMesh::ControlMesh(std::vector<Vec3> positions, const std::vector<std::vector<int32_t>>& faces)
    : positions_(std::move(positions)) {
  face_offsets_.reserve(faces.size() + 1);
  for (const auto& f : faces) {
    face_indices_.insert(face_indices_.end(), f.begin(), f.end());
    if (face_indices_.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max())) {
      fail(ErrorCode::kInvalidArgument, "too many face indices (more than 2^31)");
    }
    face_offsets_.push_back(static_cast<int32_t>(face_indices_.size()));
  }
}

ControlMesh::ControlMesh(std::vector<Vec3> positions, const std::vector<int32_t>& face_sizes,
                         std::vector<int32_t> face_indices)
    : positions_(std::move(positions)), face_indices_(std::move(face_indices)) {
  face_offsets_.reserve(face_sizes.size() + 1);
  int64_t offset = 0;
  for (size_t f = 0; f < face_sizes.size(); ++f) {
    if (face_sizes[f] < 0) {
      fail(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + " has a negative size");
    }
    offset += face_sizes[f];
    if (offset > static_cast<int64_t>(face_indices_.size())) {
      fail(ErrorCode::kInvalidArgument, "the face sizes add up to more than the " +
                                            std::to_string(face_indices_.size()) + " face indices given");
    }
    face_offsets_.push_back(static_cast<int32_t>(offset));
  }
  if (offset != static_cast<int64_t>(face_indices_.size())) {
    fail(ErrorCode::kInvalidArgument, "the face sizes add up to " + std::to_string(offset) + " but " +
                                          std::to_string(face_indices_.size()) + " face indices were given");
  }
}

std::vector<int32_t> ControlMesh::face_sizes() const {
  std::vector<int32_t> sizes(static_cast<size_t>(num_faces()));
  for (int32_t f = 0; f < num_faces(); ++f) sizes[static_cast<size_t>(f)] = face_size(f);
  return sizes;
}

bool ControlMesh::all_quads() const {
  for (int32_t f = 0; f < num_faces(); ++f) {
    if (face_size(f) != 4) return false;
  }
  return true;
}

void ControlMesh::bounding_box(Vec3& out_min, Vec3& out_max) const {
  if (positions_.empty()) {
    out_min = out_max = Vec3::Zero();
    return;
  }
  out_min = out_max = positions_.front();
  for (const Vec3& p : positions_) {
    out_min = out_min.cwiseMin(p);
    out_max = out_max.cwiseMax(p);
  }
}

double ControlMesh::bounding_diagonal() const {
  Vec3 lo, hi;
  bounding_box(lo, hi);
  return (hi - lo).norm();
}

bool ControlMesh::operator==(const ControlMesh& other) const {
  auto same_creases = [](const std::vector<Crease>& a, const std::vector<Crease>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i) {
      if (a[i].v0 != b[i].v0 || a[i].v1 != b[i].v1 || a[i].sharpness != b[i].sharpness) return false;
    }
    return true;
  };
  auto same_corners = [](const std::vector<Corner>& a, const std::vector<Corner>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i) {
      if (a[i].vertex != b[i].vertex || a[i].sharpness != b[i].sharpness) return false;
    }
    return true;
  };
  return positions_ == other.positions_ && face_offsets_ == other.face_offsets_ &&
         face_indices_ == other.face_indices_ && boundary_ == other.boundary_ &&
         same_creases(creases_, other.creases_) && same_corners(corners_, other.corners_);
}

}  // namespace softshell
