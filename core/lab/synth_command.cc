#include <spdlog/spdlog.h>

#include <memory>

#include "core/lab/commands.h"
#include "core/lab/scene_flags.h"
#include "core/scenes/synthesize.h"

namespace softid::lab {
namespace {

struct SynthFlags {
  SceneFlags scene;
  std::string out;
  scenes::CameraRigOptions cameras;
  capture::DepthNoiseOptions noise;
  double depth_scale = 1e-4;
  bool realistic_noise = false;
  bool no_mass = false;
};

int RunSynth(const SynthFlags& flags) {
  Result<scenes::Scene> scene = flags.scene.BuildScene();
  if (!scene.ok()) {
    spdlog::error("{}", scene.status().message());
    return kExitInvalidInput;
  }
  scenes::SynthesisOptions options;
  options.run = flags.scene.BuildRunOptions();
  options.cameras = flags.cameras;
  options.noise = flags.noise;
  options.depth_scale = flags.depth_scale;
  options.write_mass = !flags.no_mass;
  if (flags.realistic_noise) {
    options.noise = capture::StructuredLightNoise(options.noise.seed);
    options.depth_scale = capture::kStructuredLightDepthScale;
  }
  const int num_frames = options.run.NumFrames(*scene);
  spdlog::info("synth: scene {} -> {} ({} frames, {} camera(s) {}x{})", scene->name, flags.out,
               num_frames, options.cameras.count, options.cameras.width, options.cameras.height);
  int last_percent = -1;
  Result<scenes::SynthesisSummary> summary =
      scenes::Synthesize(*scene, options, flags.out, [&](int frame, int total) {
        const int percent = 100 * (frame + 1) / total;
        if (percent / 10 != last_percent / 10) {
          spdlog::info("synth: frame {}/{} ({}%)", frame + 1, total, percent);
          last_percent = percent;
        }
      });
  if (!summary.ok()) {
    spdlog::error("{}", summary.status().message());
    return summary.status().code() == StatusCode::kInvalidArgument ? kExitInvalidInput
                                                                   : kExitFailure;
  }
  const auto& s = *summary;
  std::printf("capture written to %s\n", flags.out.c_str());
  std::printf(
      "  capture.json  format softid-capture/1, %d frames at %.6g fps, %d camera(s) %dx%d\n",
      s.run.num_frames, options.run.fps, s.num_cameras, options.cameras.width,
      options.cameras.height);
  std::printf("  object.obj    rest mesh, %zu vertices, %zu triangles\n",
              scene->mesh.vertices.size(), scene->mesh.triangles.size());
  std::printf("  cam*/         16-bit depth PNGs, %.0f object pixels per frame on average\n",
              s.mean_valid_pixels);
  std::printf("  preview.png   contact sheet of cam0's depth frames\n");
  std::printf("  truth.json    true parameters (E = %.6g Pa, nu = %.3g, rho = %.6g kg/m^3)\n",
              scene->parameters.youngs_modulus, scene->parameters.poisson_ratio,
              scene->parameters.density);
  std::printf(
      "  simulation    %d elements, %d nodes, mass %.4g kg, %d steps in %.2f s (%.2f ms/step)\n",
      s.num_elements, s.num_nodes, s.mass, s.run.num_steps, s.run.seconds,
      1e3 * s.run.seconds / std::max(1, s.run.num_steps));
  return kExitOk;
}

}  // namespace

Command RegisterSynth(CLI::App* app) {
  auto flags = std::make_shared<SynthFlags>();
  flags->scene.Register(app);
  app->add_option("--out,-o", flags->out, "capture folder to write")->required();
  app->add_option("--cameras", flags->cameras.count, "number of cameras on a ring")
      ->capture_default_str();
  app->add_option("--width", flags->cameras.width, "image width [px]")->capture_default_str();
  app->add_option("--height", flags->cameras.height, "image height [px]")->capture_default_str();
  app->add_option("--fov", flags->cameras.field_of_view, "horizontal field of view [deg]")
      ->capture_default_str();
  app->add_option("--elevation", flags->cameras.elevation, "camera elevation [deg]")
      ->capture_default_str();
  app->add_option("--azimuth", flags->cameras.azimuth, "first camera's azimuth [deg]")
      ->capture_default_str();
  app->add_option("--distance", flags->cameras.distance,
                  "camera distance [m]; 0 = frame the scene");
  app->add_option("--noise-constant", flags->noise.sigma_constant,
                  "depth noise a [m] (sigma = a + b z^2)");
  app->add_option("--noise-quadratic", flags->noise.sigma_quadratic, "depth noise b [1/m]");
  app->add_option("--dropout", flags->noise.dropout_probability, "pixel dropout probability");
  app->add_option("--seed", flags->noise.seed, "noise seed")->capture_default_str();
  app->add_option("--depth-scale", flags->depth_scale, "metres per PNG unit")
      ->capture_default_str();
  app->add_flag("--realistic-noise", flags->realistic_noise,
                "1.5 mm + 2.5 mm (z/1m)^2 noise, 1 % dropout, 1 mm quantisation");
  app->add_flag("--no-mass", flags->no_mass, "leave mass_kg out of capture.json");
  return [flags] { return RunSynth(*flags); };
}

}  // namespace softid::lab
