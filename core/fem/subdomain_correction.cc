#include "core/fem/subdomain_correction.h"

#include <algorithm>

#include "core/common/check.h"

namespace softid::fem {

namespace {

// The columns of `rows` on the unknowns of `nodes`, ordered as `nodes`.
SubdomainCorrection::Matrix BlockOnNodes(const SubdomainCorrection::RowMatrix& rows,
                                         const std::vector<int>& nodes) {
  std::vector<int> local(rows.cols() / 3, -1);
  for (size_t k = 0; k < nodes.size(); ++k) local[nodes[k]] = static_cast<int>(k);
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int row = 0; row < rows.rows(); ++row) {
    for (SubdomainCorrection::RowMatrix::InnerIterator it(rows, row); it; ++it) {
      const int column = static_cast<int>(it.col());
      const int node = local[column / 3];
      if (node >= 0) entries.emplace_back(row, 3 * node + column % 3, it.value());
    }
  }
  const int n = static_cast<int>(rows.rows());
  SubdomainCorrection::Matrix block(n, n);
  block.setFromTriplets(entries.begin(), entries.end());
  return block;
}

}  // namespace

bool SubdomainCorrection::Pattern::Matches(const Matrix& block) const {
  return block.isCompressed() && block.rows() == size &&
         std::equal(outer.begin(), outer.end(), block.outerIndexPtr(),
                    block.outerIndexPtr() + block.outerSize() + 1) &&
         std::equal(inner.begin(), inner.end(), block.innerIndexPtr(),
                    block.innerIndexPtr() + block.nonZeros());
}

void SubdomainCorrection::Pattern::Assign(const Matrix& block) {
  size = block.rows();
  outer.assign(block.outerIndexPtr(), block.outerIndexPtr() + block.outerSize() + 1);
  inner.assign(block.innerIndexPtr(), block.innerIndexPtr() + block.nonZeros());
}

bool SubdomainCorrection::Assign(const std::vector<int>& nodes, RowMatrix rows) {
  Clear();
  if (nodes.empty()) return false;
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(nodes.size());
  SOFTID_DEMAND(rows.rows() == n && rows.cols() > 3 * nodes.back());
  if (lu_ == nullptr) lu_ = std::make_unique<Eigen::SparseLU<Matrix, Eigen::COLAMDOrdering<int>>>();
  const Matrix block = BlockOnNodes(rows, nodes);
  if (!pattern_.Matches(block)) {
    lu_->analyzePattern(block);
    pattern_.Assign(block);
  }
  lu_->factorize(block);
  if (lu_->info() != Eigen::Success) {
    pattern_ = Pattern();  // a failed factorisation may leave the analysis unusable
    return false;
  }
  nodes_ = nodes;
  rows_ = std::move(rows);
  local_.resize(n);
  solution_.resize(n);
  // The rows' product, and two triangular solves over L's and U's entries, two flops each.
  work_ = 2.0 * static_cast<double>(rows_.nonZeros()) +
          4.0 * static_cast<double>(lu_->nnzL() + lu_->nnzU());
  return true;
}

SubdomainCorrection::RowMatrix SubdomainCorrection::Rows(const Matrix& a,
                                                         const std::vector<int>& nodes,
                                                         bool transposed) {
  const int n = 3 * static_cast<int>(nodes.size());
  RowMatrix rows(n, a.cols());
  if (transposed) {
    // Rows of a^T are columns of a.
    std::vector<Eigen::Triplet<double, int>> entries;
    for (int k = 0; k < n; ++k) {
      for (Matrix::InnerIterator it(a, 3 * nodes[k / 3] + k % 3); it; ++it)
        entries.emplace_back(k, static_cast<int>(it.row()), it.value());
    }
    rows.setFromTriplets(entries.begin(), entries.end());
    return rows;
  }
  // Rows of a on the nodes: one pass over a's entries, keeping those whose row is a node's.
  std::vector<int> local(a.rows() / 3, -1);
  for (size_t k = 0; k < nodes.size(); ++k) local[nodes[k]] = static_cast<int>(k);
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int column = 0; column < a.outerSize(); ++column) {
    for (Matrix::InnerIterator it(a, column); it; ++it) {
      const int row = static_cast<int>(it.row());
      const int node = local[row / 3];
      if (node >= 0) entries.emplace_back(3 * node + row % 3, column, it.value());
    }
  }
  rows.setFromTriplets(entries.begin(), entries.end());
  return rows;
}

void SubdomainCorrection::Clear() {
  nodes_.clear();
  work_ = 0.0;
}

void SubdomainCorrection::Correct(const Eigen::Ref<const Eigen::VectorXd>& residual,
                                  Eigen::VectorXd* x) {
  const Eigen::Index count = static_cast<Eigen::Index>(nodes_.size());
  local_.noalias() = -rows_ * *x;
  for (Eigen::Index k = 0; k < count; ++k)
    local_.segment<3>(3 * k) += residual.segment<3>(3 * nodes_[k]);
  solution_ = lu_->solve(local_);
  for (Eigen::Index k = 0; k < count; ++k)
    x->segment<3>(3 * nodes_[k]) += solution_.segment<3>(3 * k);
}

}  // namespace softid::fem
