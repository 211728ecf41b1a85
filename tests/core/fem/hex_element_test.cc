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

// A cut cell: octants filled to different degrees (one nearly empty, as with the ghost floor).
std::array<double, 8> CutCell(double h) {
  const std::array<double, 8> fill = {1.0, 0.8, 0.55, 0.3, 0.9, 0.4, 0.12, 0.02};
  std::array<double, 8> w;
  for (int q = 0; q < 8; ++q) w[q] = fill[q] * h * h * h / 8.0;
  return w;
}

// Nodal displacements of a displacement field over the cell [0, h]^3.
template <typename Field>
Vector24d Nodal(double h, Field field) {
  Vector24d u;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d x(h * (c & 1), h * ((c >> 1) & 1), h * ((c >> 2) & 1));
    u.segment<3>(3 * c) = field(x);
  }
  return u;
}

class HexElementTest : public ::testing::TestWithParam<ElementFormulation> {};

// A full and a cut cell's stiffness are symmetric, positive semi-definite, with exactly the 6 rigid
// modes in their null space (no hourglass modes).
TEST_P(HexElementTest, OnlyRigidNullModes) {
  for (const auto& weights : {FullCell(0.1), CutCell(0.1)}) {
    const Matrix24d k = ElementStiffness(weights, 0.1, 5e4, 3e4, GetParam());
    EXPECT_LT((k - k.transpose()).norm(), 1e-12 * k.norm());
    const Eigen::SelfAdjointEigenSolver<Matrix24d> eig(k);
    int zeros = 0;
    for (int i = 0; i < 24; ++i) {
      EXPECT_GT(eig.eigenvalues()[i], -1e-9 * eig.eigenvalues().maxCoeff());
      if (eig.eigenvalues()[i] < 1e-9 * eig.eigenvalues().maxCoeff()) ++zeros;
    }
    EXPECT_EQ(zeros, 6);
  }
}

// Patch test: a uniform strain stores exactly (mu eps:eps + lambda/2 tr(eps)^2) x the integrated
// volume, in a full cell and in a cut one.
TEST_P(HexElementTest, UniformStrainEnergyIsExact) {
  const double h = 0.05, lambda = 2e5, mu = 1e5;
  Eigen::Matrix3d eps;
  eps << 0.01, 0.002, -0.003, 0.002, -0.004, 0.001, -0.003, 0.001, 0.006;
  const Vector24d u = Nodal(h, [&](const Eigen::Vector3d& x) { return Eigen::Vector3d(eps * x); });
  for (const auto& weights : {FullCell(h), CutCell(h)}) {
    double volume = 0.0;
    for (double w : weights) volume += w;
    const Matrix24d k = ElementStiffness(weights, h, lambda, mu, GetParam());
    const double energy = 0.5 * u.dot(k * u);
    const double expected =
        (mu * eps.squaredNorm() + 0.5 * lambda * eps.trace() * eps.trace()) * volume;
    EXPECT_NEAR(energy, expected, 1e-10 * expected);
  }
}

// d K / d mu against central differences, and the homogeneity the adjoint relies on:
// K(s lambda, s mu) = s K(lambda, mu), hence K = lambda dK/dlambda + mu dK/dmu.
TEST_P(HexElementTest, ShearDerivativeAndHomogeneity) {
  const double h = 0.04, lambda = 3e5, mu = 1e5, step = 1.0;
  const auto weights = CutCell(h);
  const Matrix24d k = ElementStiffness(weights, h, lambda, mu, GetParam());
  const Matrix24d dk_dmu = ElementShearDerivative(weights, h, lambda, mu, GetParam());
  const Matrix24d central = (ElementStiffness(weights, h, lambda, mu + step, GetParam()) -
                             ElementStiffness(weights, h, lambda, mu - step, GetParam())) /
                            (2.0 * step);
  EXPECT_LT((dk_dmu - central).norm(), 1e-6 * dk_dmu.norm());
  const Matrix24d dk_dlambda = (ElementStiffness(weights, h, lambda + step, mu, GetParam()) -
                                ElementStiffness(weights, h, lambda - step, mu, GetParam())) /
                               (2.0 * step);
  EXPECT_LT((lambda * dk_dlambda + mu * dk_dmu - k).norm(), 1e-6 * k.norm());
  EXPECT_LT((ElementStiffness(weights, h, 2.5 * lambda, 2.5 * mu, GetParam()) - 2.5 * k).norm(),
            1e-12 * k.norm());
}

INSTANTIATE_TEST_SUITE_P(Formulations, HexElementTest,
                         ::testing::Values(ElementFormulation::kTrilinear,
                                           ElementFormulation::kIncompatibleModes));

// Pure bending of a cube about y (Poisson ratio 0): u_x = k x' z', u_z = -k x'^2 / 2 (primes: from
// the centre) strains only eps_xx = k z', storing E k^2 h^5 / 24. The incompatible modes take the
// curvature exactly; the trilinear element adds parasitic shear (shear locking) and stores more.
TEST(HexElement, IncompatibleModesBendExactly) {
  const double h = 0.1, youngs = 1e5, curvature = 0.2;
  const Vector24d u = Nodal(h, [&](const Eigen::Vector3d& x) {
    const Eigen::Vector3d c = x - Eigen::Vector3d::Constant(0.5 * h);
    return Eigen::Vector3d(curvature * c.x() * c.z(), 0.0, -0.5 * curvature * c.x() * c.x());
  });
  const double exact = youngs * curvature * curvature * std::pow(h, 5) / 24.0;
  auto energy = [&](ElementFormulation formulation) {
    const Matrix24d k = ElementStiffness(FullCell(h), h, 0.0, 0.5 * youngs, formulation);
    return 0.5 * u.dot(k * u);
  };
  EXPECT_NEAR(energy(ElementFormulation::kIncompatibleModes), exact, 1e-9 * exact);
  EXPECT_GT(energy(ElementFormulation::kTrilinear), 1.4 * exact);  // 1.5 exactly
}

}  // namespace
}  // namespace softid::fem
