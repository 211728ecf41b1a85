#include "core/fem/simulator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>

#include "core/geometry/primitives.h"
#include "core/geometry/triangle_mesh.h"
#include "tests/core/fem/simulator_test_util.h"

namespace softid::fem {
namespace {

using geometry::MakeBox;
using geometry::MakeSphere;
using geometry::MakeTorus;
using testing::BarSetup;
using testing::MakeClampedBar;
using testing::PeakTimes;
using testing::TipDeflection;

constexpr double kPi = std::numbers::pi;

SimulationOptions AverageAcceleration(double dt) {
  SimulationOptions options;
  options.time_step = dt;
  options.newmark_beta = 0.25;
  options.newmark_gamma = 0.5;
  return options;
}

// Free fall before contact follows x0 + v0 t + g t^2 / 2 exactly (average-acceleration Newmark).
TEST(Simulator, FreeFallIsExactParabola) {
  PhysicalParameters p;
  p.youngs_modulus = 5e4;
  p.gravity = Eigen::Vector3d(0.3, -0.2, -9.81);
  p.initial_velocity = Eigen::Vector3d(1.0, 0.5, 2.0);
  SimulationOptions options = AverageAcceleration(1.0 / 120.0);
  options.cells_along_longest_side = 8;
  Simulator sim(MakeSphere(0.1, 3), p, options);
  const Eigen::Vector3d x0 = sim.CentreOfMass();
  for (int step = 0; step < 60; ++step) ASSERT_FALSE(sim.Step().diverged);
  const double t = sim.state().time;
  const Eigen::Vector3d expected = x0 + p.initial_velocity * t + 0.5 * p.gravity * t * t;
  const double travelled = (expected - x0).norm();
  EXPECT_LT((sim.CentreOfMass() - expected).norm(), 1e-9 * travelled);
  // Every node moves rigidly with the centre of mass.
  const Eigen::Vector3d shift = expected - x0;
  for (int i = 0; i < sim.hex_mesh().NumNodes(); ++i) {
    EXPECT_LT((sim.state().u.segment<3>(3 * i) - shift).norm(), 1e-9 * travelled);
  }
}

// Generalized-alpha is second-order accurate (halving the step quarters the error) where Newmark
// with gamma = 0.6 is first-order (halves it): the tip of a clamped bar swinging under gravity
// for 0.25 s (about one bending period), against a run at a 32x finer step.
TEST(Simulator, GeneralizedAlphaIsSecondOrderAccurate) {
  const testing::BarSetup bar{0.4, 0.05, 2};
  PhysicalParameters p;
  p.youngs_modulus = 2e5;
  p.density = 1000.0;
  const auto tip_at = [&](double rho_infinity, int steps) {
    SimulationOptions options;
    if (rho_infinity >= 0.0) options.UseGeneralizedAlpha(rho_infinity);
    options.time_step = 0.25 / steps;
    options.newton_tolerance = 1e-10;
    options.linear_tolerance = 1e-10;
    Simulator sim = testing::MakeClampedBar(bar, p, options);
    for (int step = 0; step < steps; ++step) EXPECT_TRUE(sim.Step().converged);
    return TipDeflection(sim, bar.length);
  };
  for (double rho_infinity : {-1.0, 0.8}) {
    const double reference = tip_at(rho_infinity, 1024);
    const double coarse = std::abs(tip_at(rho_infinity, 32) - reference);
    const double fine = std::abs(tip_at(rho_infinity, 64) - reference);
    const double finer = std::abs(tip_at(rho_infinity, 128) - reference);
    const double order = std::log2(std::sqrt(coarse * fine) / std::sqrt(fine * finer));
    if (rho_infinity < 0.0) {
      EXPECT_LT(order, 1.4) << "Newmark gamma = 0.6: errors " << coarse << " " << fine << " "
                            << finer;
    } else {
      EXPECT_GT(order, 1.7) << "generalized-alpha: errors " << coarse << " " << fine << " "
                            << finer;
    }
  }
}

// An initial angular velocity spins a free, stiff body about its centre of mass: after t it has
// turned by |omega| t, the centre has not moved, and angular momentum is conserved.
TEST(Simulator, InitialAngularVelocitySpinsAboutCentreOfMass) {
  PhysicalParameters p;
  p.youngs_modulus = 1e7;
  p.gravity.setZero();
  p.initial_angular_velocity = Eigen::Vector3d(0.0, 0.0, 2.0);
  SimulationOptions options = AverageAcceleration(1.0 / 480.0);
  options.cells_along_longest_side = 8;
  options.linear_tolerance = 1e-10;
  options.newton_tolerance = 1e-8;
  Simulator sim(MakeBox(Eigen::Vector3d(0.2, 0.1, 0.05), 0.02), p, options);
  const Eigen::Vector3d centre = sim.CentreOfMass();
  auto angular_momentum = [&] {
    Eigen::Vector3d l = Eigen::Vector3d::Zero();
    for (int i = 0; i < sim.hex_mesh().NumNodes(); ++i) {
      const Eigen::Vector3d x = sim.hex_mesh().rest_positions[i] + sim.state().u.segment<3>(3 * i);
      l += sim.lumped_mass()[i] * (x - centre).cross(sim.state().v.segment<3>(3 * i));
    }
    return l;
  };
  const Eigen::Vector3d l0 = angular_momentum();
  for (int step = 0; step < 240; ++step) ASSERT_FALSE(sim.Step().diverged);  // 0.5 s: 1 rad
  const Eigen::Matrix3d turned =
      Eigen::AngleAxisd(2.0 * sim.state().time, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  double worst = 0.0;
  for (int i = 0; i < sim.hex_mesh().NumNodes(); ++i) {
    const Eigen::Vector3d& rest = sim.hex_mesh().rest_positions[i];
    const Eigen::Vector3d expected = centre + turned * (rest - centre);
    worst = std::max(worst, (rest + sim.state().u.segment<3>(3 * i) - expected).norm());
  }
  EXPECT_LT(worst, 1e-3 * 0.1);  // 0.1 mm on a body spinning 10 cm corners through 1 rad
  EXPECT_LT((sim.CentreOfMass() - centre).norm(), 1e-9);
  EXPECT_LT((angular_momentum() - l0).norm(), 1e-3 * l0.norm());
}

// Newton's estimate-first shortcut (a step that follows a one-update step first tries the
// preconditioner's estimate alone) changes the work, not the motion: a tumbling torus that falls
// and bounces ends where the full Newton iteration puts it, to within Newton's tolerance, with
// the tangent assembled in far fewer steps.
TEST(Simulator, EstimateFirstStepsFollowTheFullNewtonIteration) {
  PhysicalParameters p;
  p.youngs_modulus = 2e5;
  p.initial_velocity = Eigen::Vector3d(0.3, 0.0, -0.5);
  p.initial_angular_velocity = Eigen::Vector3d(0.5, 1.0, 0.0);
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), -0.2};
  auto run = [&](bool estimate_first, int* tangent_assemblies) {
    SimulationOptions options;
    options.cells_along_longest_side = 10;
    options.newton_estimate_first = estimate_first;
    Simulator sim(MakeTorus(0.1, 0.04, 24, 12), p, options);
    *tangent_assemblies = 0;
    for (int step = 0; step < 120; ++step) {
      const StepSummary summary = sim.Step();
      EXPECT_TRUE(summary.converged) << "step " << step;
      *tangent_assemblies += summary.tangent_assemblies;
    }
    return sim.state();
  };
  int shortcut_assemblies = 0, full_assemblies = 0;
  const SimulationState shortcut = run(true, &shortcut_assemblies);
  const SimulationState full = run(false, &full_assemblies);
  const double h = 0.28 / 10;  // cell size of the torus's 0.28 m side
  EXPECT_LT((shortcut.u - full.u).lpNorm<Eigen::Infinity>(), 1e-3 * h);
  EXPECT_GT(full.u.lpNorm<Eigen::Infinity>(), 0.1);  // it fell, bounced and tumbled
  // Free flight (~30 steps) and the gentle end of the bounce skip the tangent.
  EXPECT_LT(shortcut_assemblies, full_assemblies - 15)
      << shortcut_assemblies << " vs " << full_assemblies;
}

// The lumped mass equals density x volume of a sphere and a torus within 2 %.
TEST(Simulator, MassIsDensityTimesVolume) {
  PhysicalParameters p;
  p.density = 800.0;
  SimulationOptions options;
  options.cells_along_longest_side = 16;
  const double r = 0.1;
  Simulator sphere(MakeSphere(r, 4), p, options);
  EXPECT_NEAR(sphere.total_mass(), p.density * 4.0 / 3.0 * kPi * r * r * r,
              0.02 * p.density * 4.0 / 3.0 * kPi * r * r * r);
  const double big = 0.1, small = 0.035;
  options.cells_along_longest_side = 32;  // 5 cells across the tube
  Simulator torus(MakeTorus(big, small, 64, 32), p, options);
  const double torus_volume = 2.0 * kPi * kPi * big * small * small;
  EXPECT_NEAR(torus.total_mass(), p.density * torus_volume, 0.02 * p.density * torus_volume);
}

// The lumped masses carry the body's moment of inertia, not only its mass: a sphere's polar
// moment sum m_i |x_i - c|^2 is 3/5 M r^2 within 4 % on a coarse grid (6 cells across), where cut
// cells are most of the body. Sharing each cut cell's mass uniformly over its corners puts
// material on its empty corners and overshoots this by 15 % (octant shares: 2.4 %). Lumping still
// moves a cut cell's mass out to its nodes: with the cut cells shaped by the distance sampled
// every quarter cell (cut_cell_samples 4), which keeps the material the corners' trilinear
// distance loses at a curved surface, the overshoot is 6.1 % at 6 cells and 1.2 % at 12.
TEST(Simulator, LumpedMassKeepsMomentOfInertia) {
  PhysicalParameters p;
  p.density = 800.0;
  const double r = 0.1;
  const auto polar_over_expected = [&](int cells, int samples) {
    SimulationOptions options;
    options.cells_along_longest_side = cells;
    options.cut_cell_samples = samples;
    Simulator sphere(MakeSphere(r, 4), p, options);
    const Eigen::Vector3d centre = sphere.CentreOfMass();
    double polar = 0.0;
    for (int i = 0; i < sphere.hex_mesh().NumNodes(); ++i)
      polar +=
          sphere.lumped_mass()[i] * (sphere.hex_mesh().rest_positions[i] - centre).squaredNorm();
    return polar / (0.6 * sphere.total_mass() * r * r);
  };
  EXPECT_NEAR(polar_over_expected(6, 1), 1.0, 0.04);
  const double coarse = polar_over_expected(6, 4) - 1.0, fine = polar_over_expected(12, 4) - 1.0;
  EXPECT_GT(coarse, 0.0);
  EXPECT_LT(coarse, 0.08);
  EXPECT_LT(std::abs(fine), 0.5 * coarse);
}

// A large rigid rotation creates no elastic force: the body keeps its rotated pose, at rest.
TEST(Simulator, RigidRotationCreatesNoElasticForce) {
  PhysicalParameters p;
  p.gravity.setZero();
  SimulationOptions options;
  options.cells_along_longest_side = 8;
  Simulator sim(MakeBox(Eigen::Vector3d(0.2, 0.1, 0.05), 0.02), p, options);
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(2.0, Eigen::Vector3d(1.0, 2.0, 0.5).normalized()).toRotationMatrix();
  SimulationState state = sim.state();
  for (int i = 0; i < sim.hex_mesh().NumNodes(); ++i) {
    const Eigen::Vector3d& x = sim.hex_mesh().rest_positions[i];
    state.u.segment<3>(3 * i) = rotation * x - x;
  }
  state.v.setZero();
  state.a.setZero();
  sim.SetState(state);
  EXPECT_LT(sim.ComputeEnergies().elastic, 1e-20);
  for (int step = 0; step < 10; ++step) ASSERT_FALSE(sim.Step().diverged);
  EXPECT_LT((sim.state().u - state.u).lpNorm<Eigen::Infinity>(), 1e-12);
  EXPECT_LT(sim.state().v.lpNorm<Eigen::Infinity>(), 1e-10);
}

// Static tip deflection of a cantilever approaches Euler-Bernoulli rho g A L^4 / (8 E I) (within
// 10 % at 4 cells through the thickness), and the error shrinks as the grid refines.
TEST(Simulator, CantileverMatchesEulerBernoulli) {
  PhysicalParameters p;
  p.youngs_modulus = 1e8;
  p.poisson_ratio = 0.3;
  p.density = 1000.0;
  BarSetup bar;
  const double b = bar.thickness, length = bar.length;
  const double area = b * b, inertia = b * b * b * b / 12.0;
  const double expected =
      p.density * 9.81 * area * std::pow(length, 4) / (8.0 * p.youngs_modulus * inertia);
  std::vector<double> errors;
  for (int cells : {2, 4}) {
    bar.cells_through_thickness = cells;
    Simulator sim = MakeClampedBar(bar, p, SimulationOptions());
    const StepSummary summary = sim.SolveStatic();
    ASSERT_TRUE(summary.converged);
    const double deflection = -TipDeflection(sim, length);
    errors.push_back(std::abs(deflection - expected) / expected);
    RecordProperty("error_" + std::to_string(cells), std::to_string(errors.back()));
  }
  EXPECT_LT(errors.back(), 0.10);
  EXPECT_LT(errors[1], errors[0]);
}

// A clamp over part of a body holds it up to the clamp's face at every resolution: the grid puts
// a plane of nodes there (without that, a 24 cm bar clamped over 2 cm was held over 2 cm on 24
// and 48 cells and 1.5 cm on 32).
TEST(Simulator, ClampHoldsTheBodyUpToItsFaceOnEveryGrid) {
  const geometry::TriangleMesh bar = geometry::MakeBox(Eigen::Vector3d(0.24, 0.04, 0.04), 0.01);
  const double face_x = -0.12 + 0.02;
  const Eigen::AlignedBox3d clamp(Eigen::Vector3d(-0.2, -0.1, -0.1),
                                  Eigen::Vector3d(face_x, 0.1, 0.1));
  PhysicalParameters p;
  p.youngs_modulus = 1e5;
  for (const int cells : {12, 16, 24, 32, 48}) {
    SimulationOptions options;
    options.cells_along_longest_side = cells;
    const Simulator sim(bar, p, options, clamp);
    double held_to = -std::numeric_limits<double>::infinity();
    double free_from = std::numeric_limits<double>::infinity();
    for (int i = 0; i < sim.hex_mesh().NumNodes(); ++i) {
      const double x = sim.hex_mesh().rest_positions[i].x();
      if (sim.is_fixed(i)) {
        held_to = std::max(held_to, x);
      } else {
        free_from = std::min(free_from, x);
      }
    }
    EXPECT_NEAR(held_to, face_x, 1e-9) << cells << " cells";
    EXPECT_NEAR(free_from, face_x + sim.hex_mesh().CellSize(), 1e-9) << cells << " cells";
  }
}

// Free vibration of the cantilever: first bending frequency within 10 % of
// 1.875^2 / (2 pi L^2) sqrt(E I / (rho A)); undamped average-acceleration Newmark keeps the
// total energy within 1 % over 1000 steps.
TEST(Simulator, CantileverFrequencyAndEnergyConservation) {
  PhysicalParameters p;
  p.youngs_modulus = 1e8;
  p.density = 1000.0;
  BarSetup bar;
  const double length = bar.length;
  const double frequency = testing::BarFirstFrequency(bar, p);
  const double dt = 1.0 / (frequency * 200.0);
  Simulator sim = MakeClampedBar(bar, p, AverageAcceleration(dt));
  const double energy0 = sim.ComputeEnergies().Total();
  double max_kinetic = 0.0, max_drift = 0.0;
  std::vector<double> tip;
  for (int step = 0; step < 1000; ++step) {
    ASSERT_FALSE(sim.Step().diverged);
    tip.push_back(TipDeflection(sim, length));
    const Energies e = sim.ComputeEnergies();
    max_kinetic = std::max(max_kinetic, e.kinetic);
    max_drift = std::max(max_drift, std::abs(e.Total() - energy0));
  }
  EXPECT_LT(max_drift, 0.01 * max_kinetic);
  const std::vector<double> peaks = PeakTimes(tip, dt);
  ASSERT_GE(peaks.size(), 3u);
  const double period = (peaks.back() - peaks.front()) / static_cast<double>(peaks.size() - 1);
  EXPECT_NEAR(1.0 / period, frequency, 0.10 * frequency);
}

// Rayleigh damping: the logarithmic decrement of the bar's vibration is within 5 % of
// 2 pi zeta / sqrt(1 - zeta^2) with zeta = alpha / (2 omega) + beta omega / 2.
TEST(Simulator, RayleighDampingLogDecrement) {
  PhysicalParameters p;
  p.youngs_modulus = 1e8;
  p.density = 1000.0;
  p.mass_damping = 0.3;
  p.stiffness_damping = 0.002;
  BarSetup bar;
  const double length = bar.length;
  const double frequency = testing::BarFirstFrequency(bar, p);
  const double dt = 1.0 / (frequency * 200.0);
  Simulator sim = MakeClampedBar(bar, p, AverageAcceleration(dt));
  // The static deflection is the centre of the oscillation.
  Simulator statics = MakeClampedBar(bar, p, SimulationOptions());
  ASSERT_TRUE(statics.SolveStatic().converged);
  const double centre = TipDeflection(statics, length);
  std::vector<double> signal;
  for (int step = 0; step < 1000; ++step) {
    ASSERT_FALSE(sim.Step().diverged);
    signal.push_back(TipDeflection(sim, length) - centre);
  }
  std::vector<double> amplitudes;
  const std::vector<double> peaks = PeakTimes(signal, dt, &amplitudes);
  ASSERT_GE(peaks.size(), 4u);
  const double period = (peaks.back() - peaks.front()) / static_cast<double>(peaks.size() - 1);
  const double omega = 2 * kPi / period;
  const double zeta = p.mass_damping / (2 * omega) + p.stiffness_damping * omega / 2;
  const double expected = 2 * kPi * zeta / std::sqrt(1 - zeta * zeta);
  const double measured =
      std::log(amplitudes.front() / amplitudes.back()) / static_cast<double>(amplitudes.size() - 1);
  EXPECT_NEAR(measured, expected, 0.05 * expected);
}

// A ball dropped onto the ground comes to rest there without drift or jitter.
TEST(Simulator, BallSettlesOnGround) {
  PhysicalParameters p;
  p.youngs_modulus = 2e4;
  p.density = 500.0;
  // Damped well enough (zeta ~ 0.3 for the ~5 Hz bounce on its Hertzian compliance) that 3 s
  // suffice; jitter or drift would show up as residual motion.
  p.mass_damping = 5.0;
  p.stiffness_damping = 0.01;
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
  SimulationOptions options;
  options.cells_along_longest_side = 8;
  options.time_step = 1.0 / 240.0;
  const double r = 0.1;
  geometry::TriangleMesh ball = MakeSphere(r, 3);
  for (auto& v : ball.vertices) v.z() += r + 0.02;
  Simulator sim(ball, p, options);
  for (int step = 0; step < 720; ++step) ASSERT_FALSE(sim.Step().diverged);  // 3 s
  const Eigen::Vector3d settled = sim.CentreOfMass();
  double max_speed = 0.0;
  for (int step = 0; step < 240; ++step) {  // 1 s more
    ASSERT_FALSE(sim.Step().diverged);
    max_speed = std::max(max_speed, sim.CentreOfMassVelocity().norm());
  }
  EXPECT_LT((sim.CentreOfMass() - settled).norm(), 1e-3 * r);
  EXPECT_LT(max_speed, 1e-3);
  EXPECT_LT(std::abs(settled.x()) + std::abs(settled.y()), 1e-6);
  // Resting on the floor: the penalty lets its lowest point sink p / k (peak Hertz pressure ~7 kPa
  // over k = 100 E / L = 1e7 Pa/m: ~0.7 mm), and its centre is lowered by the Hertzian flattening.
  double lowest = 1.0;
  for (const auto& x : sim.SurfacePositions()) lowest = std::min(lowest, x.z());
  EXPECT_LT(lowest, 0.0);
  EXPECT_GT(lowest, -0.02 * r);
  EXPECT_LT(settled.z(), r);
  EXPECT_GT(settled.z(), 0.8 * r);
}

// A thrown block that lands on a corner: the surface seen (rendered) stops where the contact
// stops it. At 16 cells the box 0.1 x 0.06 x 0.04 m is cut in y and z, and its corner cells hold
// 0.56 of a cell, but under a quarter by the trilinear signed distance of their corners alone;
// clamped into the neighbouring element, their contact points stop 0.7 cells above the rendered
// corner, which moves with its own element and sinks 9 mm into the floor at the landing.
// CalculiX on the same throw (node-to-surface penalty, same k) lets the corner sink 0.3 mm. Two
// remedies: contact points clamped at most half a cell (SimulationOptions::max_force_clamp_cells),
// or cut cells shaped by a finer sampling of the distance (cut_cell_samples), which counts the
// corner cells as full as they are.
double LowestPointOfALandingCorner(SimulationOptions options) {
  PhysicalParameters p;
  p.youngs_modulus = 4e4;
  p.poisson_ratio = 0.4;
  p.density = 300.0;
  p.contact_stiffness = 1.2e8;  // p / k = 0.1 mm at 12 kPa
  p.initial_velocity = Eigen::Vector3d(0.3, 0.0, 0.6);
  p.initial_angular_velocity = Eigen::Vector3d(4.0, 3.0, 8.0);
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
  options.cells_along_longest_side = 16;
  options.element = ElementFormulation::kIncompatibleModes;
  options.time_step = 1.0 / 960.0;
  geometry::TriangleMesh block = MakeBox(Eigen::Vector3d(0.1, 0.06, 0.04), 0.01);
  for (auto& v : block.vertices) v.z() += 0.1;
  Simulator sim(block, p, options);
  double lowest = 1.0;
  for (int step = 0; step < 230; ++step) {  // 0.24 s: the first landing is at about 0.18 s
    EXPECT_FALSE(sim.Step().diverged) << "step " << step;
    for (const auto& x : sim.SurfacePositions()) lowest = std::min(lowest, x.z());
  }
  return lowest / sim.hex_mesh().CellSize();
}

TEST(Simulator, ALandingCornerSinksOnlyAsFarAsTheContactLets) {
  SimulationOptions clamped;
  clamped.cut_cell_samples = 1;
  clamped.max_force_clamp_cells = 0.5;
  SimulationOptions sampled;
  sampled.cut_cell_samples = 4;
  sampled.max_force_clamp_cells = std::numeric_limits<double>::infinity();
  SimulationOptions neither;
  neither.cut_cell_samples = 1;
  neither.max_force_clamp_cells = std::numeric_limits<double>::infinity();
  EXPECT_LT(LowestPointOfALandingCorner(neither), -0.5) << "the premise: the corner sinks";
  for (const SimulationOptions& options : {clamped, sampled}) {
    const double lowest_cells = LowestPointOfALandingCorner(options);
    EXPECT_LT(lowest_cells, 0.0) << "it did land";
    EXPECT_GT(lowest_cells, -0.1) << "the rendered corner sank " << -lowest_cells
                                  << " cells into the floor (samples " << options.cut_cell_samples
                                  << ", clamp " << options.max_force_clamp_cells << ")";
  }
}

// A block on a ramp steeper than atan(mu) slides with g (sin theta - mu cos theta) within 5 %;
// on a shallower one it sticks: regularised Coulomb friction lets it creep no faster than
// eps tan(theta) / mu. The ramp is modelled by tilting gravity.
struct RampMotion {
  double acceleration = 0.0;  // along the slope [m/s^2]
  double max_speed = 0.0;     // along the slope, over the measurement window [m/s]
};

// A stiff block on a ramp of angle theta (gravity tilted, ground z = 0).
PhysicalParameters RampParameters(double theta, double mu) {
  PhysicalParameters p;
  p.youngs_modulus = 2e5;
  p.density = 500.0;
  p.friction_coefficient = mu;
  p.gravity = 9.81 * Eigen::Vector3d(std::sin(theta), 0.0, -std::cos(theta));
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
  return p;
}

RampMotion SlideOnRamp(double theta, double mu) {
  const PhysicalParameters p = RampParameters(theta, mu);
  SimulationOptions options;
  options.cells_along_longest_side = 8;
  options.time_step = 1.0 / 240.0;
  geometry::TriangleMesh block = MakeBox(Eigen::Vector3d(0.1, 0.1, 0.05), 0.0125);
  for (auto& v : block.vertices) v.z() += 0.026;  // dropped from 1 mm
  Simulator sim(block, p, options);
  for (int step = 0; step < 48; ++step) EXPECT_FALSE(sim.Step().diverged);  // contact settles
  RampMotion motion;
  const double v0 = sim.CentreOfMassVelocity().x();
  const double t0 = sim.state().time;
  for (int step = 0; step < 96; ++step) {
    EXPECT_FALSE(sim.Step().diverged);
    motion.max_speed = std::max(motion.max_speed, std::abs(sim.CentreOfMassVelocity().x()));
  }
  motion.acceleration = (sim.CentreOfMassVelocity().x() - v0) / (sim.state().time - t0);
  return motion;
}

TEST(Simulator, BlockSlidesDownSteepRamp) {
  const double theta = 30.0 * kPi / 180.0, mu = 0.3;
  const double expected = 9.81 * (std::sin(theta) - mu * std::cos(theta));
  EXPECT_NEAR(SlideOnRamp(theta, mu).acceleration, expected, 0.05 * expected);
}

TEST(Simulator, BlockSticksOnShallowRamp) {
  const double theta = 10.0 * kPi / 180.0, mu = 0.3;
  const double creep = SimulationOptions().friction_velocity_scale * std::tan(theta) / mu;
  EXPECT_LT(SlideOnRamp(theta, mu).max_speed, 3.0 * creep);
}

// A block sliding down a ramp with strong friction (mu = 0.8 > tan 30 deg) decelerates at
// g (mu cos - sin) and comes to rest. Bringing sliding points to rest is where Newton with the
// exact friction tangent cycled between forward and reversed slip (106 of 120 steps of a block
// landing on a ramp never met the tolerance, and the trajectory then depended on the iteration
// path): every step must converge.
TEST(Simulator, BlockStoppedByStrongFrictionConvergesEveryStep) {
  const double theta = 30.0 * kPi / 180.0, mu = 0.8, v0 = 0.3;
  PhysicalParameters p;
  p.youngs_modulus = 4e4;
  p.density = 150.0;
  p.friction_coefficient = mu;
  p.contact_damping = 0.003;  // no chatter of the penalty contact
  p.gravity = 9.81 * Eigen::Vector3d(std::sin(theta), 0.0, -std::cos(theta));
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
  p.initial_velocity = Eigen::Vector3d(v0, 0.0, 0.0);
  SimulationOptions options;
  options.cells_along_longest_side = 8;
  options.time_step = 1.0 / 240.0;
  geometry::TriangleMesh block = MakeBox(Eigen::Vector3d(0.1, 0.08, 0.06), 0.0125);
  for (auto& v : block.vertices) v.z() += 0.031;  // 1 mm above the ramp
  Simulator sim(block, p, options);
  const double x0 = sim.CentreOfMass().x();
  int unconverged = 0;
  for (int step = 0; step < 120; ++step) {
    const StepSummary summary = sim.Step();
    ASSERT_FALSE(summary.diverged) << "step " << step;
    if (!summary.converged) ++unconverged;
  }
  EXPECT_EQ(unconverged, 0);
  // At rest: no faster than the regularised creep.
  const double creep = options.friction_velocity_scale * std::tan(theta) / mu;
  EXPECT_LT(std::abs(sim.CentreOfMassVelocity().x()), 3.0 * creep);
  // Stopping distance v0^2 / (2 g (mu cos - sin)), longer by the few mm the block slides while
  // its contact settles.
  const double distance = v0 * v0 / (2.0 * 9.81 * (mu * std::cos(theta) - std::sin(theta)));
  const double slid = sim.CentreOfMass().x() - x0;
  EXPECT_GT(slid, 0.8 * distance);
  EXPECT_LT(slid, 1.5 * distance);
}

// A 10 x 10 x 5 cm block (centred at x = 0) dropped 1 mm onto a 30 degree ramp with mu = 0.3,
// 8 cells, 96 steps (0.4 s), with the options `configure` sets: its centre of mass at the end.
Eigen::Vector3d CentreAfterSlide(const std::function<void(SimulationOptions*)>& configure) {
  const PhysicalParameters p = RampParameters(30.0 * kPi / 180.0, 0.3);
  geometry::TriangleMesh block = MakeBox(Eigen::Vector3d(0.1, 0.1, 0.05), 0.0125);
  for (auto& v : block.vertices) v.z() += 0.026;
  SimulationOptions options;
  options.cells_along_longest_side = 8;
  options.time_step = 1.0 / 240.0;
  configure(&options);
  Simulator sim(block, p, options);
  for (int step = 0; step < 96; ++step) EXPECT_TRUE(sim.Step().converged) << "step " << step;
  return sim.CentreOfMass();
}

// The Newton tangent changes the path, not the solution: where Newton converges with the exact
// friction tangent, the primal-dual one reaches the same motion.
TEST(Simulator, FrictionTangentDoesNotChangeTheSlide) {
  const Eigen::Vector3d exact =
      CentreAfterSlide([](SimulationOptions* o) { o->primal_dual_friction = false; });
  const Eigen::Vector3d primal_dual =
      CentreAfterSlide([](SimulationOptions* o) { o->primal_dual_friction = true; });
  // Both meet the same Newton tolerance (under friction a velocity tolerance of 0.05 friction
  // velocity scales): the motions agree to a few microns.
  EXPECT_LT((exact - primal_dual).norm(), 1e-5)
      << exact.transpose() << " vs " << primal_dual.transpose();
}

// The default Newton tolerance is loose in position (1e-4 h) but tight in velocity under friction,
// whose stick-slip law amplifies velocity errors: a slide ends within microns of a fully converged
// one (with 1e-4 h alone it ended 70-120 um off).
TEST(Simulator, SlideWithDefaultToleranceMatchesAConvergedOne) {
  const Eigen::Vector3d by_default = CentreAfterSlide([](SimulationOptions*) {});
  const Eigen::Vector3d converged =
      CentreAfterSlide([](SimulationOptions* o) { o->newton_tolerance = 1e-9; });
  EXPECT_GT(by_default.x(), 0.05);  // it did slide
  EXPECT_LT((by_default - converged).norm(), 5e-6)
      << by_default.transpose() << " vs " << converged.transpose();
}

// Invalid parameters are rejected with the field named.
// A soft block started with the ground plane cutting deep into it (parameters an optimiser's line
// search can reach: pillow-ramp's spurious minimum) is thrown apart by the penalty forces. The
// state stays finite (in that fit for 96 steps, the body growing to 1e18 m), so only the extent
// test can call it diverged; a cost evaluated on such states matched every point somewhere.
TEST(Simulator, BodyStretchedFarBeyondItsSizeHasDiverged) {
  PhysicalParameters p;
  p.youngs_modulus = 1960.0;
  p.density = 80.0;
  p.mass_damping = 0.16;
  p.stiffness_damping = 0.0015;
  p.gravity = Eigen::Vector3d(1.39, 0.71, -8.44);
  const geometry::TriangleMesh block = geometry::MakeBox(Eigen::Vector3d(0.3, 0.2, 0.1), 0.025);
  const Eigen::Vector3d normal = Eigen::Vector3d(0.387, 0.655, 0.649).normalized();
  double lowest = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& v : block.vertices) lowest = std::min(lowest, normal.dot(v));
  SimulationOptions options;
  options.cells_along_longest_side = 16;
  options.time_step = 1.0 / 120.0;
  // The paper's cut cells, whose box corners are light: with the distance sampled every quarter
  // cell (cut_cell_samples 4) the corners hold their mass and the same plane stretches the block
  // to 2.2 x its size only, a case the extent test need not catch.
  options.cut_cell_samples = 1;

