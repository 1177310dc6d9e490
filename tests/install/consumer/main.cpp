// Loads a control mesh from the installed assets, precomputes the shell and pulls one point.
#include <cstdio>

#include <softshell/engine/solver.h>
#include <softshell/obj_io.h>

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  auto mesh = softshell::read_obj(argv[1]);
  if (!mesh) {
    std::fprintf(stderr, "%s\n", mesh.error().message.c_str());
    return 1;
  }
  auto model = softshell::engine::ShellModel::build(*mesh, softshell::Material{});
  if (!model) {
    std::fprintf(stderr, "%s\n", model.error().message.c_str());
    return 1;
  }
  softshell::DeformationRequest request;
  for (int32_t v : mesh->face(0)) request.vertex_constraints.push_back({v, softshell::kAxisAll, softshell::Vec3::Zero()});
  request.limit_constraints.push_back({{mesh->num_faces() - 1, 0, 0.5, 0.5}, softshell::Vec3(0, 0, 0.01), {}, {}});
  softshell::engine::Solver solver(*model, std::make_shared<softshell::engine::FactorCache>());
  auto solution = solver.solve(request);
  if (!solution) {
    std::fprintf(stderr, "%s\n", solution.error().message.c_str());
    return 1;
  }
  std::printf("consumer: solved %d DOFs, max displacement %g\n", (*model)->num_dofs(),
              solution->displacement.cwiseAbs().maxCoeff());
  return 0;
}
