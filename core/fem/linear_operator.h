// y = A x for a square operator that LinearSolver's GMRES applies: the step matrix need not be
// assembled to be solved with (see StepTangentOperator), and a sparse matrix is one such operator
// (SparseMatrixOperator).
#pragma once

#include <Eigen/Core>

namespace softid::fem {

class LinearOperator {
 public:
  virtual ~LinearOperator() = default;
  virtual Eigen::Index size() const = 0;
  // y = A x, y resized to size(); x and y do not alias. Not const: an operator may keep work
  // storage, and may run on a team of threads.
  virtual void Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) = 0;
  // Work of one Apply in the units of LinearSolver's refactorisation rule (memory-bound flops: a
  // sparse matrix's product is 2 nnz).
  virtual double ApplyWork() const = 0;
};

}  // namespace softid::fem
