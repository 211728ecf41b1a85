// Captures: a rest-pose mesh plus synchronised depth videos from calibrated cameras, stored as a
// folder with capture.json (format "softid-capture/1"), the mesh and 16-bit depth PNGs.
//
// capture.json is a public contract that capture stations write against:
//   {
//     "format": "softid-capture/1",
//     "mesh": "object.obj",               // rest pose at t = 0, world frame, metres (OBJ/PLY/STL)
//     "fps": 60,                          // frames per second, > 0
//     "mass_kg": 0.25,                    // optional, > 0: density = mass / mesh volume
//     "fixed_region": {"min": [x, y, z], "max": [x, y, z]},  // optional [m]: clamped nodes
//     "cameras": [{                       // >= 1 camera, unique names
//       "name": "cam0", "width": 640, "height": 480,         // [pixels], integers > 0
//       "fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5,  // [pixels], (cx, cy) in the image
//       "depth_scale": 0.001,             // metres per unit of the 16-bit PNG, > 0
//       "world_from_camera": [16 numbers, row-major 4x4],    // X_WC, rigid; OpenCV camera axes
//       "frames": ["cam0/000000.png", "cam0/000001.png"]     // frame k shows time k / fps
//     }],
//     "frame_times": [0.0, 0.0171],       // optional [s]: time of frame k instead of k / fps
//     "floor": {"normal": [0, 0, 1], "offset": 0.0}  // optional: the floor n . x = offset [m] as
//                                         // measured; the ground's value unless a job sets it
//   }
// Gravity is -z in the world frame. Every camera has the same number of frames (>= 1). Frames are
// 16-bit single-channel PNGs of depth along the camera z axis (value * depth_scale metres), 0 = no
// data; only the object's pixels are non-zero. File paths are relative to the capture folder,
// '/'-separated, and may not leave it (no absolute paths, no "..", no symlinks pointing outside).
// Unknown extra fields are ignored. Malformed input is rejected with InvalidArgument whose message
// names the file, the field path and the value, e.g.
//   "<dir>/capture.json: cameras[0].fx = -1: must be positive and finite".
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/capture/camera.h"
#include "core/capture/depth_image.h"
#include "core/common/status.h"
#include "core/common/untrusted_json.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::capture {

// The one format version this library reads and writes.
inline constexpr std::string_view kCaptureFormat = "softid-capture/1";
// Name of the capture description inside a capture folder.
inline constexpr std::string_view kCaptureFileName = "capture.json";
// Bounds that keep a capture's memory in reach of one machine: 4096 x 4096 pixels per image
// (32 MiB decoded; depth cameras give 0.3-2 Mpixel), 16 cameras, 20,000 frames per camera (over
// five minutes at 60 fps; softid fits seconds).
inline constexpr int64_t kMaxImagePixels = 4096LL * 4096LL;
inline constexpr int kMaxCameras = 16;
inline constexpr int kMaxFramesPerCamera = 20000;
// Latest frame time accepted in frame_times, in nominal frame periods (1 / fps): the simulation
// runs up to the last frame's time whatever the number of frames.
inline constexpr int kMaxFramePeriods = 2 * kMaxFramesPerCamera;
// The mesh's longest side must lie in this range [m] (a mesh in millimetres declared as metres
// is 1000x too large), and it must enclose a volume (not flat).
inline constexpr double kMinMeshExtent_m = 1e-3;
inline constexpr double kMaxMeshExtent_m = 100.0;
// Bounds on capture.json as read from a folder or an upload: 4 MiB holds 60,000 frame names;
// the format nests 4 levels deep (cameras[i].frames[k]).
inline constexpr json::UntrustedJsonLimits kCaptureJsonLimits{.max_bytes = 4u << 20,
                                                              .max_depth = 8};

// One camera's calibration and depth video.
struct CameraRecording {
  PinholeCamera camera;
  double depth_scale = 0.001;  // [m per PNG unit], > 0
  // Frame PNGs relative to the capture folder, '/'-separated; frame k shows time k / fps [s].
  std::vector<std::string> frames;
};

