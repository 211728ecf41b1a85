// An exact solve on a few nodes where the step matrix departs most from the matrix the
// preconditioner's factor was taken of: the nodes of the elements in contact.
//
// Why: a contact or friction point adds a stiff 3x3 Jacobian to its element's nodes, and a
// landing with friction changes which points stick, slip or touch between Newton iterations. The
// reference factor (linear_solver.h) then misses exactly those blocks: a friction landing's frame
// took ~30 GMRES iterations per solve on a factor a few iterations old, 1-5 on a fresh one, but a
// fresh factor per iteration costs more than the iterations it saves. The block on the contact
// nodes is small (a few hundred nodes) and is factorised exactly (sparse LU: friction makes it
// non-symmetric) once per Newton iteration.
//
// Used as the second stage of a multiplicative Schwarz preconditioner (LinearSolver):
//   x1 = P^-1 r,  x = x1 + E A_CC^-1 (E^T r - (E^T A) x1),
// E the injection of the nodes' unknowns. Only the operator's rows on the nodes, E^T A, are
// needed, not a product with all of A. Flexible GMRES keeps the preconditioned basis, so the
// preconditioner may change between solves and need not be symmetric.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <memory>
#include <vector>

namespace softid::fem {

class SubdomainCorrection {
 public:
  using Matrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;
  using RowMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

  // Takes `rows`, the operator's rows on the unknowns of `nodes` (node i has unknowns 3 i ..
  // 3 i + 2; `nodes` ascending, rows ordered as `nodes`, all columns), and factorises their block
  // on the same unknowns. Returns false, leaving the correction empty, when `nodes` is empty or
  // the block is singular.
  // @pre rows.rows() == 3 nodes.size(), rows.cols() > 3 max(nodes)
  bool Assign(const std::vector<int>& nodes, RowMatrix rows);
  void Clear();
  bool empty() const { return nodes_.empty(); }
  int num_nodes() const { return static_cast<int>(nodes_.size()); }

  // The rows of `a` (or of a^T) on the unknowns of `nodes` (ascending), ordered as `nodes`: what
  // to Assign when the operator is an assembled matrix.
  static RowMatrix Rows(const Matrix& a, const std::vector<int>& nodes, bool transposed);

  // x += E A_CC^-1 (E^T residual - (E^T A) x). Allocation-free once sized.
  void Correct(const Eigen::Ref<const Eigen::VectorXd>& residual, Eigen::VectorXd* x);
  // Work of one Correct in the work model's units (refactorisation_rule.h): the product with the
  // rows and the LU factors' two triangular solves.
  double CorrectWork() const { return work_; }

 private:
  // The sparsity of the last block analysed: a Newton step's contact nodes rarely change between
  // its iterations, and then the LU's ordering and elimination tree are reused (factorize only).
  struct Pattern {
    Eigen::Index size = -1;
    std::vector<int> outer, inner;
    bool Matches(const Matrix& block) const;
    void Assign(const Matrix& block);
  };

  std::vector<int> nodes_;
  RowMatrix rows_;
  Pattern pattern_;
  // On the heap: Eigen's SparseLU cannot be moved, and the solver owning this must be.
  std::unique_ptr<Eigen::SparseLU<Matrix, Eigen::COLAMDOrdering<int>>> lu_;
  Eigen::VectorXd local_, solution_;  // the local residual and its solve
  double work_ = 0.0;
};

}  // namespace softid::fem
