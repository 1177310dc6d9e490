// libFuzzer target: any bytes through the OBJ reader and, when they parse, mesh validation. Both
// must return errors as values, never crash, hang or read out of bounds.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "softshell/mesh_validation.h"
#include "softshell/obj_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  softshell::ObjReadOptions limits;
  limits.max_vertices = 100000;  // keep single inputs cheap; the limits themselves are tested
  limits.max_face_indices = 400000;
  auto mesh = softshell::parse_obj(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz", limits);
  if (mesh.ok()) (void)softshell::find_mesh_issues(*mesh);
  return 0;
}
