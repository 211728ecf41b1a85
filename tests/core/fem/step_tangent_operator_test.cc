#include "core/fem/step_tangent_operator.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
#include <stdexcept>

#include "core/fem/thread_team.h"

namespace softid::fem {
namespace {

// Three cells in a row along x (nodes ix + 4 (iy + 2 iz), ix 0..3): cells 0 and 2 share no node,
// cell 1 shares a face with each. Two distinct element matrices, random rotations, one clamped
// node, surface points in every cell (the one in cell 2 not in contact).
struct RowOfCells {
  std::vector<std::array<int, 8>> element_nodes;
  StepTangentOperator::StiffnessMatrices stiffness;
  std::vector<int> stiffness_index = {0, 1, 0};
  std::vector<Eigen::Matrix3d> rotations;
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(16);
  std::vector<char> fixed = std::vector<char>(16, 0);
  SurfaceEmbedding points;
  std::vector<Eigen::Matrix3d> point_jacobians;
  std::vector<char> point_active = {1, 1, 0};
  double stiffness_coefficient = 1.3;
  double mass_coefficient = 2.5e4;

  RowOfCells() {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    const auto node = [](int ix, int iy, int iz) { return ix + 4 * (iy + 2 * iz); };
    for (int e = 0; e < 3; ++e) {
      std::array<int, 8> nodes;
      for (int c = 0; c < 8; ++c) nodes[c] = node(e + (c & 1), (c >> 1) & 1, (c >> 2) & 1);
      element_nodes.push_back(nodes);
      rotations.push_back(
          Eigen::Quaterniond(Eigen::Vector4d::NullaryExpr(4, [&] { return uniform(rng); }))
              .normalized()
              .toRotationMatrix());
    }
    for (int k = 0; k < 2; ++k) {
      Matrix24d a;
      for (int i = 0; i < 24 * 24; ++i) a(i / 24, i % 24) = uniform(rng);
      stiffness.push_back(a * a.transpose());
    }
    for (int i = 0; i < 16; ++i) mass[i] = 0.01 * (1.5 + uniform(rng));
    fixed[5] = 1;
    for (int e = 0; e < 3; ++e) {
      points.element.push_back(e);
      std::array<double, 8> w;
      double sum = 0.0;
      for (double& wi : w) sum += (wi = 1.0 + uniform(rng));
      for (double& wi : w) wi /= sum;
      points.weights.push_back(w);
      Eigen::Matrix3d j;
      for (int i = 0; i < 9; ++i) j(i / 3, i % 3) = 100.0 * uniform(rng);  // not symmetric
      point_jacobians.push_back(j);
    }
  }

  // The matrix Simulator::Assemble would write for the same terms, densely.
  Eigen::MatrixXd Dense() const {
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(48, 48);
    for (int e = 0; e < 3; ++e) {
      const Eigen::Matrix3d& r = rotations[e];
      const Matrix24d& k = stiffness[stiffness_index[e]];
      for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j)
          a.block<3, 3>(3 * element_nodes[e][i], 3 * element_nodes[e][j]) +=
              stiffness_coefficient * r * k.block<3, 3>(3 * i, 3 * j) * r.transpose();
    }
    for (int i = 0; i < 16; ++i)
      a.block<3, 3>(3 * i, 3 * i) += mass_coefficient * mass[i] * Eigen::Matrix3d::Identity();
    for (int p = 0; p < 3; ++p) {
      if (!point_active[p]) continue;
      const auto& nodes = element_nodes[points.element[p]];
      for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j)
          a.block<3, 3>(3 * nodes[i], 3 * nodes[j]) +=
              points.weights[p][i] * points.weights[p][j] * point_jacobians[p];
    }
    for (int i = 0; i < 16; ++i) {
      if (!fixed[i]) continue;
      a.middleRows<3>(3 * i).setZero();
      a.middleCols<3>(3 * i).setZero();
      a.block<3, 3>(3 * i, 3 * i).setIdentity();
    }
    return a;
  }

  StepTangentOperator::Views Views(const std::vector<std::vector<int>>& element_chunks,
                                   const std::vector<int>& shared_elements,
                                   const std::vector<std::vector<int>>& point_chunks,
                                   const std::vector<int>& shared_points, ThreadTeam* team) const {
    StepTangentOperator::Views v;
    v.element_nodes = &element_nodes;
    v.stiffness_matrices = &stiffness;
    v.stiffness_index = &stiffness_index;
    v.rotations = &rotations;
    v.stiffness_coefficient = stiffness_coefficient;
    v.mass = &mass;
    v.mass_coefficient = mass_coefficient;
    v.fixed = &fixed;
    v.points = &points;
    v.point_jacobians = &point_jacobians;
    v.point_active = &point_active;
    v.element_chunks = &element_chunks;
    v.shared_elements = &shared_elements;
    v.point_chunks = &point_chunks;
    v.shared_points = &shared_points;
    v.team = team;
    v.assembled_nonzeros = 1000.0;
    return v;
  }
};

