// The adjoint pass preconditions each step with the factor its forward step was solved with
// (SimulationOptions::adjoint_reuses_forward_factors): on a run whose forward pass renews its
// factor, the backward pass then factorises less, and the gradient is the same to the adjoint's
// tolerance.
#include <gtest/gtest.h>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"
#include "tests/core/fem/simulator_test_util.h"

namespace softid::fem {
namespace {

struct BackwardRun {
  ParameterGradient gradient;
  int forward_factorizations = 0;
  int backward_factorizations = 0;
};

// A soft block dropped onto the ground: the impact renews the forward's factor. The loss is the
// sum of the nodes' heights over the run.
BackwardRun RunBackward(bool reuse) {
  PhysicalParameters p;
  p.youngs_modulus = 2e4;
  p.density = 300.0;
  p.stiffness_damping = 0.002;
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), -0.03};
  p.initial_velocity = Eigen::Vector3d(0.3, 0.0, -1.5);
  SimulationOptions options;
  options.cells_along_longest_side = 12;
  options.time_step = 1.0 / 240.0;
  // Tight, so that the two preconditioners leave the same solution: at 1e-10 the spin gradient
  // (tiny here: nothing spins) differed by 3e-6 of itself between them.
  options.adjoint_linear_tolerance = 1e-12;
  options.adjoint_reuses_forward_factors = reuse;
  Simulator sim(geometry::MakeBox(Eigen::Vector3d(0.12, 0.08, 0.05), 0.02), p, options);
  BackwardRun run;
  const int after_parameters = sim.num_factorizations();
  std::vector<SimulationState> states = {sim.state()};
  // 0.3 s: the impact and the rebound. (Over the first 0.2 s alone the saving depended on which
  // step the forward's one renewal was adopted at: 1 vs 2 factorisations either way.)
  for (int k = 0; k < 72; ++k) {
    EXPECT_TRUE(sim.Step().converged);
    states.push_back(sim.state());
  }
  run.forward_factorizations = sim.num_factorizations() - after_parameters;
  const int before_backward = sim.num_factorizations();
  EXPECT_TRUE(testing::BackpropagateHeights(sim, states, &run.gradient));
  run.backward_factorizations = sim.num_factorizations() - before_backward;
  return run;
}

TEST(AdjointFactorReuse, BackwardPassFactorisesLessAndGivesTheSameGradient) {
  const BackwardRun own = RunBackward(false);
  const BackwardRun reused = RunBackward(true);
  ASSERT_GE(own.forward_factorizations, 1);  // the scene renews the forward's factor
  EXPECT_EQ(reused.forward_factorizations, own.forward_factorizations);
  EXPECT_LT(reused.backward_factorizations, own.backward_factorizations);
  testing::ExpectGradientsNear(reused.gradient, own.gradient, 1e-6);
  RecordProperty("forward_factorizations", own.forward_factorizations);
  RecordProperty("backward_factorizations_own", own.backward_factorizations);
  RecordProperty("backward_factorizations_reused", reused.backward_factorizations);
}

}  // namespace
}  // namespace softid::fem
