// Synthetic captures: simulate a scene, render every frame from every camera with a pinhole model
// and seeded depth noise, and write a capture folder exactly as a capture station would, plus
// truth.json with the true parameters (which the fit never reads).
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>

#include "core/capture/depth_noise.h"
#include "core/common/status.h"
#include "core/scenes/camera_rig.h"
#include "core/scenes/scene.h"
#include "core/scenes/scene_runner.h"

namespace softid::scenes {

inline constexpr const char* kTruthFileName = "truth.json";
inline constexpr const char* kTruthFormat = "softid-truth/1";
inline constexpr const char* kPreviewFileName = "preview.png";

struct SynthesisOptions {
  RunOptions run;
  CameraRigOptions cameras;
  capture::DepthNoiseOptions noise;  // none by default
  double depth_scale = 1e-4;         // metres per PNG unit [m], > 0 (0.1 mm; 6.5 m range)
  bool write_mass = true;            // put mass_kg (= density x mesh volume) in capture.json
  Status Validate() const;
};

struct SynthesisSummary {
  RunSummary run;
  int num_cameras = 0;
  int num_elements = 0;
  int num_nodes = 0;
  double mass = 0.0;               // [kg]
  double mean_valid_pixels = 0.0;  // per frame and camera
};

// truth.json of a synthetic capture or recording: format, scene name, the true parameters under
// their public names and the generator's settings (run, noise, depth scale, element count, mass).
nlohmann::json SynthesisTruthJson(const Scene& scene, const RunOptions& run,
                                  const capture::DepthNoiseOptions& noise, double depth_scale,
                                  int num_elements, double simulated_mass);

// Writes <out>/capture.json, <out>/object.obj, <out>/camN/%06d.png, <out>/truth.json and
// <out>/preview.png (a contact sheet of the first camera's frames).
// Refuses to write into a folder that already holds a capture.json.
Result<SynthesisSummary> Synthesize(const Scene& scene, const SynthesisOptions& options,
                                    const std::filesystem::path& out,
                                    const std::function<void(int, int)>& progress = {});

}  // namespace softid::scenes
