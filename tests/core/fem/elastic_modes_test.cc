#include "core/fem/elastic_modes.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/geometry/primitives.h"
#include "tests/core/fem/simulator_test_util.h"

namespace softid::fem {
namespace {

PhysicalParameters BarMaterial() {
  PhysicalParameters p;
  p.youngs_modulus = 1e5;
  p.poisson_ratio = 0.01;  // beam theory's frequency has (almost) no Poisson effect
  p.density = 1000.0;
  return p;
}

ElasticModes ModesOf(Simulator& sim, int count = 4) {
  Result<ElasticModes> modes = ComputeElasticModes(sim, {count});
  EXPECT_TRUE(modes.ok()) << modes.status().message();
  return modes.ok() ? *modes : ElasticModes{};
}

// With incompatible modes, 4 cells through the thickness resolve bending: the cantilever's first
// frequency is within 3 % of Euler-Bernoulli's (a slender bar, L / b = 10, for which Timoshenko's
// shear and rotary-inertia correction lowers it by about 1 %). The square section bends alike
// about both axes, so the first two modes coincide (to 0.1 %: the grid's cells are not placed
// symmetrically about the bar's axis).
TEST(ElasticModes, ClampedBarMatchesBeamTheory) {
  const testing::BarSetup bar;
  SimulationOptions options;
  options.element = ElementFormulation::kIncompatibleModes;
  Simulator sim = testing::MakeClampedBar(bar, BarMaterial(), options);
  const ElasticModes modes = ModesOf(sim);
  ASSERT_EQ(modes.frequencies_hz.size(), 4u);
  EXPECT_EQ(modes.rigid_modes, 0);
  const double expected = testing::BarFirstFrequency(bar, BarMaterial());
  EXPECT_NEAR(modes.frequencies_hz[0], expected, 0.03 * expected);
  EXPECT_NEAR(modes.frequencies_hz[1], modes.frequencies_hz[0], 1e-3 * expected);
}

// Trilinear elements lock in bending (parasitic shear): on the same grid the bar is stiffer than
// with incompatible modes (1.5 % in frequency at 4 cells through the thickness), and more so on
// a coarser grid.
TEST(ElasticModes, TrilinearElementsAreStifferInBending) {
  const auto first_frequency = [](ElementFormulation element, int cells) {
    testing::BarSetup bar;
    bar.cells_through_thickness = cells;
    SimulationOptions options;
    options.element = element;
    Simulator sim = testing::MakeClampedBar(bar, BarMaterial(), options);
    return ModesOf(sim, 1).frequencies_hz.at(0);
  };
  const double incompatible = first_frequency(ElementFormulation::kIncompatibleModes, 4);
  const double coarse = first_frequency(ElementFormulation::kTrilinear, 2);
  const double fine = first_frequency(ElementFormulation::kTrilinear, 4);
  EXPECT_GT(fine, 1.005 * incompatible);
  EXPECT_GT(coarse, fine);
}

// A free body has six rigid modes at (numerically) zero frequency, and with the Poisson ratio
// fixed every elastic frequency scales as sqrt(E).
TEST(ElasticModes, FreeBodyHasSixRigidModesAndScalesWithModulus) {
  const geometry::TriangleMesh box = geometry::MakeBox(Eigen::Vector3d(0.1, 0.06, 0.04), 0.01);
  PhysicalParameters p;
  p.youngs_modulus = 4e4;
  p.poisson_ratio = 0.4;
  p.density = 300.0;
  p.ground.reset();
  SimulationOptions options;
  options.cells_along_longest_side = 10;
  Simulator soft(box, p, options);
  p.youngs_modulus *= 4.0;
  Simulator stiff(box, p, options);
  const ElasticModes a = ModesOf(soft), b = ModesOf(stiff);
  ASSERT_EQ(a.frequencies_hz.size(), 4u);
  ASSERT_EQ(b.frequencies_hz.size(), 4u);
  EXPECT_EQ(a.rigid_modes, 6);
  EXPECT_LT(a.rigid_frequency_hz, 1e-3 * a.frequencies_hz[0]);
  EXPECT_GT(a.frequencies_hz[0], 1.0);
  for (int i = 0; i < 4; ++i)
    EXPECT_NEAR(b.frequencies_hz[i], 2.0 * a.frequencies_hz[i], 1e-6 * b.frequencies_hz[i]);
  EXPECT_NEAR(ExpectedFittedModulus(4e4, a.frequencies_hz[0], b.frequencies_hz[0]), 16e4, 1e-3);
}

TEST(ElasticModes, RejectsACountBelowOne) {
  Simulator sim = testing::MakeClampedBar(testing::BarSetup{}, BarMaterial(), SimulationOptions());
  const Result<ElasticModes> modes = ComputeElasticModes(sim, {0});
  ASSERT_FALSE(modes.ok());
  EXPECT_NE(modes.status().message().find("count = 0"), std::string::npos);
}

}  // namespace
}  // namespace softid::fem
