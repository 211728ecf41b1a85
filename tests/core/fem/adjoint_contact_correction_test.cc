// The adjoint's transposed solves use the preconditioner's contact correction
// (SimulationOptions::contact_correction, subdomain_correction.h) too: on a block landing with
// friction the backward pass needs fewer GMRES iterations, and the gradient is the same to the
// adjoint's tolerance.
#include <gtest/gtest.h>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"
#include "tests/core/fem/simulator_test_util.h"

namespace softid::fem {
namespace {

PhysicalParameters LandingWithFriction() {
  PhysicalParameters p;
  p.youngs_modulus = 2e4;
  p.density = 300.0;
  p.friction_coefficient = 0.5;
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), -0.03};
  p.initial_velocity = Eigen::Vector3d(0.6, 0.0, -1.5);
  return p;
}

Simulator MakeSimulator(bool correction) {
  SimulationOptions options;
  options.cells_along_longest_side = 12;
  options.time_step = 1.0 / 240.0;
  options.adjoint_linear_tolerance = 1e-10;
  options.contact_correction = correction;
  return Simulator(geometry::MakeBox(Eigen::Vector3d(0.12, 0.08, 0.05), 0.02),
                   LandingWithFriction(), options);
}

struct Backward {
  ParameterGradient gradient;
  int iterations = 0;
};

Backward RunBackward(Simulator& sim, const std::vector<SimulationState>& states) {
  Backward out;
  const int before = sim.backward_linear_iterations();
  EXPECT_TRUE(testing::BackpropagateHeights(sim, states, &out.gradient));
  out.iterations = sim.backward_linear_iterations() - before;
  return out;
}

TEST(AdjointContactCorrection, FewerIterationsSameGradient) {
  // One forward pass (with the correction) gives the states both backward passes run over.
  Simulator corrected_sim = MakeSimulator(true);
  std::vector<SimulationState> states = {corrected_sim.state()};
  for (int k = 0; k < 72; ++k) {  // 0.3 s: the landing, the slide
    EXPECT_TRUE(corrected_sim.Step().converged);
    states.push_back(corrected_sim.state());
  }
  Simulator plain_sim = MakeSimulator(false);
  const Backward corrected = RunBackward(corrected_sim, states);
  const Backward plain = RunBackward(plain_sim, states);
  EXPECT_LT(corrected.iterations, 0.8 * plain.iterations);
  testing::ExpectGradientsNear(corrected.gradient, plain.gradient, 1e-6);
  RecordProperty("iterations_corrected", corrected.iterations);
  RecordProperty("iterations_plain", plain.iterations);
}

}  // namespace
}  // namespace softid::fem
