// C ABI: levels of detail (a control mesh refined k times, and requests carried to it).

#include <string>
#include <vector>

#include "c_api_internal.h"
#include "softshell/softshell_c_bridge.h"

using namespace softshell;         // NOLINT(google-build-using-namespace): a .cpp of entry points
using namespace softshell::c_api;  // NOLINT(google-build-using-namespace)

extern "C" {

ss_status ss_refinement_create(const ss_mesh* coarse, int32_t levels, ss_refinement** out_refinement) {
  return guard("ss_refinement_create", [&] {
    required(out_refinement, "out_refinement");
    *out_refinement = nullptr;
    const auto m = live(coarse, "coarse");
    *out_refinement =
        make_handle<ss_refinement>(std::make_shared<MeshRefinement>(MeshRefinement::create(*m, levels).value()));
  });
}

void ss_refinement_destroy(ss_refinement* refinement) { destroy(refinement, "ss_refinement_destroy"); }

ss_status ss_refinement_fine_mesh(const ss_refinement* refinement, ss_mesh** out_mesh) {
  return guard("ss_refinement_fine_mesh", [&] {
    required(out_mesh, "out_mesh");
    *out_mesh = nullptr;
    const auto r = live(refinement, "refinement");
    *out_mesh = make_handle<ss_mesh>(std::make_shared<ControlMesh>(r->fine()));
  });
}

ss_status ss_refinement_fine_point(const ss_refinement* refinement, const ss_surface_point* coarse_point,
                                   ss_surface_point* out_fine_point) {
  return guard("ss_refinement_fine_point", [&] {
    const auto r = live(refinement, "refinement");
    required(out_fine_point, "out_fine_point");
    *out_fine_point = to_c(r->fine_point(point(coarse_point, "coarse_point")).value());
  });
}

ss_status ss_refinement_refine_positions(const ss_refinement* refinement, const double* coarse_xyz, int32_t count,
                                         double* out_fine_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_refinement_refine_positions", [&] {
    const auto r = live(refinement, "refinement");
    const std::vector<Vec3> fine = r->refine_positions(read_xyz(coarse_xyz, count, "coarse_xyz")).value();
    write_xyz(fine, out_fine_xyz, capacity, out_count, "fine positions");
  });
}

ss_status ss_refinement_request_to_fine(const ss_refinement* refinement, const ss_request* coarse_request,
                                        int32_t force_transfer, ss_request** out_fine_request) {
  return guard("ss_refinement_request_to_fine", [&] {
    required(out_fine_request, "out_fine_request");
    *out_fine_request = nullptr;
    const auto r = live(refinement, "refinement");
    const auto req = live(coarse_request, "coarse_request");
    if (force_transfer != SS_FORCE_TRANSFER_SUBDIVIDE && force_transfer != SS_FORCE_TRANSFER_VIRTUAL_WORK) {
      fail(ErrorCode::kInvalidArgument, "force_transfer must be SS_FORCE_TRANSFER_SUBDIVIDE or _VIRTUAL_WORK");
    }
    const auto transfer =
        force_transfer == SS_FORCE_TRANSFER_VIRTUAL_WORK ? ForceTransfer::kVirtualWork : ForceTransfer::kSubdivide;
    *out_fine_request =
        make_handle<ss_request>(std::make_shared<DeformationRequest>(r->request_to_fine(*req, transfer).value()));
  });
}

}  // extern "C"
