#pragma once
/// \file
/// \brief `ShellModel`: the precomputed isogeometric Kirchhoff-Love shell of one geometry
/// (quadrature basis and stiffness matrix K). Immutable once built; shared by every solve.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/executor.h"
#include "softshell/limit_evaluator.h"
#include "softshell/material.h"
#include "softshell/result.h"

namespace softshell::engine {

/// How the shell is integrated (see README "Extraordinary vertices and quadrature" for the accuracy/cost tables).
struct QuadratureOptions {
  /// Gauss points per direction on every (sub-)cell: 4 integrates a bicubic patch's stiffness
  /// integrand well (GeoPDEs uses p + 1). Range 1..10.
  int gauss_points = 4;
  /// Dyadic refinement levels of a face's domain toward an extraordinary vertex (0 = none). The
  /// basis there is polynomial on rings of sub-squares that shrink toward the vertex: every ring
  /// is integrated exactly (for the integrands that are polynomial), the innermost cell, which
  /// holds the infinitely many rings below, by a Gauss rule re-weighted to integrate the
  /// self-similar leading term exactly; its pressure load is integrated exactly in closed form.
  /// What remains shrinks ~3-10x per level: the membrane patch test (exact answer: an affine
  /// field) is met to 2e-8 with 4 levels, 2e-9 with 5, 7e-10 with 6 (the default), on flat meshes
  /// with valence 3, 5, 6 and boundary extraordinary vertices and n-gons. Each level adds 3 cells
  /// per extraordinary corner. Range 0..8.
  int ev_refinement_levels = 6;
  /// Gauss points per direction on the ring cells of 1/8 of the face's side or smaller (depth 3
  /// and deeper). 3 integrate the flat membrane integrand there (degree 5 per direction)
  /// exactly, and the deep rings are a small part of the face, so levels 5 and 6 cost about what
  /// levels 3 and 4 cost with the face's rule. 0 = `gauss_points`. Range 0..10.
  int ev_ring_gauss_points = 3;
  /// Cells whose parametrization is strongly non-uniform are split 2 x 2, up to
  /// `max_distortion_splits` times: those where the area element or the length of a tangent
  /// varies by more than this factor between the cell's Gauss points. Such faces appear where
  /// tight support loops model a sharp edge; one Gauss rule over them is far from exact. (The
  /// innermost cell at an extraordinary vertex, where the parametrization is singular, is never
  /// split: its rule is made for it.) >= 1; 0 turns the splitting off.
  double max_cell_distortion = 4.0;
  /// Range 0..6.
  int max_distortion_splits = 3;
};

/// Options of the precomputation.
struct PrecomputeOptions {
  QuadratureOptions quadrature;
  LimitEvaluator::Options evaluator;
  /// Where the per-face work runs (the host's threads); empty = softshell::default_executor().
  /// The linear solves on the model's factors sweep large ones (8 MB or more) on two of its threads.
  std::shared_ptr<Executor> executor;
  /// At most this many of the executor's threads work on one build; 0 = all of them. The result
  /// is bit-for-bit the same for every thread count. 1 also keeps the solves' sweeps on one thread.
  int threads = 0;
  /// Called with the fraction done in [0, 1], from one of the worker threads. May be empty.
  std::function<void(double)> progress;
  /// If set and becomes true, the build stops with kCancelled.
  const std::atomic<bool>* cancel = nullptr;
};

/// One quadrature point of the limit surface, with its basis (for loads and stresses).
struct QuadraturePoint {
  SurfacePoint point;
  double weight = 0.0;  ///< Gauss weight times the area of its cell in the (sub-)face domain
};

/// The precomputed shell of one geometry: limit evaluator, quadrature points and the sparse
/// symmetric stiffness matrix K (3n x 3n, DOF 3i + a is axis a of control point i).
///
/// Thread-safety: immutable after `build`; every const member may be called concurrently.
class ShellModel {
 public:
  /// Validates mesh and material, evaluates the basis at every quadrature point and assembles K.
  /// Crease and corner tags are not used: the shell is the smooth limit surface of the control
  /// mesh (a kink would act as a hinge in a Kirchhoff-Love shell).
  static Result<std::shared_ptr<const ShellModel>> build(const ControlMesh& mesh, const Material& material,
                                                         const PrecomputeOptions& options = {});

  /// A process-unique id (factor cache key).
  uint64_t id() const { return id_; }
  const ControlMesh& mesh() const { return evaluator_.mesh(); }
  const Material& material() const { return material_; }
  const LimitEvaluator& evaluator() const { return evaluator_; }
  const PrecomputeOptions& options() const { return options_; }
  int32_t num_control_points() const { return mesh().num_vertices(); }
  int32_t num_dofs() const { return 3 * num_control_points(); }

