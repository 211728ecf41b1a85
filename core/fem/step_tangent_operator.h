// The forward Newton step's matrix applied element by element, never assembled:
//   A = c_k sum_e R_e K_e R_e^T + c_m M + sum_p (w_p w_p^T) (x) J_p,
// R_e the element rotations, K_e the rest stiffness matrices, M the lumped mass, and per surface
// point p in contact the 3x3 force Jacobian J_p spread over its element's corners by the weights
// w_p; clamped nodes are eliminated (identity rows and columns). It is the matrix
// Simulator::Assemble writes for Newton's dynamic tangent (no geometric term), to round-off.
//
// Why: at 3,100 cells the assembled matrix is ~10 MB of values and indices, zeroed and written
// (64 scattered 3x3 blocks per element) once per Newton iteration and streamed once per GMRES
// product. An element's product reads its rotation and a shared K_e that stays in cache, so a
// product costs a fraction of the assembled one and the tangent costs nothing beyond what the
// residual computes anyway. A matrix is still assembled for the rare refactorisation.
//
// Products run on a team: member m applies the elements of element_chunks[m] (which share no
// node with another member's) and the points in them, then the caller the shared elements and
// points, in a fixed order: the result does not depend on the threads' timing.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <Eigen/StdVector>
#include <array>
#include <vector>

#include "core/fem/hex_element.h"
#include "core/fem/linear_operator.h"
#include "core/fem/surface_embedding.h"

namespace softid::fem {

class ThreadTeam;

class StepTangentOperator final : public LinearOperator {
 public:
  using StiffnessMatrices = std::vector<Matrix24d, Eigen::aligned_allocator<Matrix24d>>;
  // What the operator reads. Nothing is owned: all of it must outlive the operator's use, and
  // keep its values while products run.
  struct Views {
    const std::vector<std::array<int, 8>>* element_nodes = nullptr;
    const StiffnessMatrices* stiffness_matrices = nullptr;
    const std::vector<int>* stiffness_index = nullptr;  // per element, into stiffness_matrices
    const std::vector<Eigen::Matrix3d>* rotations = nullptr;        // per element
    double stiffness_coefficient = 1.0;                             // c_k
    const Eigen::VectorXd* mass = nullptr;                          // per node [kg]
    double mass_coefficient = 0.0;                                  // c_m
    const std::vector<char>* fixed = nullptr;                       // per node: eliminated
    const SurfaceEmbedding* points = nullptr;                       // element and weights per point
    const std::vector<Eigen::Matrix3d>* point_jacobians = nullptr;  // per point, where active
    const std::vector<char>* point_active = nullptr;                // per point
    // Parallel layout (see Simulator): per member its own elements and their points, then the
    // shared ones. A team of one takes element_chunks[0] and points_chunks[0].
    const std::vector<std::vector<int>>* element_chunks = nullptr;
    const std::vector<int>* shared_elements = nullptr;
    const std::vector<std::vector<int>>* point_chunks = nullptr;
    const std::vector<int>* shared_points = nullptr;
    ThreadTeam* team = nullptr;  // null: the calling thread
    // Nonzeros of the assembled matrix: the work model counts a product as that matrix's, so the
    // refactorisation rule decides the same whichever way the products are computed.
    double assembled_nonzeros = 0.0;
  };

  StepTangentOperator() = default;
  // @throws std::invalid_argument when a view is missing or sizes disagree.
  explicit StepTangentOperator(const Views& views) { Bind(views); }
  // Applies the operator `views` describe from now on, keeping the work storage (no allocation
  // per solve). @throws std::invalid_argument as the constructor.
  void Bind(const Views& views);

  Eigen::Index size() const override {
    return views_.mass != nullptr ? 3 * views_.mass->size() : 0;
  }
  void Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) override;
  double ApplyWork() const override { return 2.0 * views_.assembled_nonzeros; }

  // The operator's rows on the unknowns of `nodes` (ascending; node i has unknowns 3 i .. 3 i + 2),
  // ordered as `nodes`, all columns: the rows of the assembled matrix, without assembling it.
  // Visits every element once; rotates element blocks only in rows of `nodes`.
  using RowMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;
  RowMatrix NodeRows(const std::vector<int>& nodes);

 private:
  void ApplyElements(const std::vector<int>& elements, const double* x, double* y) const;
  void ApplyPoints(const std::vector<int>& points, const double* x, double* y) const;
  Views views_;
  bool has_fixed_ = false;
  Eigen::VectorXd masked_;  // x with the clamped nodes' entries zeroed
  // NodeBlock's work storage: node -> position in `nodes` (-1 elsewhere), element -> slot among
  // the elements touching them (-1 elsewhere), those elements, their points' 24x24 blocks, and
  // the block's entries.
  std::vector<int> local_index_, element_slot_, touched_elements_;
  std::vector<Matrix24d, Eigen::aligned_allocator<Matrix24d>> point_blocks_;
  std::vector<Eigen::Triplet<double, int>> entries_;
};

}  // namespace softid::fem
