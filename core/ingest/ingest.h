// A raw recording (softid-recording/1) turned into a capture (softid-capture/1) that every fit and
// the service read: the static scene and the object's pixels in every frame, the floor and the
// world frame, the scanned mesh posed at the release, one clock for all cameras. The stages are
// in this folder; this runs them in order and writes the capture and ingest.json.
#pragma once

#include <Eigen/Geometry>
#include <atomic>
#include <filesystem>
#include <functional>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/ingest/floor_plane.h"
#include "core/ingest/foreground.h"
#include "core/ingest/mask_completion.h"
#include "core/ingest/mesh_registration.h"
#include "core/ingest/object_tracking.h"
#include "core/ingest/static_scene.h"
#include "core/ingest/world_frame.h"
#include "core/recording/recording.h"

namespace softid::ingest {

struct IngestOptions {
  StaticSceneOptions static_scene;
  ForegroundOptions foreground;
  FloorPlaneOptions floor;
  ObjectTrackingOptions tracking;
  MeshRegistrationOptions registration;
  MaskCompletionOptions mask_completion;
  // Without background frames, the static scene comes from at most this many frames spread over
  // the recording (memory stays bounded for long recordings).
  int max_static_frames = 64;
  // Frames of different cameras this close in time form one capture frame [s].
  double same_time_s = 1e-4;
  // Threads reading and segmenting frames side by side, and sorting the static scene's readings
  // when static_scene.threads is 0; 0 = one per core. The registration has its own
  // (registration.threads).
  int threads = 0;  // >= 0
  // Checked between frames and stages; once set, Ingest stops with Cancelled and writes no
  // capture.json. Not owned; null: never cancelled.
  const std::atomic<bool>* cancel = nullptr;

  Status Validate() const;
};

struct CameraIngest {
  std::string name;
  bool static_from_background = false;
  std::vector<int> object_pixels;     // per recording frame (0: object not found)
  std::vector<int> rejected_regions;  // per recording frame: foreground left out
  bool cut_off = false;               // the object touches the image border in every frame
  // Per recording frame: the object's pixels (row-major indices in the raw, distorted image),
  // completed by the posed mesh (mask_completion.h).
  std::vector<std::vector<int>> object_masks;
  // Per recording frame: the pixels the posed mesh added to the mask, or -1 where no pose was
  // found (the mask is as segmented); empty when the completion is off.
  std::vector<int> completed_pixels;
};

// Wall time of the ingest's stages [s]. Only the segmentation and the masks grow with the
// recording's length: the static scene reads at most max_static_frames frames (or the background
// frames), and the others work on the first frame or on the whole capture's summary.
struct IngestStageSeconds {
  double static_scene = 0.0;  // every camera's lens and static scene
  double floor = 0.0;         // the floor and the world frame
  double segmentation = 0.0;  // every frame of every camera read, segmented and tracked
  double registration = 0.0;  // the mesh's pose at the release and the checks on the motion
  double masks = 0.0;         // every frame read again, its mask completed and written
  double finishing = 0.0;     // the mesh, capture.json and the contact sheet
  double Total() const;
};

struct IngestReport {
  std::vector<CameraIngest> cameras;
  FloorPlane floor_C;             // in camera 0's frame
  WorldPlane floor_W;             // in the world frame
  bool world_from_floor = false;  // the world frame was built on the floor (no camera pose given)
  MeshRegistration registration;  // in camera 0's frame, on the cameras' first frames
  // The cameras whose first frames the mesh was registered to (those that saw the release at
  // camera 0's time), and how many of the object's points they gave.
  std::vector<std::string> registration_cameras;
  int registration_points = 0;
  Eigen::Isometry3d X_WS = Eigen::Isometry3d::Identity();  // mesh pose at the release
  double time_origin_s = 0.0;                              // device-clock time of t = 0
  std::vector<double> frame_times_s;
  double median_interval_s = 0.0, max_gap_s = 0.0;
  IngestStageSeconds seconds;

  // ingest.json contents (masks left out).
  nlohmann::json ToJson() const;
};

// The ingest's picture in the capture folder (contact_sheet.h).
inline constexpr std::string_view kContactSheetFileName = "ingest.png";

using IngestProgress = std::function<void(std::string_view stage, int done, int total)>;

// Ingests `recording` into the capture folder `capture_dir` (capture.json, object.obj, per-camera
// frames with only the object's pixels, undistorted onto the camera's ideal pinhole without
// interpolation; frame_times) plus ingest.json and ingest.png (contact_sheet.h). Errors name the
// stage, the camera and the frame: no foreground, the object on the image border in every frame of
// every camera, a mesh whose size cannot match the object's points, a registration that does not
// converge (overlap and RMS), no floor. Cancelled when options.cancel is set meanwhile. Frames
// are written as their masks are completed (capture_writer.h): of each frame only the object's
// mask stays in memory (the report's), not its images or points; an ingest that fails before its
// capture is complete (segmentation, registration) leaves an earlier capture in `capture_dir` as
// it was.
Result<IngestReport> Ingest(const recording::Recording& recording,
                            const std::filesystem::path& capture_dir,
                            const IngestOptions& options = {}, const IngestProgress& progress = {});

}  // namespace softid::ingest