  /// K, full symmetric (both triangles stored), column-major (CSC).
  const Eigen::SparseMatrix<double>& stiffness() const { return stiffness_; }

  /// The quadrature points of every face (for loads and stresses).
  const std::vector<QuadraturePoint>& quadrature() const { return quadrature_; }

  /// Rigid-body modes (3n x 6c for c connected components): per component, unit translations
  /// along x, y, z and infinitesimal rotations about x, y, z through the component's centroid
  /// (scaled by 1 / its size). K times any of them is zero up to round-off.
  const Eigen::MatrixXd& rigid_modes() const { return rigid_modes_; }
  /// Every zero-energy mode: the rigid modes (first 6c columns) followed by the extra modes of
  /// the control mesh: displacements that leave a part's limit surface where it is (for example
  /// the checkerboard pattern of a cube whose vertices all have valence 3, which Catmull-Clark
  /// maps to zero). Found for every part on the Gram matrix of the basis at the quadrature
  /// points, so they depend neither on the thickness nor on the material (a thin shell's bending
  /// modes are never taken for zero modes). Extra modes are orthonormal within each component and
  /// orthogonal to its rigid modes; K times each mode is zero up to round-off. `build` refuses a
  /// part whose limit surface falls apart into pieces (possible with ghost faces), whose pieces
  /// could move against each other without strain.
  const Eigen::MatrixXd& zero_energy_modes() const { return zero_modes_; }
  int32_t num_rigid_modes() const { return static_cast<int32_t>(rigid_modes_.cols()); }
  /// For each extra mode (column num_rigid_modes() + k): true if it leaves the limit surface where
  /// it is (the solver then fixes its amplitude to zero when nothing else does). True for every
  /// extra mode, by construction.
  const std::vector<bool>& invisible_modes() const { return invisible_; }
  /// The connected component each zero-energy mode (column of zero_energy_modes()) lives on.
  const std::vector<int32_t>& zero_energy_mode_component() const { return mode_component_; }

  /// Connected component of each control point (0..c-1) and the number of components.
  const std::vector<int32_t>& component_of() const { return component_of_; }
  int32_t num_components() const { return static_cast<int32_t>(rigid_modes_.cols() / 6); }

  /// Total area of the limit surface (sum over quadrature points).
  double area() const { return area_; }

  /// Strain energy 1/2 u^T K u of a displacement vector (3n).
  double strain_energy(const Eigen::VectorXd& displacement) const;

  /// The load vector (3n) of a request's forces, surface forces, surface load and pressure.
  /// Precondition: the loads pass `validate_request` (asserted: SOFTSHELL_ASSERT).
  Eigen::VectorXd load_vector(const DeformationRequest& request) const;

  /// Bytes held (matrix, quadrature, modes, evaluator estimate).
  size_t memory_bytes() const;
  /// What `memory_bytes()` of the model of `mesh` will be, before building it (for a memory
  /// budget): K's sparsity counted from the topology (control points that share a face's
  /// one-ring support), quadrature points from `options.quadrature`: 1.0-1.5x the built model's
  /// on the shipped meshes of 100+ control points (tests/service: ModelEstimateTest), except
  /// where cells are split for distortion, which the topology does not show (catmark_car: 0.6x).
  /// Time linear in the mesh size.
  static size_t estimate_memory_bytes(const ControlMesh& mesh, const PrecomputeOptions& options = {});

  /// Seconds the build took.
  double build_seconds() const { return build_seconds_; }

 private:
  ShellModel(LimitEvaluator evaluator, Material material, PrecomputeOptions options);
  friend class ShellModelBuilder;

  uint64_t id_;
  LimitEvaluator evaluator_;
  Material material_;
  PrecomputeOptions options_;
  Eigen::SparseMatrix<double> stiffness_;
  std::vector<QuadraturePoint> quadrature_;
  Eigen::MatrixXd rigid_modes_;
  Eigen::MatrixXd zero_modes_;
  std::vector<bool> invisible_;
  std::vector<int32_t> mode_component_;
  std::vector<int32_t> component_of_;
  Eigen::VectorXd area_weights_;    // n: integral of N_A dA (consistent surface loads)
  Eigen::VectorXd normal_weights_;  // 3n: integral of N_A n dA (pressure)
  double area_ = 0.0;
  double build_seconds_ = 0.0;
};

}  // namespace softshell::engine