struct Capture {
  // Capture folder; set by ReadCapture, not stored in capture.json.
  std::filesystem::path directory;
  // Rest-pose mesh at t = 0 (world frame, metres), relative to the capture folder.
  std::string mesh_file = "object.obj";
  // Nominal frames per second [1/s], > 0: frame k shows time k / fps unless frame_times is given;
  // the simulation's time step is 1 / (fps * substeps) either way.
  double fps = 0.0;
  // Optional time of every frame [s] (one per frame, >= 0, strictly increasing), for recordings
  // whose frames are not evenly spaced (device-clock jitter, dropped frames). Empty: k / fps.
  std::vector<double> frame_times;
  std::optional<double> mass_kg;                    // [kg], > 0 when present
  std::optional<Eigen::AlignedBox3d> fixed_region;  // world frame [m]: nodes inside are clamped
  // The floor as the station measured it (e.g. softid-lab ingest): the plane n . x = offset_m in
  // the world frame, n a unit vector pointing up. A fit takes it as the ground plane unless the
  // job config fixes or starts the ground itself.
  struct Floor {
    Eigen::Vector3d normal{0, 0, 1};
    double offset_m = 0.0;
  };
  std::optional<Floor> floor;
  std::vector<CameraRecording> cameras;

  // Number of frames per camera (all cameras have the same); 0 without cameras.
  int NumFrames() const;
  int NumCameras() const { return static_cast<int>(cameras.size()); }
  // Time shown by frame k [s]: frame_times[k], or k / fps without frame_times.
  double FrameTime(int frame) const;
};

struct ReadCaptureOptions {
  // true (default): decode every frame PNG, which also detects corrupt or truncated image data.
  // false: check only each frame's PNG header (16-bit greyscale of the camera's size); much
  // faster for long captures, corrupt pixel data then surfaces in LoadFrame.
  bool decode_frames = true;

  // Always OK; present for uniformity with other options structs.
  Status Validate() const { return Status::Ok(); }
};

// capture.json contents of `capture` (directory is not stored). Optional fields are omitted when
// unset. Doubles round-trip exactly.
nlohmann::json ToJson(const Capture& capture);

// Parses and validates capture.json contents without touching any file: format and version,
// required fields and their JSON types, values (see the format above), relative paths that stay
// inside the folder (lexically), unique camera names, equal frame counts. Errors are
// InvalidArgument "<source>: <field path> = <value>: <reason>". The result has an empty directory.
Result<Capture> CaptureFromJson(const nlohmann::json& json,
                                std::string_view source = kCaptureFileName);

// Reads <directory>/capture.json with CaptureFromJson, then checks the files it references: the
// mesh loads with geometry::ReadTriangleMesh (only files inside the folder are opened), is not
// empty, encloses a volume and has a longest side in [kMinMeshExtent_m, kMaxMeshExtent_m]; every
// frame exists and is a 16-bit single-channel PNG of its camera's size (decoded or header-only, see
// options); no path leaves the folder through a symlink. NotFound when the directory or
// capture.json does not exist; InvalidArgument naming capture.json, the field, the value and the
// problem for anything else.
Result<Capture> ReadCapture(const std::filesystem::path& directory,
                            const ReadCaptureOptions& options = {});

// Loads the capture's mesh (world frame, metres) with geometry::ReadTriangleMesh.
Result<geometry::TriangleMesh> LoadCaptureMesh(const Capture& capture);

// Loads frame `frame` of camera `camera` (depth in metres along the camera z axis).
// InvalidArgument for indices out of range; otherwise as ReadDepthPng.
Result<DepthImage> LoadFrame(const Capture& capture, int camera, int frame);

// Writes a capture folder: `mesh` as OBJ to capture.mesh_file ("object.obj" when empty; must end
// in ".obj"), frames_per_camera[i][k] as <camera name>/%06d.png with camera i's depth_scale, and
// capture.json last (through a temporary file renamed into place, after removing any previous
// capture.json) so an interrupted write never looks complete. The frames are staged and moved
// into place only when all are written (capture_writer.h, which also writes frame by frame): a
// write that fails on a frame leaves a previous capture in the folder as it was. capture.directory and each
// camera's `frames` are ignored (frame names are generated). Everything is validated before the
// first file is written: the same rules as CaptureFromJson, camera names usable as folder names
// (no '/', '\\', "." or ".."), one image list per camera with equal counts (>= 1), image sizes
// matching the cameras, a non-empty mesh. InvalidArgument for invalid input (also for depths a
// PNG cannot store, see WriteDepthPng), IoError when a file cannot be written.
Status WriteCapture(const std::filesystem::path& directory, const Capture& capture,
                    const geometry::TriangleMesh& mesh,
                    const std::vector<std::vector<DepthImage>>& frames_per_camera);

}  // namespace softid::capture
