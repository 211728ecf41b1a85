#include "core/fem/hex_element.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

namespace softid::fem {
namespace {

std::array<double, 8> FullCell(double h) {
  std::array<double, 8> w;
  w.fill(h * h * h / 8.0);
  return w;
}

// A full cell's stiffness is symmetric, positive semi-definite, with exactly the 6 rigid modes in
// its null space (no hourglass modes).
TEST(HexElement, FullCellHasOnlyRigidNullModes) {
  const Matrix24d k = ElementStiffness(FullCell(0.1), 0.1, 5e4, 3e4);
  EXPECT_LT((k - k.transpose()).norm(), 1e-9 * k.norm());
  const Eigen::SelfAdjointEigenSolver<Matrix24d> eig(k);
  int zeros = 0;
  for (int i = 0; i < 24; ++i) {
    EXPECT_GT(eig.eigenvalues()[i], -1e-9 * eig.eigenvalues().maxCoeff());
    if (eig.eigenvalues()[i] < 1e-9 * eig.eigenvalues().maxCoeff()) ++zeros;
  }
  EXPECT_EQ(zeros, 6);
}

// Patch test: a uniform strain stores exactly (mu eps:eps + lambda/2 tr(eps)^2) x volume.
TEST(HexElement, UniformStrainEnergyIsExact) {
  const double h = 0.05, lambda = 2e5, mu = 1e5;
  Eigen::Matrix3d eps;
  eps << 0.01, 0.002, -0.003, 0.002, -0.004, 0.001, -0.003, 0.001, 0.006;
  Vector24d u;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d x(h * (c & 1), h * ((c >> 1) & 1), h * ((c >> 2) & 1));
    u.segment<3>(3 * c) = eps * x;
  }
  const Matrix24d k = ElementStiffness(FullCell(h), h, lambda, mu);
  const double energy = 0.5 * u.dot(k * u);
  const double expected =
      (mu * eps.squaredNorm() + 0.5 * lambda * eps.trace() * eps.trace()) * h * h * h;
  EXPECT_NEAR(energy, expected, 1e-12 * expected);
}

}  // namespace
}  // namespace softid::fem
