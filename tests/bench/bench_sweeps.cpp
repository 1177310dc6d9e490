// The triangular sweeps and the numeric factorization of a stiffness matrix on one thread and on
// two (engine/src/supernodal_sweeps.h, supernodal_numeric.h): a whole forward and backward sweep
// with one right-hand side, what a preconditioned Krylov iteration of the nonlinear solver and a
// linear solve's backward half cost. Each mesh is held by the lowest 5% of its control points (bench_drag.h).
//
// Usage: bench_sweeps [repeats = 100] [mesh ...]   (default: the shipped meshes with factors of
// 8 MB or more, and catmark_righthanded below it)
// Prints, per mesh: the factor, whether its tree split into two halves, and the median (90th
// percentile) of the sweeps on one thread (the backend's own: CHOLMOD's BLAS or the GPL-free
// one's) and on two, the same for a factor whose sweeps read L rounded to single precision (the
// nonlinear solver's preconditioners, SweepPrecision::kSingle) and how far its solve is from the
// exact one, and of a refactorization into the same analysis on one thread and on two
// (supernodal_numeric.h), the latter also with the single-precision copy made.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "bench_drag.h"
#include "bench_support.h"
#include "cholesky_factor.h"
#include "factorization.h"
#include "softshell/executor.h"
#include "supernodal_sweeps.h"
#include "test_meshes.h"

using namespace softshell;

namespace {

struct Timing {
  double p50 = 0.0, p90 = 0.0;
};

// Between two timed sweeps, the caches are filled with other data (as a Krylov iteration's tangent
// product does between two preconditioner solves): otherwise a factor of tens of MB stays in the
// last-level caches of two cores and two threads look faster than memory lets them be.
std::vector<double>& other_data() {
  static std::vector<double> data(size_t{32} << 20, 1.0);  // 256 MB
  return data;
}

template <class Pass>
Timing time_pass(int repeats, Pass pass) {
  std::vector<double> ms;
  std::vector<double>& other = other_data();
  for (int i = 0; i < repeats; ++i) {
    for (double& v : other) v += 1.0;
    const auto t0 = bench::Clock::now();
    pass();
    ms.push_back(bench::ms_since(t0));
  }
  return {bench::percentile(ms, 0.5), bench::percentile(ms, 0.9)};
}

// Runs a parallel_for's items one after the other on the calling thread while claiming two
// threads: the two-thread plan's sweeps on one thread (ours against the backend's own).
class OneThreadClaimingTwo final : public Executor {
 public:
  void post(std::function<void()> task) override { task(); }
  int concurrency() const override { return 2; }
};

}  // namespace

