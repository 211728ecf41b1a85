// Synthetic raw recordings (softid-recording/1): what a real capture station records, for testing
// ingest end to end. The scene is simulated exactly as Synthesize does (RunScene, the same fine
// time step), then rendered as full depth images of a whole room: a finite floor slab on the
// scene's ground plane (flat or a ramp), two walls behind the object, one static clutter box on the
// floor away from the object's path, and the object's deformed surface; through a distorted lens,
// with seeded depth noise, device-clock time stamps (random offset, jitter, dropped frames) and the
// scanned mesh in a random scanner frame (optionally in millimetres). truth.json beside it holds
// what ingest has to recover (see SynthesizeRawRecording).
//
// Any Scene works: for a scanned object such as the Stanford bunny build the scene with
// MakeMeshScene(path) (softid-lab synth --raw --mesh <file>); the built-in scenes are procedural.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include "core/capture/depth_noise.h"
#include "core/capture/pixel_rays.h"
#include "core/common/status.h"
#include "core/scenes/camera_rig.h"
#include "core/scenes/scene.h"
#include "core/scenes/scene_runner.h"

namespace softid::scenes {

// Folder (relative to the recording) of the true object masks: truth_masks/<camera>/%06d.png.
inline constexpr const char* kTrueMasksFolder = "truth_masks";

struct RawSynthesisOptions {
  RawSynthesisOptions();

  // Simulation: frame k of the ideal clock is at k / fps; the simulator steps at 1 / (fps *
  // substeps_per_frame) as in Synthesize, and each recorded frame shows the surface interpolated
  // linearly between the two steps around its (jittered) true time.
  RunOptions run;
  // Camera count, size, field of view and elevation; the ring is aimed at the scene's view target
  // with a radius that covers the object's whole trajectory. Default: 1 camera at 30 degrees
  // elevation, 160 x 120 pixels. With one camera, recording.json omits world_from_camera
  // (truth.json has it).
  CameraRigOptions cameras;
  // OpenCV lens distortion (k1, k2, p1, p2[, k3...]) of every camera; empty: ideal pinhole.
  capture::DistortionCoefficients distortion = {-0.12, 0.03, 0.0005, -0.0003, 0.0};
  capture::DepthNoiseOptions noise;  // none by default, as Synthesize
  double depth_scale = 1e-3;         // metres per PNG unit [m], > 0; farther depths read 0
  // Device clock: t_device = time_offset + t_true with time_offset = 1000 + U(0, 100) s.
  double time_jitter_s = 1e-3;  // standard deviation of each frame's true time [s], >= 0
  // Share of frames 1.. (never frame 0) left out of the recording, in [0, 1): exactly
  // round(drop_fraction * (frames - 1)) of them, chosen at random.
  double drop_fraction = 0.05;
  int background_frames = 0;      // frames of the empty scene per camera, in [0, 1000]
  bool mesh_in_mm = true;         // mesh file in millimetres ("mesh_unit": "mm"), else metres
  bool write_true_masks = false;  // truth_masks/<camera>/%06d.png, 255 where the object is seen and
                                  // the sensor has a reading
  bool write_mass = true;         // mass_kg = density x rest volume in recording.json
  // Seed of the time offset, jitter, dropped frames and scanner pose (the noise has its own).
  uint64_t seed = 1;

  Status Validate() const;
};

struct RawSynthesisSummary {
  RunSummary run;  // of the fine-step simulation (one RunScene frame per time step)
  int num_cameras = 0;
  int num_frames = 0;   // frames per camera in the recording
  int num_dropped = 0;  // frames per camera left out
  int num_elements = 0;
  int num_nodes = 0;
  double mass = 0.0;                // simulated [kg]
  double time_offset_s = 0.0;       // device-clock time of t = 0 [s]
  double mean_valid_pixels = 0.0;   // pixels with data per frame and camera
  double mean_object_pixels = 0.0;  // pixels showing the object per frame and camera
  Eigen::Isometry3d world_from_scanner = Eigen::Isometry3d::Identity();
};

// Simulates `scene` and writes a softid-recording/1 folder at `directory` (recording::
// WriteRecording: recording.json, scan.ply, <camera>/%06d.png, <camera>/bg_%03d.png) plus
// truth.json: Synthesize's truth (format softid-truth/1, scene, parameters, generator) and
//   "raw": {"world_from_scanner": 16 numbers row-major (world point [m] = X * scanner point [m]),
//           "floor": {"normal": [3], "offset": d} (world frame, n . x = d),
//           "time_offset_s": device-clock time of t = 0,
//           "frame_times_s": per recorded frame the true simulation time [s],
//           "frame_indices": per recorded frame its index on the ideal k / fps clock,
//           "cameras": [{"name", "world_from_camera": 16 numbers}],
//           "clutter": {"center": [3], "size": [3]} (box in the floor frame),
//           "walls": [{"center": [3], "size": [3]}] (back, side), "floor_slab": {...} (each box
//           also as "world_from_box": 16 numbers), "mesh_unit", "distortion", "fps",
//           "time_jitter_s", "seed"}
// and, with write_true_masks, truth_masks/<camera>/%06d.png per recorded frame (same numbering as
// the frames). Frame 0 is jittered too (its true time is >= 0; the state before t = 0 is the
// rest pose). Depths beyond what a PNG of depth_scale holds read 0 (out of range). Refuses a folder
// that already holds recording.json or capture.json (FailedPrecondition); InvalidArgument for
// invalid options or a scene the simulator rejects; FailedPrecondition when the simulation
// diverges.
Result<RawSynthesisSummary> SynthesizeRawRecording(
    const Scene& scene, const RawSynthesisOptions& options, const std::filesystem::path& directory,
    const std::function<void(int, int)>& progress = {});

}  // namespace softid::scenes
