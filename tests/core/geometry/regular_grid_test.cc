#include "core/geometry/regular_grid.h"

#include <gtest/gtest.h>

#include <random>

namespace softid::geometry {
namespace {

RegularGrid MakeGrid() {
  RegularGrid grid;
  grid.origin = Eigen::Vector3d(-0.1, 0.2, 0.05);
  grid.cell_size = 0.01;
  grid.num_cells = Eigen::Vector3i(4, 3, 5);
  return grid;
}

// Node and cell indices are x-fastest and round-trip through coordinates.
TEST(RegularGrid, IndicesRoundTrip) {
  const RegularGrid grid = MakeGrid();
  EXPECT_EQ(grid.NumNodesPerAxis(), Eigen::Vector3i(5, 4, 6));
  EXPECT_EQ(grid.NumNodes(), 5 * 4 * 6);
  EXPECT_EQ(grid.NumCells(), 4 * 3 * 5);
  EXPECT_EQ(grid.NodeIndex(1, 2, 3), 1 + 5 * (2 + 4 * 3));
  EXPECT_EQ(grid.CellIndex(1, 2, 3), 1 + 4 * (2 + 3 * 3));
  for (int n = 0; n < grid.NumNodes(); ++n) {
    const Eigen::Vector3i c = grid.NodeCoords(n);
    ASSERT_EQ(grid.NodeIndex(c.x(), c.y(), c.z()), n);
  }
  for (int n = 0; n < grid.NumCells(); ++n) {
    const Eigen::Vector3i c = grid.CellCoords(n);
    ASSERT_EQ(grid.CellIndex(c.x(), c.y(), c.z()), n);
  }
  EXPECT_TRUE(grid.NodePosition(grid.NodeIndex(1, 2, 3))
                  .isApprox(grid.origin + 0.01 * Eigen::Vector3d(1, 2, 3)));
}

// CellNodes lists the corners in order c = dx + 2dy + 4dz.
TEST(RegularGrid, CellNodesCornerOrder) {
  const RegularGrid grid = MakeGrid();
  const int cell = grid.CellIndex(2, 1, 3);
  const std::array<int, 8> nodes = grid.CellNodes(cell);
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3i expected(2 + (c & 1), 1 + ((c >> 1) & 1), 3 + ((c >> 2) & 1));
    EXPECT_EQ(grid.NodeCoords(nodes[c]), expected) << "corner " << c;
  }
}

// LocateCell finds the containing cell and local coordinates; outside points clamp the cell.
TEST(RegularGrid, LocateCell) {
  const RegularGrid grid = MakeGrid();
  Eigen::Vector3d local;
  const Eigen::Vector3d p = grid.origin + 0.01 * Eigen::Vector3d(2.25, 0.5, 4.75);
  const int cell = grid.LocateCell(p, &local);
  EXPECT_EQ(grid.CellCoords(cell), Eigen::Vector3i(2, 0, 4));
  EXPECT_TRUE(local.isApprox(Eigen::Vector3d(0.25, 0.5, 0.75), 1e-9));
  // The far corner belongs to the last cell with local coordinates 1.
  const Eigen::Vector3d corner = grid.origin + 0.01 * grid.num_cells.cast<double>();
  EXPECT_EQ(grid.CellCoords(grid.LocateCell(corner, &local)), Eigen::Vector3i(3, 2, 4));
  EXPECT_TRUE(local.isApprox(Eigen::Vector3d::Ones(), 1e-9));
  // Outside: clamped cell, unclamped local coordinates.
  const Eigen::Vector3d outside = grid.origin + 0.01 * Eigen::Vector3d(-1.5, 1.5, 7.0);
  EXPECT_EQ(grid.CellCoords(grid.LocateCell(outside, &local)), Eigen::Vector3i(0, 1, 4));
  EXPECT_NEAR(local.x(), -1.5, 1e-9);
  EXPECT_NEAR(local.z(), 3.0, 1e-9);
  EXPECT_EQ(grid.CellCoords(grid.LocateCell(Eigen::Vector3d::Constant(1e300), nullptr)),
            Eigen::Vector3i(3, 2, 4));
}

// Trilinear weights interpolate the corners, sum to one and reproduce linear functions.
TEST(RegularGrid, TrilinearWeightsInterpolate) {
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner(c & 1, (c >> 1) & 1, (c >> 2) & 1);
    const std::array<double, 8> w = TrilinearWeights(corner);
    for (int d = 0; d < 8; ++d) EXPECT_EQ(w[d], c == d ? 1.0 : 0.0);
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Eigen::Vector3d a(0.3, -1.2, 2.0);
  for (int trial = 0; trial < 100; ++trial) {
    const Eigen::Vector3d xi(u(rng), u(rng), u(rng));
    const std::array<double, 8> w = TrilinearWeights(xi);
    double sum = 0.0, linear = 0.0;
    for (int c = 0; c < 8; ++c) {
      sum += w[c];
      linear += w[c] * a.dot(Eigen::Vector3d(c & 1, (c >> 1) & 1, (c >> 2) & 1));
    }
    EXPECT_NEAR(sum, 1.0, 1e-14);
    EXPECT_NEAR(linear, a.dot(xi), 1e-14);
  }
}

// Trilinear gradients match central finite differences of the weights.
TEST(RegularGrid, TrilinearGradientsMatchFiniteDifferences) {
  const Eigen::Vector3d xi(0.2, 0.7, 0.45);
  const std::array<Eigen::Vector3d, 8> g = TrilinearGradients(xi);
  const double eps = 1e-6;
  for (int a = 0; a < 3; ++a) {
    const std::array<double, 8> plus = TrilinearWeights(xi + eps * Eigen::Vector3d::Unit(a));
    const std::array<double, 8> minus = TrilinearWeights(xi - eps * Eigen::Vector3d::Unit(a));
    for (int c = 0; c < 8; ++c) {
      EXPECT_NEAR(g[c][a], (plus[c] - minus[c]) / (2 * eps), 1e-9) << "corner " << c;
    }
  }
}

}  // namespace
}  // namespace softid::geometry
