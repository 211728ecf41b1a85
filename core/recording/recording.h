// Recordings: what a capture station recorded, before softid knows where the object is. A folder
// with recording.json (format "softid-recording/1"), the scanned mesh and 16-bit depth PNGs of the
// whole scene. docs/recording-format.md is the user-facing reference.
//
// recording.json is a public contract that capture stations write against:
//   {
//     "format": "softid-recording/1",
//     "mesh": "scan.ply",                 // rest shape in the scanner's frame (OBJ/PLY/STL)
//     "mesh_unit": "mm",                  // optional: "m" (default) or "mm"
//     "mass_kg": 0.38,                    // optional, > 0
//     "cameras": [{                       // 1..kMaxCameras cameras, unique folder-safe names
//       "name": "cam0", "width": 640, "height": 480,         // [pixels], integers > 0
//       "fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5,  // [pixels], (cx, cy) in the image
//       "distortion": [k1, k2, p1, p2, k3],  // optional: OpenCV model, 4/5/8/12/14 coefficients
//       "depth_scale": 0.001,             // metres per unit of the 16-bit PNG, > 0
//       "world_from_camera": [16 numbers],  // X_WC, rigid, OpenCV axes; required with >= 2
//                                           // cameras
//       "frames": [{"file": "cam0/000000.png", "t": 12.3451}],  // device clock [s], increasing
//       "background": ["cam0/bg_000.png"]   // optional: frames of the empty scene
//     }]
//   }
// Frames are full depth images of the scene (floor, walls, clutter and the object), still
// distorted; 0 = no data. Cameras may have different frame counts and time stamps. Paths are
// relative to the folder, '/'-separated, and may not leave it (lexically or through symlinks).
// Unknown fields are ignored. Malformed input is rejected with InvalidArgument
// "<source>: <field path> = <value>: <reason>", as capture.json is (core/capture/capture.h).
#pragma once

#include <filesystem>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/capture/camera.h"
#include "core/capture/depth_image.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::recording {

// The one format version this library reads and writes.
inline constexpr std::string_view kRecordingFormat = "softid-recording/1";
// Name of the recording description inside a recording folder.
inline constexpr std::string_view kRecordingFileName = "recording.json";
// At most this many background frames per camera.
inline constexpr int kMaxBackgroundFrames = 1000;
// Numbers of OpenCV distortion coefficients accepted (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 [tx
// ty]]]]).
inline constexpr int kDistortionSizes[] = {4, 5, 8, 12, 14};

// One depth frame: its PNG, relative to the folder, and its device-clock time stamp [s].
struct RecordingFrame {
  std::string file;
  double time_s = 0.0;  // finite; strictly increasing within a camera
};

// One camera's calibration and depth video.
struct RecordingCamera {
  // Name, size, intrinsics, and X_WC (identity when the recording gives no world_from_camera).
  capture::PinholeCamera camera;
  bool has_world_from_camera = false;
  // OpenCV distortion coefficients of the depth image (empty: none); 4, 5, 8, 12 or 14 of them.
  std::vector<double> distortion;
  double depth_scale = 0.001;  // [m per PNG unit], > 0
  std::vector<RecordingFrame> frames;
  // PNGs of the empty scene (no object), relative to the folder; may be empty.
  std::vector<std::string> background;
};

// The length unit of the mesh file's coordinates.
enum class MeshUnit { kMetre, kMillimetre };
// Metres per mesh unit: 1 or 0.001.
double MetresPerUnit(MeshUnit unit);
// "m" or "mm", as in recording.json.
std::string_view ToString(MeshUnit unit);

struct Recording {
  // Recording folder; set by ReadRecording, not stored in recording.json.
  std::filesystem::path directory;
  // Scanned rest shape in the scanner's frame, in mesh_unit, relative to the folder.
  std::string mesh_file = "scan.ply";
  MeshUnit mesh_unit = MeshUnit::kMetre;
  std::optional<double> mass_kg;  // [kg], > 0 when present
  std::vector<RecordingCamera> cameras;