int main(int argc, char** argv) {
  bench::malloc_as_the_server();
  const int repeats = argc > 1 ? std::atoi(argv[1]) : 100;
  if (repeats < 1) {
    std::fprintf(stderr, "usage: bench_sweeps [repeats >= 1] [mesh ...]\n");
    return 2;
  }
  std::vector<std::string> meshes;
  for (int i = 2; i < argc; ++i) meshes.emplace_back(argv[i]);
  if (meshes.empty()) meshes = {"catmark_righthanded.obj", "spot_quadrangulated.obj", "blub_quadrangulated.obj"};

  std::printf("softshell triangular sweeps on %s (%s)\n", bench::machine().c_str(),
              engine::internal::CholeskyFactor::backend());
  std::printf("a forward and a backward sweep over the whole factor, one right-hand side, %d times, the caches filled\n"
              "with other data before each; median (p90)\n\n",
              repeats);
  std::printf("| mesh | DOFs | factor | split in two | backend's, one thread | ours, one thread | ours, two threads | speed-up | "
              "single, one thread | single, two threads | single's solve off by | "
              "refactorization, one thread | two threads | speed-up | two threads, with single |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  ThreadPool pool(2);
  OneThreadClaimingTwo inline_pool;
  for (const std::string& name : meshes) {
    auto drag = bench::setup_drag(test::load_asset_mesh(name));
    if (!drag.ok()) {
      std::fprintf(stderr, "%s: %s\n", name.c_str(), drag.error().message.c_str());
      return 1;
    }
    const auto& model = drag->model;
    std::vector<int32_t> fixed;
    for (const VertexConstraint& c : drag->request.vertex_constraints) {
      for (int axis = 0; axis < 3; ++axis) {
        if (c.mask & (1u << axis)) fixed.push_back(3 * c.index + axis);
      }
    }
    std::sort(fixed.begin(), fixed.end());
    fixed.erase(std::unique(fixed.begin(), fixed.end()), fixed.end());
    // Planned whatever its size, so that the table shows where two threads start to pay.
    engine::internal::g_two_thread_sweep_entries.store(0);
    const engine::internal::Factorization one(model->stiffness(), fixed, {});
    const engine::internal::Factorization two(model->stiffness(), fixed, {}, nullptr, Eigen::MatrixXd(),
                                              std::shared_ptr<Executor>(&pool, [](Executor*) {}));
    const engine::internal::Factorization ours(model->stiffness(), fixed, {}, nullptr, Eigen::MatrixXd(),
                                               std::shared_ptr<Executor>(&inline_pool, [](Executor*) {}));
    constexpr auto kSingle = engine::internal::SweepPrecision::kSingle;
    const engine::internal::Factorization one_single(model->stiffness(), fixed, {}, nullptr, Eigen::MatrixXd(), nullptr,
                                                     kSingle);
    const engine::internal::Factorization two_single(model->stiffness(), fixed, {}, nullptr, Eigen::MatrixXd(),
                                                     std::shared_ptr<Executor>(&pool, [](Executor*) {}), kSingle);
    Eigen::MatrixXd b = Eigen::MatrixXd::Random(static_cast<Eigen::Index>(one.factored().size()), 1);
    const Eigen::MatrixXd x1 = one.backward(one.forward(b)), x2 = two.backward(two.forward(b));
    const double difference = (x2 - x1).norm() / x1.norm();
    if (!(difference < 1e-12)) {
      std::fprintf(stderr, "%s: two threads answer differently (%.1e)\n", name.c_str(), difference);
      return 1;
    }
    const double single_difference = (one_single.backward(one_single.forward(b)) - x1).norm() / x1.norm();
    Timing t1, t_ours, t2, ts1, ts2;
    for (int round = 0; round < 2; ++round) {  // interleaved
      t1 = time_pass(repeats, [&] { b = one.backward(one.forward(b)); b.normalize(); });
      t_ours = time_pass(repeats, [&] { b = ours.backward(ours.forward(b)); b.normalize(); });
      t2 = time_pass(repeats, [&] { b = two.backward(two.forward(b)); b.normalize(); });
      ts1 = time_pass(repeats, [&] { b = one_single.backward(one_single.forward(b)); b.normalize(); });
      ts2 = time_pass(repeats, [&] { b = two_single.backward(two_single.forward(b)); b.normalize(); });
    }
    // The numeric factorization into the same analysis (as the nonlinear solver refactors its
    // preconditioner), on one thread and on two (supernodal_numeric.h).
    const int refactorizations = std::max(3, repeats / 10);
    Timing f1, f2, f2s;
    for (int round = 0; round < 2; ++round) {
      f1 = time_pass(refactorizations, [&] { engine::internal::Factorization again(model->stiffness(), fixed, {}, &one); });
      f2 = time_pass(refactorizations, [&] {
        engine::internal::Factorization again(model->stiffness(), fixed, {}, &two, Eigen::MatrixXd(),
                                              std::shared_ptr<Executor>(&pool, [](Executor*) {}));
      });
      f2s = time_pass(refactorizations, [&] {
        engine::internal::Factorization again(model->stiffness(), fixed, {}, &two_single, Eigen::MatrixXd(),
                                              std::shared_ptr<Executor>(&pool, [](Executor*) {}), kSingle);
      });
    }
    std::printf("| %s | %d | %.1f MiB | %s | %.2f (%.2f) ms | %.2f (%.2f) ms | %.2f (%.2f) ms | %.2f | %.2f (%.2f) ms | "
                "%.2f (%.2f) ms | %.1e | %.1f (%.1f) ms | %.1f (%.1f) ms | %.2f | %.1f (%.1f) ms |\n",
                name.c_str(), model->num_dofs(), static_cast<double>(one.bytes()) / (1 << 20),
                two.two_thread_sweeps() ? "yes" : "no", t1.p50, t1.p90, t_ours.p50, t_ours.p90, t2.p50, t2.p90,
                t1.p50 / t2.p50, ts1.p50, ts1.p90, ts2.p50, ts2.p90, single_difference, f1.p50, f1.p90, f2.p50, f2.p90,
                f1.p50 / f2.p50, f2s.p50, f2s.p90);
  }
  return 0;
}