  // Control: the plane 2 cm below the block; it lands and never comes near the limit.
  p.ground = GroundPlane{normal, lowest - 0.02};
  {
    Simulator sim(block, p, options);
    for (int step = 0; step < 60; ++step) ASSERT_FALSE(sim.Step().diverged) << step;
  }
  // The plane 7 cm into the block (its centre 4 cm above it).
  p.ground = GroundPlane{normal, lowest + 0.07};
  int diverged_at = -1;
  {
    Simulator sim(block, p, options);
    for (int step = 1; step <= 20 && diverged_at < 0; ++step) {
      if (sim.Step().diverged) diverged_at = step;
    }
  }
  EXPECT_GT(diverged_at, 0) << "the blown-up run was not reported";
  // Without the test the same run stays finite and stretches past 10x its size.
  options.max_extent_ratio = 1e30;
  Simulator unchecked(block, p, options);
  Eigen::AlignedBox3d rest;
  for (const Eigen::Vector3d& x : unchecked.hex_mesh().rest_positions) rest.extend(x);
  double largest_ratio = 0.0;
  int steps = 0;
  for (int step = 1; step <= 20; ++step, ++steps) {
    const bool failed = unchecked.Step().diverged;
    if (failed || !unchecked.state().u.allFinite()) break;
    Eigen::AlignedBox3d box;
    const HexMesh& mesh = unchecked.hex_mesh();
    for (int i = 0; i < mesh.NumNodes(); ++i)
      box.extend(mesh.rest_positions[i] + unchecked.state().u.segment<3>(3 * i));
    largest_ratio = std::max(largest_ratio, box.diagonal().norm() / rest.diagonal().norm());
  }
  std::printf(
      "plane through the block: diverged at step %d; unchecked, %d finite steps, extent up to "
      "%.3g x rest\n",
      diverged_at, steps, largest_ratio);
  EXPECT_EQ(steps, 20);  // no other divergence test fires
  EXPECT_GT(largest_ratio, 10.0);
}