  int NumCameras() const { return static_cast<int>(cameras.size()); }
};

// recording.json contents of `recording` (directory is not stored). Optional fields are omitted
// when unset (world_from_camera when has_world_from_camera is false); mesh_unit is always written.
// Doubles round-trip exactly.
nlohmann::json ToJson(const Recording& recording);

// Parses and validates recording.json contents without touching any file: format and version,
// required fields and their JSON types, values, limits, relative paths that stay inside the
// folder (lexically), unique folder-safe camera names, strictly increasing time stamps, poses for
// every camera when there are several. Errors are InvalidArgument
// "<source>: <field path> = <value>: <reason>". The result has an empty directory.
Result<Recording> RecordingFromJson(const nlohmann::json& json,
                                    std::string_view source = kRecordingFileName);

// Reads <directory>/recording.json (untrusted-JSON limits of capture::kCaptureJsonLimits) with
// RecordingFromJson, then checks the files it references: the mesh loads, is not empty, encloses
// a volume and has a longest side in [kMinMeshExtent_m, kMaxMeshExtent_m] after mesh_unit; every
// frame and background file exists and has a 16-bit single-channel PNG header of its camera's
// size (pixels are not decoded); no path leaves the folder through a symlink. NotFound when the
// folder or recording.json does not exist; InvalidArgument naming recording.json, the field, the
// value and the problem for anything else.
Result<Recording> ReadRecording(const std::filesystem::path& directory);

// Loads the recording's mesh in metres (scanner frame): the file scaled by mesh_unit.
Result<geometry::TriangleMesh> LoadRecordingMesh(const Recording& recording);

// Loads frame `frame` of camera `camera`: depth in metres along the camera z axis, still
// distorted. InvalidArgument naming the index when it is out of range; otherwise as ReadDepthPng.
Result<capture::DepthImage> LoadRecordingFrame(const Recording& recording, int camera, int frame);
// Loads background frame `background` of camera `camera`, as LoadRecordingFrame.
Result<capture::DepthImage> LoadBackgroundFrame(const Recording& recording, int camera,
                                                int background);

// The kind of softid folder.
enum class FolderFormat { kCapture, kRecording };
// kCapture when `directory` holds capture.json, kRecording when it holds recording.json.
// InvalidArgument when it holds both (ambiguous); NotFound naming both file names when it holds
// neither or does not exist. Reads neither file.
Result<FolderFormat> DetectFolderFormat(const std::filesystem::path& directory);

// Writes a recording folder (for the synthetic-recording generator and tests): `mesh` (metres,
// scanner frame) converted to recording.mesh_unit, as OBJ or PLY after the extension of
// recording.mesh_file ("scan.ply" when empty); frames_per_camera[i][k] as
// <camera name>/%06d.png and background_per_camera[i][b] as <camera name>/bg_%03d.png with camera
// i's depth_scale; recording.json last (through a temporary file renamed into place, after
// removing any previous recording.json) so an interrupted write never looks complete. The
// directory and the file names in the cameras' frames and background are ignored (names are
// generated); the frames' time stamps are kept, so cameras[i].frames has one entry per image of
// frames_per_camera[i]. background_per_camera is empty (no background) or has one list per
// camera. Everything is validated before the first file is written: the rules of
// RecordingFromJson, image sizes matching the cameras, the mesh's size after mesh_unit, no
// capture.json in the folder. InvalidArgument for invalid input (also for depths a PNG cannot
// store, see WriteDepthPng), IoError when a file cannot be written.
Status WriteRecording(
    const std::filesystem::path& directory, const Recording& recording,
    const geometry::TriangleMesh& mesh,
    const std::vector<std::vector<capture::DepthImage>>& frames_per_camera,
    const std::vector<std::vector<capture::DepthImage>>& background_per_camera = {});

}  // namespace softid::recording
