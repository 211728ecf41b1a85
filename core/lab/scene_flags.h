// Command-line flags shared by softid-lab commands that run a scene: which scene, every physical
// parameter under its public name (dashes for underscores), and the simulation resolution. The
// scalar and 3-vector parameters' flags come from the parameter registry (core/fem), so a new
// parameter has its flag without an edit here.
#pragma once

#include <CLI/CLI.hpp>
#include <map>
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
  // The values given for registry parameters, by name: 1 number for a scalar, 3 for a vector.
  std::map<std::string, std::vector<double>> parameter_values;
  std::vector<double> ground_normal;
  std::optional<double> ground_offset;
  bool no_ground = false;
  std::string stiffness_field;
  std::optional<double> stiffness_halves;
  // Simulation.
  int cells = 20;
  double cell_size = 0.0;
  double rho_infinity = -1.0;         // < 0: Newmark; else generalized-alpha (SimulationOptions)
  std::string element = "trilinear";  // fem::ElementFormulation's name
  int cut_cell_samples = fem::SimulationOptions().cut_cell_samples;
  int substeps = 4;
  double fps = 60.0;
  std::optional<double> duration;

  void Register(CLI::App* app);
  // The scene with every flag applied; errors name the flag and value.
  Result<scenes::Scene> BuildScene() const;
  scenes::RunOptions BuildRunOptions() const;

 private:
  void RegisterParameterFlags(CLI::App* app);
  // The registry parameters' flags applied to *p; errors name the flag and value.
  Status ApplyParameterFlags(fem::PhysicalParameters* p) const;
};

}  // namespace softid::lab
