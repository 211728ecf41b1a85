#include "core/scenes/synthesize.h"

#include <fstream>

#include "core/capture/capture.h"
#include "core/capture/depth_preview.h"
#include "core/capture/depth_renderer.h"
#include "core/common/json_fields.h"
#include "core/geometry/hole_caps.h"

namespace softid::scenes {

Status SynthesisOptions::Validate() const {
  SOFTID_RETURN_IF_ERROR(run.Validate());
  SOFTID_RETURN_IF_ERROR(cameras.Validate());
  SOFTID_RETURN_IF_ERROR(noise.Validate());
  if (!(depth_scale > 0.0) || !std::isfinite(depth_scale)) {
    return json::Invalid("depth_scale", depth_scale, "must be positive and finite");
  }
  return Status::Ok();
}

nlohmann::json SynthesisTruthJson(const Scene& scene, const RunOptions& run,
                                  const capture::DepthNoiseOptions& noise, double depth_scale,
                                  int num_elements, double simulated_mass) {
  return {
      {"format", kTruthFormat},
      {"scene", scene.name},
      {"parameters", fem::ToJson(scene.parameters)},
      {"generator",
       {{"cells_along_longest_side", run.simulation.cells_along_longest_side},
        {"cell_size", run.simulation.cell_size},
        {"substeps_per_frame", run.substeps_per_frame},
        {"time_step", 1.0 / (run.fps * run.substeps_per_frame)},
        {"newmark_beta", run.simulation.newmark_beta},
        {"newmark_gamma", run.simulation.newmark_gamma},
        {"generalized_alpha_m", run.simulation.generalized_alpha_m},
        {"generalized_alpha_f", run.simulation.generalized_alpha_f},
        {"element", fem::ToString(run.simulation.element)},
        {"cut_cell_samples", run.simulation.cut_cell_samples},
        {"elements", num_elements},
        {"simulated_mass", simulated_mass},
        {"noise",
         {{"sigma_constant", noise.sigma_constant},
          {"sigma_quadratic", noise.sigma_quadratic},
          {"dropout_probability", noise.dropout_probability},
          {"seed", noise.seed},
          {"depth_scale", depth_scale}}}}},
  };
}

namespace {

// Simulates the scene and renders every frame from every camera with seeded depth noise into
// *frames (per camera); fills *summary's simulation and image statistics.
Status SimulateAndRender(const Scene& scene, const SynthesisOptions& options,
                         const std::vector<capture::PinholeCamera>& cameras,
                         const std::function<void(int, int)>& progress,
                         std::vector<std::vector<capture::DepthImage>>* frames,
                         SynthesisSummary* summary) {
  capture::DepthRenderer renderer;
  const int num_frames = options.run.NumFrames(scene);
  long long valid_pixels = 0;
  // The real object is closed where its scan has holes: the cameras see the caps, not through.
  geometry::HoleLoops holes;  // found on the first state's surface

  const auto record_frame = [&](int frame, const fem::Simulator& sim) {
    if (frame == 0) {
      summary->num_elements = sim.hex_mesh().NumElements();
      summary->num_nodes = sim.hex_mesh().NumNodes();
      summary->mass = sim.total_mass();
      holes = geometry::FindHoleLoops(sim.DeformedSurface());
    }
    const geometry::TriangleMesh surface = geometry::WithHolesCapped(sim.DeformedSurface(), holes);
    for (size_t c = 0; c < cameras.size(); ++c) {
      capture::DepthImage image = renderer.Render(surface, cameras[c]);
      capture::ApplyDepthNoise(options.noise, frame, static_cast<int>(c), &image);
      valid_pixels += image.NumValid();
      (*frames)[c].push_back(std::move(image));
    }
    if (progress) progress(frame, num_frames);
  };
  SOFTID_ASSIGN_OR_RETURN(summary->run, RunSceneToEnd(scene, options.run, record_frame));
  summary->num_cameras = static_cast<int>(cameras.size());
  summary->mean_valid_pixels =
      static_cast<double>(valid_pixels) / (static_cast<double>(num_frames) * cameras.size());
  return Status::Ok();
}

// capture.json's contents (the frames' file names are WriteCapture's).
capture::Capture MakeCapture(const Scene& scene, const SynthesisOptions& options,
                             const std::vector<capture::PinholeCamera>& cameras) {
  capture::Capture cap;
  cap.fps = options.run.fps;
  if (options.write_mass) {
    cap.mass_kg = scene.parameters.density * std::abs(geometry::SignedVolume(scene.mesh));
  }
  cap.fixed_region = scene.fixed_region;
  for (const auto& camera : cameras) {
    capture::CameraRecording recording;
    recording.camera = camera;
    recording.depth_scale = options.depth_scale;
    cap.cameras.push_back(recording);
  }
  return cap;
}

}  // namespace

Result<SynthesisSummary> Synthesize(const Scene& scene, const SynthesisOptions& options,
                                    const std::filesystem::path& out,
                                    const std::function<void(int, int)>& progress) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (std::filesystem::exists(out / capture::kCaptureFileName)) {
    return Status::FailedPrecondition("out = " + out.string() +
                                      ": already holds a capture; choose an empty folder");
  }
  const std::vector<capture::PinholeCamera> cameras =
      MakeCameraRing(options.cameras, scene.view_target, scene.view_radius);
  std::vector<std::vector<capture::DepthImage>> frames(cameras.size());
  SynthesisSummary summary;
  SOFTID_RETURN_IF_ERROR(SimulateAndRender(scene, options, cameras, progress, &frames, &summary));

  const capture::Capture cap = MakeCapture(scene, options, cameras);
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec) return Status::IoError("out = " + out.string() + ": " + ec.message());

  // truth.json first: capture.json is written last, so a folder with it is complete.
  const nlohmann::json truth = SynthesisTruthJson(
      scene, options.run, options.noise, options.depth_scale, summary.num_elements, summary.mass);
  {
    std::ofstream file(out / kTruthFileName);
    file << truth.dump(2) << "\n";
    if (!file) return Status::IoError("cannot write " + (out / kTruthFileName).string());
  }
  SOFTID_RETURN_IF_ERROR(capture::WriteCapture(out, cap, scene.mesh, frames));
  // For people: what the first camera saw, as a contact sheet.
  SOFTID_RETURN_IF_ERROR(capture::WriteDepthPreview(out / kPreviewFileName, frames[0]));
  return summary;
}

}  // namespace softid::scenes
