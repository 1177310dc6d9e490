#pragma once
/// \file
/// \brief Wire codecs: the binary and JSON bodies of PROTOCOL.md, shared by every client and the
/// server so that both sides read and write the same bytes.
///
/// Encoders turn values into bodies; decoders turn bodies from outside (hostile until proven
/// otherwise) into values. Every decoder:
///  - checks each count against the actual body length *before* allocating anything for it, so a
///    header that claims gigabytes costs nothing;
///  - rejects truncated bodies, trailing bytes, NaN/Inf, bad masks, indices it can check, and JSON
///    that is nested deeper than `kMaxJsonDepth` or has unknown fields;
///  - returns `kInvalidArgument` with a message that names the field and what was expected.
/// Decoders never throw.
///
/// Binary numbers are little-endian; `f32` values widen exactly to `double` when decoded and are
/// rounded to nearest when encoded. JSON numbers are doubles and are written so that they read
/// back bit for bit (shortest round-trip form).
///
/// Thread-safety: every function is reentrant.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/hold.h"
#include "softshell/limit_evaluator.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/session.h"

namespace softshell::wire {

/// A body format.
enum class Format : uint8_t {
  kBinary,  ///< `application/octet-stream`, the paper's layouts
  kJson,    ///< `application/json`
};

inline constexpr std::string_view kBinaryMediaType = "application/octet-stream";
inline constexpr std::string_view kJsonMediaType = "application/json";

/// The media type of a format.
std::string_view media_type(Format format);

/// Largest face (number of corners) a decoder accepts (the same bound as the OBJ reader).
inline constexpr int32_t kMaxFaceSize = 1024;
/// Deepest JSON nesting a decoder accepts (the deepest valid body nests 5 levels).
inline constexpr int kMaxJsonDepth = 16;

// ---------------------------------------------------------------------------------------------
// Errors and HTTP statuses

/// The HTTP status of an error code (PROTOCOL.md): kInvalidArgument 400, kNotFound 404, ...
int http_status(ErrorCode code);
/// The error code of an HTTP status (the inverse of `http_status`; 5xx other than 507 give
/// kUnavailable or kInternal).
ErrorCode error_code_for_status(int status);

/// `{"error": "<short code>", "message": "..."}`.
std::string encode_error_json(const Error& error);
/// The same with any short code (for HTTP-level errors without an `ErrorCode`, such as
/// "method_not_allowed").
std::string encode_error_json(std::string_view code, std::string_view message);
/// The error in an error response. Falls back to the status's code and the raw body (shortened)
/// when the body is not the JSON error layout.
Error decode_error_json(std::string_view body, int http_status);

// ---------------------------------------------------------------------------------------------
// Geometry uploads (`POST /geometries`, `GET /geometries/{id}`)

/// True if the binary upload layout can carry the mesh: every face a quad, no crease or corner
/// tags and the default boundary mode. (Numbers are then rounded to f32; see
/// `geometry_is_float32_exact`.)
bool geometry_fits_binary(const ControlMesh& mesh);
/// True if every coordinate and the material's E, nu, t are exactly representable as f32, so the
/// binary layout carries the values without rounding.
bool geometry_is_float32_exact(const ControlMesh& mesh, const Material& material);

/// Binary upload body. kInvalidArgument if the mesh does not fit the layout (see
/// `geometry_fits_binary`) or a number is not finite or overflows f32.
Result<std::string> encode_geometry_binary(const ControlMesh& mesh, const Material& material);

/// JSON upload body: `vertices`, `faces`, `material`, `boundary`, and the extension fields
/// `creases` (`[{"vertices": [a, b], "sharpness": s}]`) and `corners`
/// (`[{"vertex": v, "sharpness": s}]`) when the mesh has tags.
std::string encode_geometry_json(const ControlMesh& mesh, const Material& material);
/// The same plus `"geom_id"` and `"namespace"` (the response of `GET /geometries/{id}`).
std::string encode_geometry_json(const ControlMesh& mesh, const Material& material, const GeomId& id,
                                 std::string_view name_space);

/// Decodes a binary upload body. Checks the length exactly, finiteness and face indices.
/// `name_space` of the result is empty.
Result<Geometry> decode_geometry_binary(std::string_view body);
/// Decodes a JSON upload body (or a `GET /geometries/{id}` response: `geom_id` is ignored and
/// `namespace`, if present, fills `name_space`). Checks finiteness, face sizes, indices and
/// crease/corner tags; the mesh is not validated for simulation (see mesh_validation.h).
Result<Geometry> decode_geometry_json(std::string_view body);

/// Upload response bodies: 16 raw id bytes, or `{"geom_id": "<hex>", "status": "..."}`.
std::string encode_upload_response_binary(const GeomId& id);
std::string encode_upload_response_json(const GeomId& id, GeometryStatus status);
// ---------------------------------------------------------------------------------------------
// Stresses (`GET|POST /geometries/{id}/results/{res_id}/stresses`, an extension)

/// `{"level": L}` or `{"points": [{"face", "subface", "u", "v"}, ...]}`, optionally with
/// `"yield_strength"` (Pa).
std::string encode_stress_query_json(const StressQuery& query);
Result<StressQuery> decode_stress_query_json(std::string_view body);
/// `{"res_id", "yield_strength", "exceeds_yield", "max": {sample}, "von_mises": [...],
/// "von_mises_top": [...], "von_mises_bottom": [...], "membrane_force": [[n11, n22, n12], ...],
/// "bending_moment": [[m11, m22, m12], ...]}`, per point in query order, plus `"points":
/// [[face, subface, u, v], ...]` when `with_points` (explicit queries echo their points; a level
/// query's points are the tessellation's vertices, which the client has).
std::string encode_stress_field_json(const StressField& field, bool with_points);
Result<StressField> decode_stress_field_json(std::string_view body);

/// Decodes an upload response; `created` is set from the HTTP status (201). The binary layout
/// carries no status: it is reported as kPrecomputing.
Result<UploadResult> decode_upload_response_binary(std::string_view body, bool created);
Result<UploadResult> decode_upload_response_json(std::string_view body, bool created);

// ---------------------------------------------------------------------------------------------
// Deformation requests (`POST /geometries/{id}/results`)

/// Binary request body (three u32 counts first, see PROTOCOL.md). kInvalidArgument if the request
/// uses JSON-only fields (`!fits_binary_layout()`) or a number is not finite or overflows f32.
Result<std::string> encode_request_binary(const DeformationRequest& request);
/// JSON request body with every field the request uses (extensions only when set).
std::string encode_request_json(const DeformationRequest& request);

/// Decodes a binary request. Counts are checked against the body length before allocating.
Result<DeformationRequest> decode_request_binary(std::string_view body);
/// Decodes a JSON request: `vertex_constraints` (`index`, `mask` default 7, `displacement`
/// default zero), `lagrange_constraints` (`indices`, `coefficients`, `values`), `forces`
/// (`index`, `force`) and the extensions `limit_constraints` (`face`, `subface` default 0, `u`,
/// `v`, `displacement`, optional `du_displacement`, `dv_displacement`), `surface_forces`
/// (`face`, `subface`, `u`, `v`, `force`), `surface_load`, `pressure` and `model` ("linear",
/// "nonlinear"). Every field optional.
Result<DeformationRequest> decode_request_json(std::string_view body);

// ---------------------------------------------------------------------------------------------
// Results (`POST .../results`, `GET .../results/{res_id}`, `GET .../latest_result`)

/// `u32 res_id` then n x (f32 x, y, z). kInvalidArgument if a position is not finite or
/// overflows f32.
Result<std::string> encode_result_binary(const DeformationResult& result);
/// `{"res_id": k, "positions": [[x, y, z], ...]}`.
std::string encode_result_json(const DeformationResult& result);
/// Decodes a result; the body length must be 4 + 12 n. If `expected_vertices` is given, n must
/// equal it.
Result<DeformationResult> decode_result_binary(std::string_view body,
                                               std::optional<int32_t> expected_vertices = std::nullopt);
Result<DeformationResult> decode_result_json(std::string_view body,
                                             std::optional<int32_t> expected_vertices = std::nullopt);

/// The JSON result of a hold state: `{"res_id": k, "positions": [...], "holds": {"<hold_id>": v, ...}}`
/// (PROTOCOL.md version 2; `holds` in the order given).
std::string encode_result_json(const DeformationResult& result, const HoldVersions& holds);
/// Decodes a JSON result with its optional `holds` map (absent for results of `POST .../results`).
Result<HeldResult> decode_held_result_json(std::string_view body,
                                           std::optional<int32_t> expected_vertices = std::nullopt);

/// `{"res_ids": [1, 2, ...]}`.
std::string encode_result_ids_json(const std::vector<uint32_t>& ids);
Result<std::vector<uint32_t>> decode_result_ids_json(std::string_view body);

// ---------------------------------------------------------------------------------------------
// Limit combinations (`GET .../limit_comb`)

/// `u32 p`, p x u32 indices, p x f32 position, du, dv weights.
Result<std::string> encode_limit_comb_binary(const LimitComb& comb);
/// `{"face", "subface", "u", "v", "indices", "position", "du", "dv"}`.
std::string encode_limit_comb_json(const LimitComb& comb);
/// The binary layout does not repeat the point; it is taken from `point`.
Result<LimitComb> decode_limit_comb_binary(std::string_view body, const SurfacePoint& point);
Result<LimitComb> decode_limit_comb_json(std::string_view body);

// ---------------------------------------------------------------------------------------------
// Geometry lists (`GET /geometries`, `GET /geometries/{id}/status`)

/// One entry: `{"geom_id", "namespace", "vertices", "faces", "status", "results"}` plus the
/// extensions `"progress"` (0..1) and, for a failed geometry, `"error"`.
std::string encode_geometry_info_json(const GeometryInfo& info);
Result<GeometryInfo> decode_geometry_info_json(std::string_view body);
/// A JSON array of entries.
std::string encode_geometry_list_json(const std::vector<GeometryInfo>& list);
Result<std::vector<GeometryInfo>> decode_geometry_list_json(std::string_view body);

// ---------------------------------------------------------------------------------------------
// Holds (`PUT/DELETE/GET /geometries/{id}/holds/{hold_id}`, `GET /geometries/{id}/holds`)

/// Checks a hold id: 1 to 64 characters of `[A-Za-z0-9._-]`; kInvalidArgument otherwise.
Result<void> check_hold_id(std::string_view hold_id);

/// "solved", "solving", "unsolvable".
std::string_view to_string(HoldStateStatus state);
Result<HoldStateStatus> parse_hold_state(std::string_view name);

/// The answer of a PUT that does not wait for its result (202): `{"hold_id": "...", "version": v}`.
std::string encode_hold_accepted_json(std::string_view hold_id, uint64_t version);
Result<HoldInfo> decode_hold_accepted_json(std::string_view body);

/// `{"holds": [{"hold_id", "version", "expires_in"}, ...], "res_id", "state", "message"}`.
std::string encode_hold_list_json(const HoldList& list);
Result<HoldList> decode_hold_list_json(std::string_view body);

/// `{"hold_id", "version", "expires_in", "request": <JSON request layout>}`.
std::string encode_hold_json(const HoldDetail& hold);
Result<HoldDetail> decode_hold_json(std::string_view body);

/// Parses a status name ("precomputing", "ready", "failed").
Result<GeometryStatus> parse_geometry_status(std::string_view name);

/// Parses a model name ("linear", "nonlinear"): the request's JSON field `model` and the query
/// parameter `model=` of `POST .../results` and `PUT .../holds`.
Result<DeformationModel> parse_deformation_model(std::string_view name);

}  // namespace softshell::wire
