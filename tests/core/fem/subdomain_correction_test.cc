// SubdomainCorrection: the exact solve on a few nodes, its rows taken from an assembled matrix or
// its transpose, and the LU's analysis reused while the nodes' sparsity stays the same.
#include "core/fem/subdomain_correction.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace softid::fem {
namespace {

using Matrix = SubdomainCorrection::Matrix;

// A random non-symmetric matrix with the 3x3 block coupling of a chain of `nodes` nodes, strongly
// diagonal so that every block on a subset of nodes is regular.
Matrix ChainMatrix(int nodes, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int node = 0; node < nodes; ++node) {
    for (int neighbour = std::max(0, node - 1); neighbour <= std::min(nodes - 1, node + 1);
         ++neighbour) {
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          entries.emplace_back(3 * node + i, 3 * neighbour + j,
                               (node == neighbour && i == j ? 10.0 : 0.0) + uniform(rng));
    }
  }
  Matrix a(3 * nodes, 3 * nodes);
  a.setFromTriplets(entries.begin(), entries.end());
  return a;
}

// The block of `a` on the unknowns of `nodes`, dense.
Eigen::MatrixXd DenseBlock(const Matrix& a, const std::vector<int>& nodes) {
  const Eigen::MatrixXd dense = a;
  const int n = 3 * static_cast<int>(nodes.size());
  Eigen::MatrixXd block(n, n);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c)
      block(r, c) = dense(3 * nodes[r / 3] + r % 3, 3 * nodes[c / 3] + c % 3);
  return block;
}

// From x = 0, Correct solves the block: x_C = A_CC^-1 r_C, and leaves the other unknowns alone.
void ExpectSolvesTheBlock(SubdomainCorrection& correction, const Matrix& a,
                          const std::vector<int>& nodes) {
  const Eigen::VectorXd residual = Eigen::VectorXd::LinSpaced(a.rows(), -1.0, 2.0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(a.rows());
  correction.Correct(residual, &x);
  const int n = 3 * static_cast<int>(nodes.size());
  Eigen::VectorXd local_residual(n), local_x(n);
  std::vector<char> member(a.rows() / 3, 0);
  for (int k = 0; k < n; ++k) {
    local_residual[k] = residual[3 * nodes[k / 3] + k % 3];
    local_x[k] = x[3 * nodes[k / 3] + k % 3];
    member[nodes[k / 3]] = 1;
  }
  EXPECT_LT((DenseBlock(a, nodes) * local_x - local_residual).norm(),
            1e-12 * local_residual.norm());
  for (int i = 0; i < a.rows(); ++i)
    if (!member[i / 3]) EXPECT_EQ(x[i], 0.0) << "unknown " << i;
}

TEST(SubdomainCorrection, RowsOfTheTransposeAreColumns) {
  const Matrix a = ChainMatrix(30, 1);
  const std::vector<int> nodes = {2, 3, 4, 17, 29};
  const Matrix transposed = a.transpose();
  const Eigen::MatrixXd from_columns = SubdomainCorrection::Rows(a, nodes, true);
  const Eigen::MatrixXd from_rows = SubdomainCorrection::Rows(transposed, nodes, false);
  EXPECT_EQ(from_columns, from_rows);
  const Eigen::MatrixXd dense = a;
  for (int k = 0; k < 3 * static_cast<int>(nodes.size()); ++k)
    EXPECT_EQ(from_columns.row(k), dense.col(3 * nodes[k / 3] + k % 3).transpose()) << k;
}

// A Newton step keeps its contact nodes while the values change: the second Assign reuses the
// first's analysis, and must still solve the new block; new nodes get a new analysis.
TEST(SubdomainCorrection, NewValuesOnTheSameNodesAreSolvedExactly) {
  const std::vector<int> nodes = {5, 6, 7, 8, 20};
  SubdomainCorrection correction;
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const Matrix a = ChainMatrix(30, seed);
    ASSERT_TRUE(correction.Assign(nodes, SubdomainCorrection::Rows(a, nodes, false)));
    ExpectSolvesTheBlock(correction, a, nodes);
    correction.Clear();
  }
  const std::vector<int> other = {0, 1, 12, 13, 14, 15};
  const Matrix a = ChainMatrix(30, 4);
  ASSERT_TRUE(correction.Assign(other, SubdomainCorrection::Rows(a, other, false)));
  EXPECT_EQ(correction.num_nodes(), 6);
  ExpectSolvesTheBlock(correction, a, other);
}

TEST(SubdomainCorrection, ASingularBlockLeavesItEmpty) {
  const std::vector<int> nodes = {3, 4};
  Matrix a = ChainMatrix(10, 5);
  SubdomainCorrection correction;
  ASSERT_TRUE(correction.Assign(nodes, SubdomainCorrection::Rows(a, nodes, false)));
  // Node 3's rows (unknowns 9-11) vanish on the block's columns (nodes 3 and 4).
  for (int c = 9; c < 15; ++c)
    for (int r = 9; r < 12; ++r) a.coeffRef(r, c) = 0.0;
  EXPECT_FALSE(correction.Assign(nodes, SubdomainCorrection::Rows(a, nodes, false)));
  EXPECT_TRUE(correction.empty());
  // And a regular block afterwards is analysed and solved again.
  const Matrix regular = ChainMatrix(10, 6);
  ASSERT_TRUE(correction.Assign(nodes, SubdomainCorrection::Rows(regular, nodes, false)));
  ExpectSolvesTheBlock(correction, regular, nodes);
}

}  // namespace
}  // namespace softid::fem