// The element-by-element product equals the product with the assembled matrix (rotated element
// blocks, lumped mass, non-symmetric contact blocks spread by the weights, clamped node
// eliminated), on one thread and on a team of two with shared elements and points.
TEST(StepTangentOperator, EqualsTheAssembledMatrix) {
  const RowOfCells cells;
  const Eigen::MatrixXd dense = cells.Dense();
  const Eigen::VectorXd x = Eigen::VectorXd::Random(48);
  const Eigen::VectorXd expected = dense * x;

  const std::vector<std::vector<int>> all_elements = {{0, 1, 2}}, all_points = {{0, 1, 2}};
  const std::vector<int> none;
  StepTangentOperator single(cells.Views(all_elements, none, all_points, none, nullptr));
  EXPECT_EQ(single.size(), 48);
  EXPECT_EQ(single.ApplyWork(), 2000.0);
  Eigen::VectorXd y;
  single.Apply(x, &y);
  EXPECT_LT((y - expected).norm(), 1e-12 * expected.norm());
  // The clamped node's rows are the identity.
  EXPECT_TRUE(y.segment<3>(15) == x.segment<3>(15));

  ThreadTeam team(2);
  ASSERT_EQ(team.size(), 2);
  const std::vector<std::vector<int>> element_chunks = {{0}, {2}}, point_chunks = {{0}, {2}};
  const std::vector<int> shared_elements = {1}, shared_points = {1};
  StepTangentOperator threaded(
      cells.Views(element_chunks, shared_elements, point_chunks, shared_points, &team));
  Eigen::VectorXd z, z_again;
  threaded.Apply(x, &z);
  EXPECT_LT((z - expected).norm(), 1e-12 * expected.norm());
  threaded.Apply(x, &z_again);
  EXPECT_TRUE(z == z_again);  // bitwise: a fixed summation order
}

// NodeRows are the assembled matrix's rows on the nodes' unknowns, in their order: element blocks
// of elements partly inside, contact blocks, mass, a clamped node's identity and eliminated column.
TEST(StepTangentOperator, NodeRowsAreTheAssembledMatrixsRows) {
  const RowOfCells cells;
  const Eigen::MatrixXd dense = cells.Dense();
  const std::vector<std::vector<int>> all = {{0, 1, 2}};
  const std::vector<int> none;
  StepTangentOperator op(cells.Views(all, none, all, none, nullptr));
  const std::vector<int> nodes = {0, 2, 5, 6, 11, 15};  // across all three cells; 5 clamped
  const Eigen::MatrixXd rows = Eigen::MatrixXd(op.NodeRows(nodes));
  ASSERT_EQ(rows.rows(), 18);
  ASSERT_EQ(rows.cols(), 48);
  Eigen::MatrixXd expected(18, 48);
  for (size_t k = 0; k < nodes.size(); ++k)
    expected.middleRows<3>(3 * k) = dense.middleRows<3>(3 * nodes[k]);
  EXPECT_LT((rows - expected).norm(), 1e-12 * expected.norm());
  EXPECT_GT((expected.block<3, 3>(0, 3).norm()), 0.0);  // coupled nodes: the test sees off-blocks
}

TEST(StepTangentOperator, RejectsMissingViewsAndMismatchedSizes) {
  const RowOfCells cells;
  const std::vector<std::vector<int>> all = {{0, 1, 2}};
  const std::vector<int> none;
  StepTangentOperator::Views views = cells.Views(all, none, all, none, nullptr);
  views.rotations = nullptr;
  EXPECT_THROW(StepTangentOperator{views}, std::invalid_argument);
  const std::vector<int> short_index = {0, 1};
  views = cells.Views(all, none, all, none, nullptr);
  views.stiffness_index = &short_index;
  EXPECT_THROW(StepTangentOperator{views}, std::invalid_argument);
  const std::vector<std::vector<int>> two_chunks = {{0}, {1, 2}};
  views = cells.Views(two_chunks, none, all, none, nullptr);  // a team of one needs one chunk
  EXPECT_THROW(StepTangentOperator{views}, std::invalid_argument);

  // A rejected binding leaves the operator as it was.
  StepTangentOperator op;
  EXPECT_EQ(op.size(), 0);
  EXPECT_THROW(op.Bind(views), std::invalid_argument);
  EXPECT_EQ(op.size(), 0);
  op.Bind(cells.Views(all, none, all, none, nullptr));
  EXPECT_EQ(op.size(), 48);
  EXPECT_THROW(op.Bind(views), std::invalid_argument);
  EXPECT_EQ(op.size(), 48);
}

}  // namespace
}  // namespace softid::fem
