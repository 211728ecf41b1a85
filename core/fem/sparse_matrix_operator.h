// A sparse matrix, or its transpose, as a LinearOperator. On a team, member m multiplies a range
// of columns holding about 1/size of the nonzeros: transposed, its rows of the result; else a
// partial product, the partials summed in member order (a fixed order: the result does not
// depend on the threads' timing).
#pragma once

#include <Eigen/SparseCore>
#include <vector>

#include "core/fem/linear_operator.h"

namespace softid::fem {

class ThreadTeam;

class SparseMatrixOperator final : public LinearOperator {
 public:
  using Matrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

  SparseMatrixOperator() = default;
  // Applies `a` (transposed: a^T), which must outlive the use, on `team` (null: the calling
  // thread). Keeps the work storage of an earlier binding.
  void Bind(const Matrix& a, bool transposed, ThreadTeam* team);

  Eigen::Index size() const override { return a_ != nullptr ? a_->rows() : 0; }
  void Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) override;
  double ApplyWork() const override {
    return a_ != nullptr ? 2.0 * static_cast<double>(a_->nonZeros()) : 0.0;
  }

 private:
  const Matrix* a_ = nullptr;
  bool transposed_ = false;
  ThreadTeam* team_ = nullptr;
  // Column range bounds per member and the members' partial results.
  std::vector<int> column_ranges_;
  std::vector<Eigen::VectorXd> partial_products_;
};

}  // namespace softid::fem
