#include <gtest/gtest.h>

#include <random>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"

namespace softid::fem {
namespace {

// The exact Jacobian of the step equations (corotation with its rotation derivative, stiffness
// damping, penalty contact, friction, drag) matches central finite differences, in a rotated,
// deformed, penetrating, sliding state.
TEST(StepJacobian, MatchesFiniteDifferences) {
  PhysicalParameters p;
  p.youngs_modulus = 3e4;
  p.poisson_ratio = 0.35;
  p.density = 400.0;
  p.mass_damping = 0.5;
  p.stiffness_damping = 0.02;
  p.friction_coefficient = 0.4;
  p.contact_damping = 0.003;
  p.drag_linear = 0.3;
  p.drag_quadratic = 0.8;
  p.ground = GroundPlane{Eigen::Vector3d(0.1, 0.0, 1.0).normalized(), 0.0};
  SimulationOptions options;
  options.cells_along_longest_side = 5;
  options.time_step = 1.0 / 120.0;
  geometry::TriangleMesh box = geometry::MakeBox(Eigen::Vector3d(0.1, 0.06, 0.05), 0.02);
  for (auto& v : box.vertices) v.z() += 0.03;
  Simulator sim(box, p, options);

  // A state: rotated by 0.4 rad, deformed, moving and sliding; pushed into the floor.
  const int n = sim.hex_mesh().NumNodes();
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 1.0);
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
  SimulationState state = sim.state();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d& x = sim.hex_mesh().rest_positions[i];
    state.u.segment<3>(3 * i) = rotation * x - x + Eigen::Vector3d(0, 0, -0.012) +
                                0.002 * Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    state.v.segment<3>(3 * i) = Eigen::Vector3d(0.5, 0.1, -0.3) +
                                0.05 * Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  }
  state.a.setZero();
  sim.SetState(state);
  Eigen::VectorXd u_next = state.u + options.time_step * state.v;
  for (int i = 0; i < 3 * n; ++i) u_next[i] += 1e-3 * noise(rng);

  Eigen::VectorXd r0;
  Eigen::SparseMatrix<double> jacobian;
  sim.EvaluateStepResidual(u_next, &r0, &jacobian);
  for (int trial = 0; trial < 3; ++trial) {
    Eigen::VectorXd direction(3 * n);
    for (int i = 0; i < 3 * n; ++i) direction[i] = noise(rng);
    const double eps = 1e-7;
    Eigen::VectorXd r_plus, r_minus;
    sim.EvaluateStepResidual(u_next + eps * direction, &r_plus, nullptr);
    sim.EvaluateStepResidual(u_next - eps * direction, &r_minus, nullptr);
    const Eigen::VectorXd finite_difference = (r_plus - r_minus) / (2 * eps);
    const Eigen::VectorXd analytic = jacobian * direction;
    EXPECT_LT((analytic - finite_difference).norm(), 1e-5 * finite_difference.norm())
        << "trial " << trial;
  }
}

}  // namespace
}  // namespace softid::fem
