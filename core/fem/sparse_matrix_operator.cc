#include "core/fem/sparse_matrix_operator.h"

#include <algorithm>

#include "core/fem/thread_team.h"

namespace softid::fem {

void SparseMatrixOperator::Bind(const Matrix& a, bool transposed, ThreadTeam* team) {
  a_ = &a;
  transposed_ = transposed;
  team_ = team;
  const int members = team_ != nullptr ? team_->size() : 1;
  if (members == 1) return;
  const int n = static_cast<int>(a.cols());
  column_ranges_.assign(members + 1, n);
  column_ranges_[0] = 0;
  const int* outer = a.outerIndexPtr();
  for (int m = 1; m < members; ++m) {
    const double target = static_cast<double>(a.nonZeros()) * m / members;
    column_ranges_[m] =
        static_cast<int>(std::lower_bound(outer, outer + n, target,
                                          [](int entry, double value) { return entry < value; }) -
                         outer);
  }
  partial_products_.resize(members);
  for (int m = 1; m < members; ++m) partial_products_[m].resize(a.rows());
}

void SparseMatrixOperator::Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) {
  const Matrix& a = *a_;
  const int members = team_ != nullptr ? team_->size() : 1;
  if (members == 1) {
    // The transposed product runs over the column-major storage as row dot products: no
    // transposed copy of the matrix is made.
    if (transposed_)
      y->noalias() = a.transpose() * x;
    else
      y->noalias() = a * x;
    return;
  }
  y->resize(a.rows());
  team_->Run([&](int m) {
    const int first = column_ranges_[m], count = column_ranges_[m + 1] - first;
    if (transposed_) {
      y->segment(first, count).noalias() = a.middleCols(first, count).transpose() * x;
    } else {
      Eigen::VectorXd& partial = m == 0 ? *y : partial_products_[m];
      partial.noalias() = a.middleCols(first, count) * x.segment(first, count);
    }
  });
  if (!transposed_) {
    for (int m = 1; m < members; ++m) *y += partial_products_[m];
  }
}

}  // namespace softid::fem
