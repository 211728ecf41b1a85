#include <spdlog/spdlog.h>

#include <functional>
#include <memory>

#include "core/lab/commands.h"
#include "core/lab/scene_flags.h"
#include "core/scenes/raw_recording_synthesis.h"
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
  // --raw: a softid-recording/1 folder of the whole scene instead of a capture.
  bool raw = false;
  int raw_cameras = 1;
  int background_frames = 0;
  double time_jitter = 1e-3;
  double drop_fraction = 0.05;
  bool no_distortion = false;
  std::string mesh_unit = "mm";
  bool true_masks = false;
};

// Logs "synth: <unit> k/n (p%)" at every tenth of the run.
std::function<void(int, int)> TenthsLogger(const char* unit) {
  return [unit, last_percent = -1](int done, int total) mutable {
    const int percent = 100 * (done + 1) / total;
    if (percent / 10 != last_percent / 10) {
      spdlog::info("synth: {} {}/{} ({}%)", unit, done + 1, total, percent);
      last_percent = percent;
    }
  };
}

// Logs a failed synthesis; the exit code tells bad input from other failures.
int ExitForFailure(const Status& status) {
  spdlog::error("{}", status.message());
  return status.code() == StatusCode::kInvalidArgument ? kExitInvalidInput : kExitFailure;
}

int RunRawSynth(const SynthFlags& flags, const scenes::Scene& scene) {
  scenes::RawSynthesisOptions options;
  options.run = flags.scene.BuildRunOptions();
  options.cameras = flags.cameras;
  options.cameras.count = flags.raw_cameras;
  options.noise = flags.noise;
  options.depth_scale = flags.depth_scale;
  options.write_mass = !flags.no_mass;
  if (flags.realistic_noise) {
    options.noise = capture::StructuredLightNoise(options.noise.seed);
    options.depth_scale = capture::kStructuredLightDepthScale;
  }
  options.seed = flags.noise.seed;
  options.background_frames = flags.background_frames;
  options.time_jitter_s = flags.time_jitter;
  options.drop_fraction = flags.drop_fraction;
  if (flags.no_distortion) options.distortion.clear();
  options.mesh_in_mm = flags.mesh_unit == "mm";
  options.write_true_masks = flags.true_masks;
  const int num_frames = options.run.NumFrames(scene);
  spdlog::info("synth --raw: scene {} -> {} ({} frames, {} camera(s) {}x{})", scene.name, flags.out,
               num_frames, options.cameras.count, options.cameras.width, options.cameras.height);
  Result<scenes::RawSynthesisSummary> summary =
      scenes::SynthesizeRawRecording(scene, options, flags.out, TenthsLogger("step"));
  if (!summary.ok()) return ExitForFailure(summary.status());
  const auto& s = *summary;
  std::printf("recording written to %s\n", flags.out.c_str());
  std::printf(
      "  recording.json  format softid-recording/1, %d frames per camera (%d dropped), %d "
      "camera(s) %dx%d%s\n",
      s.num_frames, s.num_dropped, s.num_cameras, options.cameras.width, options.cameras.height,
      options.distortion.empty() ? "" : ", lens distortion");
  std::printf("  scan.ply        rest mesh in a random scanner frame, in %s\n",
              options.mesh_in_mm ? "millimetres" : "metres");
  std::printf(
      "  cam*/           16-bit depth PNGs of the whole scene, %.0f pixels with data and "
      "%.0f object pixels per frame on average, %d background frame(s)\n",
      s.mean_valid_pixels, s.mean_object_pixels, options.background_frames);
  std::printf(
      "  truth.json      true parameters and \"raw\": scanner pose, floor, clock offset "
      "%.6f s, camera poses\n",
      s.time_offset_s);
  if (options.write_true_masks) {
    std::printf("  truth_masks/    8-bit masks of the object per camera and frame\n");
  }
  std::printf(
      "  simulation      %d elements, %d nodes, mass %.4g kg, %d steps in %.2f s (%.2f ms/step)\n",
      s.num_elements, s.num_nodes, s.mass, s.run.num_steps, s.run.seconds,
      1e3 * s.run.seconds / std::max(1, s.run.num_steps));
  return kExitOk;
}

int RunSynth(const SynthFlags& flags) {
  Result<scenes::Scene> scene = flags.scene.BuildScene();
  if (!scene.ok()) {
    spdlog::error("{}", scene.status().message());
    return kExitInvalidInput;
  }
  if (flags.raw) return RunRawSynth(flags, *scene);
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
  Result<scenes::SynthesisSummary> summary =
      scenes::Synthesize(*scene, options, flags.out, TenthsLogger("frame"));
  if (!summary.ok()) return ExitForFailure(summary.status());
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
  app->footer(
      "Examples:\n"
      "  softid-lab synth --scene torus-drop --out capture/\n"
      "  softid-lab synth --scene pillow-ramp --friction 0.3 --cameras 2 --realistic-noise --out "
      "capture/\n"
      "  softid-lab synth --scene torus-drop --raw --out recording/   # a raw recording to ingest");
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
  app->add_flag("--raw", flags->raw,
                "write a raw recording (softid-recording/1) of the whole scene instead: floor, "
                "walls, clutter, lens distortion, device clock, mesh in a scanner frame");
  app->add_option("--raw-cameras", flags->raw_cameras,
                  "--raw: number of cameras (1: no world_from_camera)")
      ->capture_default_str();
  app->add_option("--background-frames", flags->background_frames,
                  "--raw: frames of the empty scene per camera")
      ->capture_default_str();
  app->add_option("--time-jitter", flags->time_jitter,
                  "--raw: standard deviation of the frame times [s]")
      ->capture_default_str();
  app->add_option("--drop-fraction", flags->drop_fraction,
                  "--raw: share of frames dropped (never frame 0)")
      ->capture_default_str();
  app->add_flag("--no-distortion", flags->no_distortion, "--raw: ideal pinhole lens");
  app->add_option("--mesh-unit", flags->mesh_unit, "--raw: unit of the scan file")
      ->check(CLI::IsMember({"m", "mm"}))
      ->capture_default_str();
  app->add_flag("--true-masks", flags->true_masks,
                "--raw: write truth_masks/<camera>/%06d.png (255 where the object is seen)");
  return [flags] { return RunSynth(*flags); };
}

}  // namespace softid::lab
