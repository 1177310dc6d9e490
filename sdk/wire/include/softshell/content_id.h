#pragma once
/// \file
/// \brief Content-derived geometry ids: the same mesh, material and namespace give the same
/// `GeomId` on every server, in every process, whichever wire format carried them.
///
/// The id is the first 16 bytes of SHA-256 over `canonical_geometry_encoding()`. The canonical
/// encoding is made of the values the server simulates, i.e. after decoding:
///
///  - every number as its IEEE-754 binary64 value, little-endian; a binary upload's f32 values
///    are widened to double exactly, so a JSON upload of the same numbers (written with enough
///    digits to identify them, e.g. the shortest round-trip form of the widened f32) gives the
///    same id; -0.0 is written as +0.0;
///  - integers as little-endian u64 (counts) or u32 (indices);
///  - in this order: the tag `"softshell.geometry.v1"` and a zero byte; the namespace's length
///    and UTF-8 bytes; the boundary mode (u32: 0 edge_and_corner, 1 none); E, nu, t; the number of
///    control points and their x, y, z; the number of faces, every face's size, then all face
///    indices; the number of creases and each (v0, v1, sharpness); the number of corners and each
///    (vertex, sharpness). Tags are taken in the order given; sharpness values are widened from f32.
///
/// Material density is not part of the wire format and not part of the id.
///
/// Thread-safety: reentrant.

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "softshell/control_mesh.h"
#include "softshell/material.h"
#include "softshell/session.h"

namespace softshell {

/// The bytes that are hashed (see the file comment).
std::string canonical_geometry_encoding(const ControlMesh& mesh, const Material& material,
                                        std::string_view name_space);

/// The geometry's id: SHA-256 of the canonical encoding, truncated to 16 bytes.
GeomId geometry_id(const ControlMesh& mesh, const Material& material, std::string_view name_space);

/// SHA-256 of arbitrary bytes (32 bytes).
std::array<uint8_t, 32> sha256(std::string_view data);

}  // namespace softshell
