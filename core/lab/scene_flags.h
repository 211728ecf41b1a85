// Command-line flags shared by softid-lab commands that run a scene: which scene, every physical
// parameter under its public name (dashes for underscores), and the simulation resolution.
#pragma once

#include <CLI/CLI.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/scenes/scene.h"
#include "core/scenes/scene_runner.h"

namespace softid::lab {

struct SceneFlags {
  std::string scene = "torus-drop";
  std::string mesh;
  std::string parameters_file;
  std::optional<double> youngs_modulus, poisson_ratio, density, mass_damping, stiffness_damping;
  std::vector<double> gravity, initial_velocity, initial_angular_velocity, ground_normal;
  std::optional<double> ground_offset;
  bool no_ground = false;
  std::optional<double> contact_stiffness, contact_damping, friction_coefficient;
  std::optional<double> drag_linear, drag_quadratic;
  std::string stiffness_field;
  std::optional<double> stiffness_halves;
  // Simulation.
  int cells = 20;
  double cell_size = 0.0;
  double rho_infinity = -1.0;  // < 0: Newmark; else generalized-alpha (SimulationOptions)
  int substeps = 4;
  double fps = 60.0;
  std::optional<double> duration;

  void Register(CLI::App* app);
  // The scene with every flag applied; errors name the flag and value.
  Result<scenes::Scene> BuildScene() const;
  scenes::RunOptions BuildRunOptions() const;
};

}  // namespace softid::lab
