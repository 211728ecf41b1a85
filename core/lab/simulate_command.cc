#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

#include "core/lab/commands.h"
#include "core/lab/scene_flags.h"
#include "core/scenes/scene_runner.h"

namespace softid::lab {
namespace {

struct SimulateFlags {
  SceneFlags scene;
  std::string out;
};

int RunSimulate(const SimulateFlags& flags) {
  Result<scenes::Scene> scene = flags.scene.BuildScene();
  if (!scene.ok()) {
    spdlog::error("{}", scene.status().message());
    return kExitInvalidInput;
  }
  std::error_code ec;
  std::filesystem::create_directories(flags.out, ec);
  if (ec) {
    spdlog::error("--out = {}: {}", flags.out, ec.message());
    return kExitFailure;
  }
  const scenes::RunOptions run = flags.scene.BuildRunOptions();
  const int num_frames = run.NumFrames(*scene);
  Status write_status;
  nlohmann::json frames = nlohmann::json::array();
  Result<scenes::RunSummary> summary = [&]() -> Result<scenes::RunSummary> {
    try {
      return scenes::RunScene(*scene, run, [&](int frame, const fem::Simulator& sim) {
        char name[32];
        std::snprintf(name, sizeof(name), "frame_%06d.ply", frame);
        if (write_status.ok()) {
          write_status = geometry::WriteTriangleMeshPly(std::filesystem::path(flags.out) / name,
                                                        sim.DeformedSurface());
        }
        const Eigen::Vector3d com = sim.CentreOfMass();
        frames.push_back({{"frame", frame},
                          {"time", sim.state().time},
                          {"file", name},
                          {"centre_of_mass", {com.x(), com.y(), com.z()}}});
        if ((frame + 1) % std::max(1, num_frames / 10) == 0) {
          spdlog::info("simulate: frame {}/{}", frame + 1, num_frames);
        }
      });
    } catch (const std::invalid_argument& e) {
      return Status::InvalidArgument(e.what());
    }
  }();
  if (!summary.ok()) {
    spdlog::error("{}", summary.status().message());
    return kExitInvalidInput;
  }
  if (!write_status.ok()) {
    spdlog::error("{}", write_status.message());
    return kExitFailure;
  }
  nlohmann::json report = {{"scene", scene->name},
                           {"parameters", fem::ToJson(scene->parameters)},
                           {"frames", frames},
                           {"steps", summary->num_steps},
                           {"diverged", summary->diverged},
                           {"seconds", summary->seconds}};
  std::ofstream(std::filesystem::path(flags.out) / "simulation.json") << report.dump(2) << "\n";
  std::printf("%d frames written to %s (frame_NNNNNN.ply, simulation.json)%s\n",
              summary->num_frames, flags.out.c_str(), summary->diverged ? " -- DIVERGED" : "");
  return summary->diverged ? kExitFailure : kExitOk;
}

}  // namespace

Command RegisterSimulate(CLI::App* app) {
  app->footer(
      "Example:\n"
      "  softid-lab simulate --scene bar-hanging --out surfaces/    # one PLY per frame");
  auto flags = std::make_shared<SimulateFlags>();
  flags->scene.Register(app);
  app->add_option("--out,-o", flags->out, "folder for the PLY frames")->required();
  return [flags] { return RunSimulate(*flags); };
}

}  // namespace softid::lab
