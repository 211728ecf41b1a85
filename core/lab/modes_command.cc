// softid-lab modes: the lowest elastic eigenfrequencies of a scene's body as softid discretises
// it (core/fem/elastic_modes.h), to hold the model's stiffness against another code's or an
// analytic frequency without contact, time stepping or a fit.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>

#include "core/fem/elastic_modes.h"
#include "core/lab/commands.h"
#include "core/lab/scene_flags.h"

namespace softid::lab {
namespace {

struct ModesFlags {
  SceneFlags scene;
  int count = 6;
  std::string grid_orientation = "world";
  std::optional<double> reference_hz;
  std::string out;
};

nlohmann::json ModesReport(const ModesFlags& flags, const fem::Simulator& sim,
                           const fem::ElasticModes& modes) {
  nlohmann::json report = {{"element", flags.scene.element},
                           {"grid_orientation", flags.grid_orientation},
                           {"cell_size_m", sim.hex_mesh().CellSize()},
                           {"elements", sim.hex_mesh().NumElements()},
                           {"nodes", sim.hex_mesh().NumNodes()},
                           {"degrees_of_freedom", modes.degrees_of_freedom},
                           {"youngs_modulus", sim.parameters().youngs_modulus},
                           {"poisson_ratio", sim.parameters().poisson_ratio},
                           {"density", sim.parameters().density},
                           {"rigid_modes", modes.rigid_modes},
                           {"rigid_frequency_hz", modes.rigid_frequency_hz},
                           {"frequencies_hz", modes.frequencies_hz}};
  if (flags.reference_hz) {
    report["reference_hz"] = *flags.reference_hz;
    report["expected_fitted_youngs_modulus"] = fem::ExpectedFittedModulus(
        sim.parameters().youngs_modulus, modes.frequencies_hz[0], *flags.reference_hz);
  }
  return report;
}

int RunModes(const ModesFlags& flags) {
  Result<scenes::Scene> scene = flags.scene.BuildScene();
  if (!scene.ok()) {
    spdlog::error("{}", scene.status().message());
    return kExitInvalidInput;
  }
  fem::SimulationOptions options = flags.scene.BuildRunOptions().simulation;
  options.grid_orientation =
      flags.grid_orientation == "body" ? fem::GridOrientation::kBody : fem::GridOrientation::kWorld;
  Result<fem::ElasticModes> modes = Status::Internal("not computed");
  std::unique_ptr<fem::Simulator> sim;
  try {
    sim = std::make_unique<fem::Simulator>(scene->mesh, scene->parameters, options,
                                           scene->fixed_region);
    modes = fem::ComputeElasticModes(*sim, {flags.count});
  } catch (const std::invalid_argument& e) {
    modes = Status::InvalidArgument(e.what());
  }
  if (!modes.ok()) {
    spdlog::error("{}", modes.status().message());
    return modes.status().code() == StatusCode::kInternal ? kExitFailure : kExitInvalidInput;
  }
  const nlohmann::json report = ModesReport(flags, *sim, *modes);
  std::printf("%s, %s grid, cell %.4g m, %d elements, %d nodes: %d rigid modes (largest %.2g Hz)\n",
              flags.scene.element.c_str(), flags.grid_orientation.c_str(),
              sim->hex_mesh().CellSize(), sim->hex_mesh().NumElements(), sim->hex_mesh().NumNodes(),
              modes->rigid_modes, modes->rigid_frequency_hz);
  for (size_t i = 0; i < modes->frequencies_hz.size(); ++i)
    std::printf("  mode %zu: %.4f Hz\n", i + 1, modes->frequencies_hz[i]);
  if (flags.reference_hz) {
    std::printf("a fit to a body whose lowest frequency is %.4f Hz returns E = %.6g Pa\n",
                *flags.reference_hz, report["expected_fitted_youngs_modulus"].get<double>());
  }
  if (!flags.out.empty()) {
    std::ofstream file(flags.out);
    if (!(file << report.dump(2) << "\n")) {
      spdlog::error("--out = {}: cannot write", flags.out);
      return kExitFailure;
    }
  }
  return kExitOk;
}

}  // namespace

Command RegisterModes(CLI::App* app) {
  app->footer(
      "Example:\n"
      "  softid-lab modes --mesh block.obj --youngs-modulus 40000 --poisson-ratio 0.4 \\\n"
      "      --density 300 --cells 16 --element incompatible_modes --reference-hz 28.84");
  auto flags = std::make_shared<ModesFlags>();
  flags->scene.Register(app);
  app->add_option("--modes", flags->count, "elastic modes to compute")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app->add_option("--grid-orientation", flags->grid_orientation,
                  "world, or body: the grid turned to the body's faces (docs/job-config.md)")
      ->check(CLI::IsMember({"world", "body"}))
      ->capture_default_str();
  app->add_option("--reference-hz", flags->reference_hz,
                  "another code's (or the real body's) lowest frequency [Hz]: print the E a fit "
                  "with this model would return")
      ->check(CLI::PositiveNumber);
  app->add_option("--out,-o", flags->out, "write the modes as JSON to this file");
  return [flags] { return RunModes(*flags); };
}

}  // namespace softid::lab
