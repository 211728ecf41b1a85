// The physics the paper's model lacks, which later work conceals in data and must rediscover:
// air drag and a spatially varying Young's modulus (friction is in simulator_test.cc).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"
#include "core/geometry/triangle_mesh.h"
#include "tests/core/fem/simulator_test_util.h"

namespace softid::fem {
namespace {

// A light ball falling under drag: m g = A_p (c1 v + c2 v^2) at terminal speed, with the
// projected area A_p taken as a quarter of the surface.
struct DragFall {
  geometry::TriangleMesh ball = geometry::MakeSphere(0.1, 3);
  PhysicalParameters parameters;
  SimulationOptions options;
  DragFall() {
    parameters.youngs_modulus = 1e5;
    parameters.density = 50.0;
    options.cells_along_longest_side = 6;
    options.time_step = 1.0 / 120.0;
  }
  double Mass() const { return Simulator(ball, parameters, options).total_mass(); }
  double ProjectedArea() const { return geometry::SurfaceArea(ball) / 4.0; }
  // Fall speed after 2 s, well past the time constant of the drags tested.
  double TerminalSpeed(double drag_linear, double drag_quadratic) {
    parameters.drag_linear = drag_linear;
    parameters.drag_quadratic = drag_quadratic;
    Simulator sim(ball, parameters, options);
    for (int step = 0; step < 240; ++step) EXPECT_FALSE(sim.Step().diverged);
    return -sim.CentreOfMassVelocity().z();
  }
};

TEST(AirDrag, LinearDragReachesTerminalSpeed) {
  DragFall fall;
  const double c1 = 30.0;  // terminal ~2 m/s, time constant ~0.2 s
  const double expected = fall.Mass() * 9.81 / (c1 * fall.ProjectedArea());
  EXPECT_NEAR(fall.TerminalSpeed(c1, 0.0), expected, 0.01 * expected);
}

TEST(AirDrag, QuadraticDragReachesTerminalSpeed) {
  DragFall fall;
  const double c2 = 4.0;
  const double expected = std::sqrt(fall.Mass() * 9.81 / (c2 * fall.ProjectedArea()));
  EXPECT_NEAR(fall.TerminalSpeed(0.0, c2), expected, 0.01 * expected);
}

// A cantilever whose clamped half is twice as stiff sags by 17/32 of the uniform bar's
// deflection (integral of M(x) (L - x) / (E(x) I) for a uniform load).
TEST(StiffnessField, SteppedCantileverMatchesBeamTheory) {
  PhysicalParameters p;
  p.youngs_modulus = 1e8;
  testing::BarSetup bar;
  Simulator uniform = testing::MakeClampedBar(bar, p, SimulationOptions());
  ASSERT_TRUE(uniform.SolveStatic().converged);
  p.stiffness_field.kind = StiffnessField::Kind::kRegions;
  p.stiffness_field.regions.push_back(
      {Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(bar.length / 2, 1, 1)),
       2.0});
  Simulator stepped = testing::MakeClampedBar(bar, p, SimulationOptions());
  ASSERT_TRUE(stepped.SolveStatic().converged);
  const double ratio =
      testing::TipDeflection(stepped, bar.length) / testing::TipDeflection(uniform, bar.length);
  EXPECT_NEAR(ratio, 17.0 / 32.0, 0.03 * 17.0 / 32.0);
}

// A log-linear field with zero gradient is the uniform material; doubling E everywhere through a
// region halves the deflection.
TEST(StiffnessField, UniformScalingHalvesDeflection) {
  PhysicalParameters p;
  p.youngs_modulus = 1e8;
  testing::BarSetup bar;
  bar.cells_through_thickness = 2;
  Simulator base = testing::MakeClampedBar(bar, p, SimulationOptions());
  ASSERT_TRUE(base.SolveStatic().converged);
  p.stiffness_field.kind = StiffnessField::Kind::kLinear;
  p.stiffness_field.log_gradient = Eigen::Vector3d::Zero();
  p.stiffness_field.origin = Eigen::Vector3d(0.3, 0, 0);
  Simulator flat = testing::MakeClampedBar(bar, p, SimulationOptions());
  ASSERT_TRUE(flat.SolveStatic().converged);
  EXPECT_NEAR(testing::TipDeflection(flat, bar.length), testing::TipDeflection(base, bar.length),
              1e-9);
  p.stiffness_field.kind = StiffnessField::Kind::kRegions;
  p.stiffness_field.regions.push_back(
      {Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1)), 2.0});
  Simulator doubled = testing::MakeClampedBar(bar, p, SimulationOptions());
  ASSERT_TRUE(doubled.SolveStatic().converged);
  EXPECT_NEAR(testing::TipDeflection(doubled, bar.length),
              0.5 * testing::TipDeflection(base, bar.length),
              1e-3 * std::abs(testing::TipDeflection(base, bar.length)));  // geometric nonlinearity
}

}  // namespace
}  // namespace softid::fem
