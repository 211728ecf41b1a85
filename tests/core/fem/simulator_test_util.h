// Helpers shared by the simulator tests: a clamped bar, time-series analysis and a backward pass.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"

namespace softid::fem::testing {

// A bar of length L along x and square cross-section b x b, clamped at x = 0.
struct BarSetup {
  double length = 0.5;      // L [m]
  double thickness = 0.05;  // b [m]
  int cells_through_thickness = 4;
};

inline Simulator MakeClampedBar(const BarSetup& bar, PhysicalParameters parameters,
                                SimulationOptions options) {
  geometry::TriangleMesh mesh = geometry::MakeBox(
      Eigen::Vector3d(bar.length, bar.thickness, bar.thickness), bar.thickness / 4);
  for (auto& v : mesh.vertices) v.x() += bar.length / 2;  // bar spans x in [0, L]
  options.cell_size = bar.thickness / bar.cells_through_thickness;
  // The box ends on the bar's end face: the nodes there are held (the simulator admits nodes on
  // the box's faces despite rounding), and no face cuts through the bar.
  const Eigen::AlignedBox3d clamp(Eigen::Vector3d(-1.0, -1.0, -1.0),
                                  Eigen::Vector3d(0.0, 1.0, 1.0));
  return Simulator(mesh, parameters, options, clamp);
}

// First bending frequency of the clamped bar, Euler-Bernoulli: 1.875^2 / (2 pi L^2) sqrt(EI / rhoA)
// [Hz], with I / A = b^2 / 12 for the square section.
inline double BarFirstFrequency(const BarSetup& bar, const PhysicalParameters& p) {
  const double b = bar.thickness, length = bar.length;
  return 1.875 * 1.875 / (2.0 * M_PI * length * length) *
         std::sqrt(p.youngs_modulus * b * b / 12.0 / p.density);
}

// Mean z displacement of the FE nodes on the free end face (x = L).
inline double TipDeflection(const Simulator& sim, double length) {
  const auto& mesh = sim.hex_mesh();
  const double h = mesh.CellSize();
  double sum = 0.0;
  int count = 0;
  for (int i = 0; i < mesh.NumNodes(); ++i) {
    if (std::abs(mesh.rest_positions[i].x() - length) < 0.01 * h) {
      sum += sim.state().u[3 * i + 2];
      ++count;
    }
  }
  return count > 0 ? sum / count : NAN;
}

// Times of the local maxima of a sampled signal (parabolic refinement).
inline std::vector<double> PeakTimes(const std::vector<double>& y, double dt,
                                     std::vector<double>* values = nullptr) {
  std::vector<double> times;
  for (size_t i = 1; i + 1 < y.size(); ++i) {
    if (y[i] > y[i - 1] && y[i] >= y[i + 1]) {
      const double denom = y[i - 1] - 2 * y[i] + y[i + 1];
      const double shift = denom != 0.0 ? 0.5 * (y[i - 1] - y[i + 1]) / denom : 0.0;
      times.push_back((static_cast<double>(i) + shift) * dt);
      if (values) values->push_back(y[i] - 0.25 * (y[i - 1] - y[i + 1]) * shift);
    }
  }
  return times;
}

// The backward pass over `states` (a forward run's, from t = 0) for the loss "sum of the nodes'
// heights over the run", into *gradient; false when a step's adjoint failed.
inline bool BackpropagateHeights(Simulator& sim, const std::vector<SimulationState>& states,
                                 ParameterGradient* gradient) {
  const int size = static_cast<int>(states[0].u.size());
  Eigen::VectorXd heights = Eigen::VectorXd::Zero(size);
  for (int i = 2; i < size; i += 3) heights[i] = 1.0;
  StateAdjoint adjoint{Eigen::VectorXd::Zero(size), Eigen::VectorXd::Zero(size),
                       Eigen::VectorXd::Zero(size)};
  bool ok = true;
  for (size_t k = states.size() - 1; k >= 1; --k) {
    adjoint.u += heights;
    ok = sim.BackpropagateStep(states[k - 1], states[k], &adjoint, gradient).ok() && ok;
  }
  sim.BackpropagateInitialState(states[0], adjoint, gradient);
  return ok;
}

// Expects every field of `actual` within `relative` of the same field of `expected` (a vector
// field as a whole: |a - e| <= relative |e|), e.g. two backward passes that differ only in how
// their linear systems were solved.
inline void ExpectGradientsNear(const ParameterGradient& actual, const ParameterGradient& expected,
                                double relative) {
  const auto scalar = [relative](const char* name, double a, double e) {
    EXPECT_NEAR(a, e, relative * std::abs(e)) << name;
  };
  const auto vector = [relative](const char* name, const Eigen::Vector3d& a,
                                 const Eigen::Vector3d& e) {
    EXPECT_LE((a - e).norm(), relative * e.norm())
        << name << ": " << a.transpose() << " vs " << e.transpose();
  };
  scalar("youngs_modulus", actual.youngs_modulus, expected.youngs_modulus);
  scalar("poisson_ratio", actual.poisson_ratio, expected.poisson_ratio);
  scalar("density", actual.density, expected.density);
  scalar("mass_damping", actual.mass_damping, expected.mass_damping);
  scalar("stiffness_damping", actual.stiffness_damping, expected.stiffness_damping);
  vector("gravity", actual.gravity, expected.gravity);
  vector("initial_velocity", actual.initial_velocity, expected.initial_velocity);
  vector("initial_angular_velocity", actual.initial_angular_velocity,
         expected.initial_angular_velocity);
  vector("initial_pose_rotation", actual.initial_pose_rotation, expected.initial_pose_rotation);
  vector("initial_pose_translation", actual.initial_pose_translation,
         expected.initial_pose_translation);
  vector("ground_normal", actual.ground_normal, expected.ground_normal);
  scalar("ground_offset", actual.ground_offset, expected.ground_offset);
  scalar("contact_stiffness", actual.contact_stiffness, expected.contact_stiffness);
  scalar("contact_damping", actual.contact_damping, expected.contact_damping);
  scalar("friction_coefficient", actual.friction_coefficient, expected.friction_coefficient);
  scalar("drag_linear", actual.drag_linear, expected.drag_linear);
  scalar("drag_quadratic", actual.drag_quadratic, expected.drag_quadratic);
  ASSERT_EQ(actual.stiffness_field.size(), expected.stiffness_field.size());
  for (size_t i = 0; i < expected.stiffness_field.size(); ++i) {
    scalar("stiffness_field", actual.stiffness_field[i], expected.stiffness_field[i]);
  }
}

}  // namespace softid::fem::testing