TEST(Simulator, RejectsInvalidParameters) {
  PhysicalParameters p;
  p.poisson_ratio = 0.5;
  try {
    Simulator sim(MakeSphere(0.1, 2), p, SimulationOptions());
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("poisson_ratio = 0.5"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace softid::fem

namespace softid::fem {
namespace {

struct NewtonRun {
  SimulationState state;
  int linear_iterations = 0;
  int newton_iterations = 0;
  int refactorizations = 0;
};

// Runs `steps` steps, each expected to converge, and sums their solver work.
NewtonRun RunSteps(Simulator& sim, int steps) {
  NewtonRun out;
  for (int step = 0; step < steps; ++step) {
    const StepSummary summary = sim.Step();
    EXPECT_TRUE(summary.converged) << "step " << step;
    out.linear_iterations += summary.linear_iterations;
    out.newton_iterations += summary.newton_iterations;
    out.refactorizations += summary.refactorized ? 1 : 0;
  }
  out.state = sim.state();
  return out;
}

// A torus tumbling onto the ground with friction: non-symmetric contact blocks that change as
// points stick and slip.
Simulator TumblingTorusWithFriction(SimulationOptions options) {
  PhysicalParameters p;
  p.youngs_modulus = 2e5;
  p.friction_coefficient = 0.4;
  p.initial_velocity = Eigen::Vector3d(0.5, 0.0, -1.0);
  p.initial_angular_velocity = Eigen::Vector3d(1.0, 2.0, 0.0);
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), -0.06};
  options.cells_along_longest_side = 16;
  return Simulator(MakeTorus(0.1, 0.04, 24, 12), p, options);
}

// Newton's matrix-free tangent (SimulationOptions::matrix_free_newton) changes how the products
// are computed, not the motion: on a team of two, a torus tumbling onto the ground with friction
// (non-symmetric contact blocks, the preconditioner renewed in contact) and a clamped bar swinging
// down under gravity (eliminated nodes) end where the assembled tangent puts them, to far less
// than Newton's tolerance, after as many Newton and GMRES iterations and refactorisations. (The
// contact correction of the preconditioner, which only matrix-free Newton has, is off in both.)
TEST(Simulator, MatrixFreeNewtonFollowsTheAssembledTangent) {
  const auto run = [](auto make, bool matrix_free, int steps) {
    SimulationOptions options;
    options.threads = 2;
    options.matrix_free_newton = matrix_free;
    options.contact_correction = false;
    Simulator sim = make(options);
    EXPECT_EQ(sim.num_threads(), 2);
    const NewtonRun out = RunSteps(sim, steps);
    return std::make_pair(out, sim.hex_mesh().CellSize());
  };
  const auto torus = TumblingTorusWithFriction;
  const auto bar = [](SimulationOptions options) {
    PhysicalParameters p;
    p.youngs_modulus = 1e5;
    p.density = 1000.0;
    testing::BarSetup setup;
    setup.cells_through_thickness = 4;  // 640 elements: enough for a team of two
    return testing::MakeClampedBar(setup, p, options);
  };
  for (int scene = 0; scene < 2; ++scene) {
    SCOPED_TRACE(scene == 0 ? "torus" : "bar");
    const int steps = scene == 0 ? 60 : 40;
    const auto [free, h] = scene == 0 ? run(torus, true, steps) : run(bar, true, steps);
    const auto [assembled, h2] = scene == 0 ? run(torus, false, steps) : run(bar, false, steps);
    EXPECT_GT(free.state.u.lpNorm<Eigen::Infinity>(), 2.0 * h);  // it moved
    // Both meet Newton's tolerance, whose error left is ~newton_tolerance h / 10 (1e-5 h).
    // Measured 2.2e-8 m = 1.3e-6 h (torus) and 2e-13 m (bar), with equal iteration counts (the
    // torus 8e-11 m with one distance sample per cut cell's edge).
    EXPECT_LT((free.state.u - assembled.state.u).lpNorm<Eigen::Infinity>(),
              SimulationOptions().newton_tolerance * h / 10.0);
    EXPECT_NEAR(free.newton_iterations, assembled.newton_iterations,
                0.03 * assembled.newton_iterations);
    EXPECT_NEAR(free.linear_iterations, assembled.linear_iterations,
                0.05 * assembled.linear_iterations);
    EXPECT_EQ(free.refactorizations, assembled.refactorizations);
    if (scene == 0) {
      EXPECT_GT(free.refactorizations, 0);  // the factor is assembled for
    }
  }
}

// The contact correction of the preconditioner (SimulationOptions::contact_correction) changes the
// solver's work, not the motion: a torus tumbling onto the ground with friction ends within
// Newton's tolerance of the run without it, on far fewer GMRES iterations (measured 1828 vs 3470,
// final states 6e-6 m apart at h = 1.75 cm).
TEST(Simulator, ContactCorrectionSavesIterationsNotAccuracy) {
  const auto run = [](bool correction) {
    SimulationOptions options;
    options.contact_correction = correction;
    Simulator sim = TumblingTorusWithFriction(options);
    const NewtonRun out = RunSteps(sim, 60);
    return std::make_pair(out, sim.hex_mesh().CellSize());
  };
  const auto [corrected, h] = run(true);
  const auto [plain, h2] = run(false);
  EXPECT_GT(corrected.state.u.lpNorm<Eigen::Infinity>(), 2.0 * h);  // it moved
  EXPECT_LT((corrected.state.u - plain.state.u).lpNorm<Eigen::Infinity>(), 3e-3 * h);
  EXPECT_LT(corrected.linear_iterations, 0.75 * plain.linear_iterations);
}

}  // namespace
}  // namespace softid::fem
