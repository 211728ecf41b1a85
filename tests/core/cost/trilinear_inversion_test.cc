#include "core/cost/trilinear_inversion.h"

#include <gtest/gtest.h>

#include <random>

#include "core/geometry/regular_grid.h"

namespace softid::cost {
namespace {

// A unit cube of edge h at `origin`, corners randomly displaced by up to `distortion` * h.
std::array<Eigen::Vector3d, 8> DistortedCell(double h, double distortion, std::mt19937* rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::array<Eigen::Vector3d, 8> corners;
  const Eigen::Vector3d origin(0.3, -1.2, 2.5);
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d offset((c & 1) ? 1.0 : 0.0, (c & 2) ? 1.0 : 0.0, (c & 4) ? 1.0 : 0.0);
    const Eigen::Vector3d noise(uniform(*rng), uniform(*rng), uniform(*rng));
    corners[c] = origin + h * offset + distortion * h * noise;
  }
  return corners;
}

Eigen::Vector3d Map(const std::array<Eigen::Vector3d, 8>& corners, const Eigen::Vector3d& xi) {
  const std::array<double, 8> w = geometry::TrilinearWeights(xi);
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int c = 0; c < 8; ++c) x += w[c] * corners[c];
  return x;
}

// Newton recovers the local coordinates of points in distorted cells to round-off, in a few
// iterations, and returns the Jacobian at the solution.
TEST(InvertTrilinearMap, RecoversLocalCoordinates) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double h = 0.01;
  int max_iterations = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const auto corners = DistortedCell(h, 0.25, &rng);
    const Eigen::Vector3d xi(unit(rng), unit(rng), unit(rng));
    const TrilinearInversion result = InvertTrilinearMap(corners, Map(corners, xi));
    ASSERT_TRUE(result.converged) << "trial " << trial;
    EXPECT_LT((result.xi - xi).cwiseAbs().maxCoeff(), 1e-13);
    max_iterations = std::max(max_iterations, result.iterations);
    // Jacobian = sum_c x_c grad N_c(xi).
    const std::array<Eigen::Vector3d, 8> g = geometry::TrilinearGradients(result.xi);
    Eigen::Matrix3d jacobian = Eigen::Matrix3d::Zero();
    for (int c = 0; c < 8; ++c) jacobian += corners[c] * g[c].transpose();
    EXPECT_LT((result.jacobian - jacobian).norm(), 1e-12 * h);
  }
  EXPECT_LE(max_iterations, 8);
}

// Points outside the cell converge to local coordinates outside [0,1]^3 (the caller rejects them);
// a degenerate (flat) cell does not converge.
TEST(InvertTrilinearMap, OutsideAndDegenerate) {
  std::mt19937 rng(3);
  const auto corners = DistortedCell(0.01, 0.1, &rng);
  const TrilinearInversion outside =
      InvertTrilinearMap(corners, Map(corners, Eigen::Vector3d(1.3, 0.5, -0.2)));
  ASSERT_TRUE(outside.converged);
  EXPECT_NEAR(outside.xi.x(), 1.3, 1e-12);
  EXPECT_NEAR(outside.xi.z(), -0.2, 1e-12);

  std::array<Eigen::Vector3d, 8> flat = corners;
  for (auto& x : flat) x.z() = 0.0;
  EXPECT_FALSE(InvertTrilinearMap(flat, Eigen::Vector3d(0.3, -1.2, 0.004)).converged);
}

}  // namespace
}  // namespace softid::cost
