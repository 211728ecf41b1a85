// The same inputs give bitwise the same states, costs and gradients: the optimiser's line searches
// and finite differences must not see solver noise. The factor-renewal rule (LinearSolver's ski
// rental) once compared wall-clock times, so a run could refactorise at different steps and end in
// a different state near stick-slip friction.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"

namespace softid::fem {
namespace {

// A block dropped onto a ramp just steeper than atan(mu) (mu = 0.3, tilted gravity), sliding and
// turning: impact and stick-slip keep the reference factor going stale.
struct RampScene {
  PhysicalParameters parameters;
  SimulationOptions options;
  geometry::TriangleMesh block;
  RampScene() {
    const double theta = 17.0 * std::numbers::pi / 180.0;
    parameters.youngs_modulus = 2e5;
    parameters.density = 500.0;
    parameters.friction_coefficient = 0.3;
    parameters.gravity = 9.81 * Eigen::Vector3d(std::sin(theta), 0.0, -std::cos(theta));
    parameters.initial_velocity = Eigen::Vector3d(0.2, 0.05, 0.0);
    parameters.initial_angular_velocity = Eigen::Vector3d(0.0, 0.0, 2.0);
    parameters.ground = GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
    options.cells_along_longest_side = 8;
    options.time_step = 1.0 / 240.0;
    block = geometry::MakeBox(Eigen::Vector3d(0.1, 0.1, 0.05), 0.0125);
    for (auto& v : block.vertices) v.z() += 0.026;  // dropped from 1 mm
  }
};

struct Trajectory {
  std::vector<SimulationState> states;
  int refactorizations = 0;
};

Trajectory Forward(Simulator& sim, const PhysicalParameters& parameters, int steps) {
  sim.SetParameters(parameters);
  Trajectory run;
  run.states.push_back(sim.state());
  for (int k = 0; k < steps; ++k) {
    const StepSummary summary = sim.Step();
    EXPECT_FALSE(summary.diverged) << "step " << k;
    run.refactorizations += summary.refactorized ? 1 : 0;
    run.states.push_back(sim.state());
  }
  return run;
}

// Bitwise: == on doubles, not a tolerance.
void ExpectSameStates(const Trajectory& a, const Trajectory& b) {
  ASSERT_EQ(a.states.size(), b.states.size());
  for (size_t k = 0; k < a.states.size(); ++k) {
    ASSERT_TRUE(a.states[k].u == b.states[k].u) << "u differs at step " << k;
    ASSERT_TRUE(a.states[k].v == b.states[k].v) << "v differs at step " << k;
    ASSERT_TRUE(a.states[k].a == b.states[k].a) << "a differs at step " << k;
  }
  EXPECT_EQ(a.refactorizations, b.refactorizations);
}

TEST(Determinism, ContactAndFrictionRunIsBitwiseRepeatable) {
  const RampScene scene;
  constexpr int kSteps = 240;  // 1 s
  Simulator first(scene.block, scene.parameters, scene.options);
  const Trajectory a = Forward(first, scene.parameters, kSteps);
  // The factor must have been renewed several times, or the rule was not exercised.
  EXPECT_GE(a.refactorizations, 3);
  // The same simulator again (as an objective reuses it), and a fresh one.
  ExpectSameStates(a, Forward(first, scene.parameters, kSteps));
  Simulator second(scene.block, scene.parameters, scene.options);
  ExpectSameStates(a, Forward(second, scene.parameters, kSteps));
}

// On a team of threads (assembly, triangular solves, products) a run is still bitwise repeatable,
// and it follows the one-thread run to within Newton's tolerance: only the summation order differs.
TEST(Determinism, ThreadedRunIsRepeatableAndFollowsTheOneThreadRun) {
  RampScene scene;
  scene.options.cells_along_longest_side = 16;  // 1,024 elements: enough for a team of two
  constexpr int kSteps = 72;                    // 0.3 s: impact, slide and turn
  SimulationOptions threaded_options = scene.options;
  threaded_options.threads = 2;
  Simulator threaded(scene.block, scene.parameters, threaded_options);
  ASSERT_EQ(threaded.num_threads(), 2);
  const Trajectory a = Forward(threaded, scene.parameters, kSteps);
  EXPECT_GT(a.refactorizations, 0);
  EXPECT_GT(threaded.solver_parallel_share(), 0.5);
  ExpectSameStates(a, Forward(threaded, scene.parameters, kSteps));

  Simulator single(scene.block, scene.parameters, scene.options);
  ASSERT_EQ(single.num_threads(), 1);
  const Trajectory b = Forward(single, scene.parameters, kSteps);
  const double h = threaded.hex_mesh().CellSize();
  double largest = 0.0;
  for (int k = 0; k <= kSteps; ++k)
    largest = std::max(largest, (a.states[k].u - b.states[k].u).lpNorm<Eigen::Infinity>());
  // Measured 2e-11 m: the Newton paths coincide up to round-off. Newton's own tolerance bounds it.
  EXPECT_LT(largest, scene.options.newton_tolerance * h) << "largest difference " << largest;
}

// L = sum_k w . u_k, its adjoint gradient: forward then backward, twice on one simulator.
struct Evaluation {
  double loss = 0.0;
  ParameterGradient gradient;
};

Evaluation ForwardAdjoint(Simulator& sim, const PhysicalParameters& parameters, int steps) {
  const Trajectory run = Forward(sim, parameters, steps);
  const int size = static_cast<int>(run.states[0].u.size());
  Eigen::VectorXd w(size);
  for (int i = 0; i < size; ++i) w[i] = std::sin(0.37 * i);
  Evaluation out;
  StateAdjoint adjoint{Eigen::VectorXd::Zero(size), Eigen::VectorXd::Zero(size),
                       Eigen::VectorXd::Zero(size)};
  for (int k = steps; k >= 1; --k) {
    out.loss += w.dot(run.states[k].u);
    adjoint.u += w;
    const Status status =
        sim.BackpropagateStep(run.states[k - 1], run.states[k], &adjoint, &out.gradient);
    EXPECT_TRUE(status.ok()) << status.ToString();
  }
  sim.BackpropagateInitialState(run.states[0], adjoint, &out.gradient);
  return out;
}

TEST(Determinism, ForwardAdjointGradientIsBitwiseRepeatable) {
  const RampScene scene;
  constexpr int kSteps = 120;
  Simulator sim(scene.block, scene.parameters, scene.options);
  const Evaluation a = ForwardAdjoint(sim, scene.parameters, kSteps);
  const Evaluation b = ForwardAdjoint(sim, scene.parameters, kSteps);
  EXPECT_EQ(a.loss, b.loss);
  EXPECT_EQ(ToJson(a.gradient).dump(), ToJson(b.gradient).dump());
  EXPECT_EQ(a.gradient.youngs_modulus, b.gradient.youngs_modulus);
  EXPECT_EQ(a.gradient.friction_coefficient, b.gradient.friction_coefficient);
  EXPECT_TRUE(a.gradient.gravity == b.gradient.gravity);
  EXPECT_TRUE(a.gradient.initial_velocity == b.gradient.initial_velocity);
  EXPECT_NE(a.gradient.friction_coefficient, 0.0);
}

// The adjoint pass on a team (assembly, transposed solves, the element loop of the parameter
// gradient) is bitwise repeatable, and follows the one-thread pass: a renewed factor is adopted at
// the same point whether it was computed in the background or not, so only the summation order
// differs (measured: loss 3e-10, gradients up to 2e-9 relative; when the team adopted its factors
// a step later than one thread, 8e-6 and 3e-4).
TEST(Determinism, ThreadedGradientIsRepeatableAndFollowsTheOneThreadGradient) {
  RampScene scene;
  scene.options.cells_along_longest_side = 16;
  constexpr int kSteps = 48;
  SimulationOptions threaded_options = scene.options;
  threaded_options.threads = 2;
  Simulator threaded(scene.block, scene.parameters, threaded_options);
  ASSERT_EQ(threaded.num_threads(), 2);
  const Evaluation a = ForwardAdjoint(threaded, scene.parameters, kSteps);
  const Evaluation b = ForwardAdjoint(threaded, scene.parameters, kSteps);
  EXPECT_EQ(a.loss, b.loss);
  EXPECT_EQ(ToJson(a.gradient).dump(), ToJson(b.gradient).dump());

  Simulator single(scene.block, scene.parameters, scene.options);
  const Evaluation c = ForwardAdjoint(single, scene.parameters, kSteps);
  EXPECT_NEAR(a.loss, c.loss, 1e-7 * std::abs(c.loss));
  const auto expect_close = [](double threaded_value, double single_value, const char* name) {
    EXPECT_NEAR(threaded_value, single_value, 1e-6 * std::abs(single_value)) << name;
  };
  expect_close(a.gradient.youngs_modulus, c.gradient.youngs_modulus, "youngs_modulus");
  expect_close(a.gradient.poisson_ratio, c.gradient.poisson_ratio, "poisson_ratio");
  expect_close(a.gradient.density, c.gradient.density, "density");
  expect_close(a.gradient.stiffness_damping, c.gradient.stiffness_damping, "stiffness_damping");
  expect_close(a.gradient.friction_coefficient, c.gradient.friction_coefficient,
               "friction_coefficient");
  for (int i = 0; i < 3; ++i) {
    expect_close(a.gradient.gravity[i], c.gradient.gravity[i], "gravity");
    expect_close(a.gradient.initial_velocity[i], c.gradient.initial_velocity[i],
                 "initial_velocity");
  }
}

}  // namespace
}  // namespace softid::fem
