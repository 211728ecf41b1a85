#include "core/ingest/ingest.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>

#include "core/capture/capture.h"
#include "core/capture/capture_writer.h"
#include "core/capture/pixel_rays.h"
#include "core/common/for_each_index.h"
#include "core/ingest/camera_view.h"
#include "core/ingest/capture_frames.h"
#include "core/ingest/contact_sheet.h"
#include "core/ingest/release_pose.h"
#include "core/ingest/timeline.h"

namespace softid::ingest {
namespace {

using capture::DepthImage;

// Seconds since the last lap (or construction).
class StageClock {
 public:
  double Lap() {
    const auto now = std::chrono::steady_clock::now();
    const double seconds = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    return seconds;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

Result<StaticScene> CameraStaticScene(const recording::Recording& rec, int c,
                                      const IngestOptions& options, bool* from_background) {
  const recording::RecordingCamera& camera = rec.cameras[c];
  *from_background = !camera.background.empty();
  // The background frames, else at most max_static_frames frames spread over the recording; read
  // side by side.
  const int n = static_cast<int>(camera.frames.size());
  const int count = *from_background ? static_cast<int>(camera.background.size())
                                     : std::min(n, options.max_static_frames);
  std::vector<Result<DepthImage>> read(count, Status::Internal("unread"));
  ForEachIndex(count, options.threads > 0 ? options.threads : CoreCount(), [&](size_t i) {
    const int k = count == 1 ? 0 : static_cast<int>(std::lround(i * (n - 1.0) / (count - 1.0)));
    read[i] = *from_background ? recording::LoadBackgroundFrame(rec, c, static_cast<int>(i))
                               : recording::LoadRecordingFrame(rec, c, k);
  });
  std::vector<DepthImage> images;
  for (Result<DepthImage>& image : read) {
    SOFTID_RETURN_IF_ERROR(image.status());
    images.push_back(std::move(*image));
  }
  StaticSceneOptions scene_options = options.static_scene;
  if (scene_options.threads == 0) scene_options.threads = options.threads;
  return *from_background ? EstimateEmptyScene(images, scene_options)
                          : EstimateStaticScene(images, scene_options);
}

Status CheckNotCancelled(const IngestOptions& options) {
  if (options.cancel != nullptr && options.cancel->load(std::memory_order_relaxed))
    return Status::Cancelled("ingest: cancelled");
  return Status::Ok();
}

bool OnBorder(int pixel, int width, int height) {
  const int row = pixel / width, col = pixel % width;
  return row == 0 || col == 0 || row == height - 1 || col == width - 1;
}

// A static scene from the recording's own frames: the pixels the object covers in the first frame
// may show it in every frame (see MarkHiddenByTheObject).
Status MarkHiddenPixels(const recording::Recording& rec, int c, const WorldPlane& floor_W,
                        const IngestOptions& options, CameraView* view) {
  SOFTID_ASSIGN_OR_RETURN(DepthImage first, recording::LoadRecordingFrame(rec, c, 0));
  SOFTID_ASSIGN_OR_RETURN(Foreground fg,
                          SegmentForeground(first, view->scene, view->rays, options.foreground));
  if (fg.regions.empty()) return Status::Ok();  // SegmentCamera reports it
  const Eigen::Matrix3d& R_WC = view->X_WC.linear();
  const Eigen::Vector3d normal_C = R_WC.transpose() * floor_W.normal_W;
  const double offset_C = floor_W.offset_m - floor_W.normal_W.dot(view->X_WC.translation());
  MarkHiddenByTheObject(fg.regions[0].pixels, normal_C, offset_C, view->rays, options.static_scene,
                        &view->scene);
  return Status::Ok();
}

// The mean of `points`; none for none.
std::optional<Eigen::Vector3d> MeanOf(const std::vector<Eigen::Vector3d>& points) {
  if (points.empty()) return std::nullopt;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) sum += p;
  return sum / static_cast<double>(points.size());
}

// Whether any of `pixels` lies on the image's border.
bool OnBorderAnywhere(const std::vector<int>& pixels, const DepthImage& image) {
  for (const int pixel : pixels) {
    if (OnBorder(pixel, image.width, image.height)) return true;
  }
  return false;
}

// Picks the object among frame k's foreground regions (in order: the tracker follows it), puts its
// points in *points_C and records its mask, pixel count and centre.
Status TrackFrame(const recording::Recording& rec, int c, int k, const DepthImage& image,
                  const Foreground& foreground, ObjectTracker* tracker,
                  std::vector<Eigen::Vector3d>* points_C, CameraView* view, CameraIngest* report) {
  const recording::RecordingCamera& camera = rec.cameras[c];
  const TrackedFrame tracked = tracker->Track(foreground, view->X_WC, camera.frames[k].time_s);
  if (k == 0 && !tracked.found) {
    return Status::FailedPrecondition(fmt::format(
        "ingest: camera \"{}\" frame 0 ({}): no foreground: nothing is nearer than the static "
        "scene (is the object in view, and does it move during the recording?)",
        camera.camera.name, camera.frames[0].file));
  }
  points_C->clear();
  points_C->reserve(tracked.pixels.size());
  for (const int pixel : tracked.pixels) {
    const Eigen::Vector2d& xy = view->rays.xy[pixel];
    points_C->push_back(image.depth[pixel] * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
  }
  report->object_pixels.push_back(static_cast<int>(tracked.pixels.size()));
  report->rejected_regions.push_back(tracked.rejected_regions);
  report->object_masks.push_back(tracked.pixels);
  view->centres_C.push_back(MeanOf(*points_C));
  return Status::Ok();
}

// Segments and tracks the object through every frame of camera c; keeps each frame's mask in
// *report, frame 0's points and every frame's centre in *view.
Status SegmentCamera(const recording::Recording& rec, int c, double object_radius_m,
                     const IngestOptions& options, CameraView* view, CameraIngest* report,
                     const IngestProgress& progress) {
  const recording::RecordingCamera& camera = rec.cameras[c];
  const int n = static_cast<int>(camera.frames.size());
  ObjectTracker tracker(object_radius_m, options.tracking);
  int frames_on_border = 0;
  // Frames are read and segmented side by side, a few per worker at a time (memory stays bounded
  // on long recordings); tracking follows them in order.
  const int workers = options.threads > 0 ? options.threads : CoreCount();
  const int chunk = 2 * workers;
  std::vector<Result<DepthImage>> images(chunk, Status::Internal("unread"));
  std::vector<Result<Foreground>> segmented(chunk, Status::Internal("unsegmented"));
  std::vector<Eigen::Vector3d> points;
  for (int first = 0; first < n; first += chunk) {
    SOFTID_RETURN_IF_ERROR(CheckNotCancelled(options));
    const int count = std::min(chunk, n - first);
    ForEachIndex(count, workers, [&](size_t i) {
      images[i] = recording::LoadRecordingFrame(rec, c, first + static_cast<int>(i));
      segmented[i] = images[i].ok() ? SegmentForeground(*images[i], view->scene, view->rays,
                                                        options.foreground)
                                    : Result<Foreground>(images[i].status());
    });
    for (int i = 0; i < count; ++i) {
      SOFTID_RETURN_IF_ERROR(segmented[i].status());
      SOFTID_RETURN_IF_ERROR(TrackFrame(rec, c, first + i, *images[i], *segmented[i], &tracker,
                                        &points, view, report));
      frames_on_border += OnBorderAnywhere(report->object_masks.back(), *images[i]) ? 1 : 0;
      if (first + i == 0) view->release_points_C = points;
    }
    for (int i = 0; i < count; ++i) {
      SOFTID_RETURN_IF_ERROR(CheckNotCancelled(options));
      if (progress) progress("segmentation", first + i + 1, n);
    }
  }
  report->cut_off = frames_on_border == n;
  return Status::Ok();
}

// A camera that never sees the whole object still constrains the fit with what it sees; a
// recording where no camera does is set up wrong (and the mesh has no whole view to register to).
Status CheckSomeCameraSeesTheWholeObject(const recording::Recording& rec,
                                         const IngestReport& report) {
  for (const CameraIngest& camera : report.cameras) {
    if (!camera.cut_off) return Status::Ok();
  }
  return Status::FailedPrecondition(fmt::format(
      "ingest: camera \"{}\": the object touches the image border in all {} frames{}: it is cut "
      "off (move the camera back or the object into view)",
      rec.cameras[0].camera.name, rec.cameras[0].frames.size(),
      rec.NumCameras() > 1 ? ", as in every other camera" : ""));
}

Status WriteIngestJson(const std::filesystem::path& path, const IngestReport& report) {
  std::ofstream file(path);
  file << report.ToJson().dump(2) << "\n";
  file.close();
  if (!file) return Status::IoError(fmt::format("{}: cannot write", path.string()));
  return Status::Ok();
}

nlohmann::json PoseJson(const Eigen::Isometry3d& X) {
  nlohmann::json out = nlohmann::json::array();
  for (int i = 0; i < 16; ++i) out.push_back(X.matrix()(i / 4, i % 4));
  return out;
}

}  // namespace

Status IngestOptions::Validate() const {
  SOFTID_RETURN_IF_ERROR(static_scene.Validate());
  SOFTID_RETURN_IF_ERROR(foreground.Validate());
  SOFTID_RETURN_IF_ERROR(floor.Validate());
  SOFTID_RETURN_IF_ERROR(tracking.Validate());
  SOFTID_RETURN_IF_ERROR(registration.Validate());
  SOFTID_RETURN_IF_ERROR(mask_completion.Validate());
  if (max_static_frames < 1) {
    return Status::InvalidArgument(
        fmt::format("max_static_frames = {}: must be >= 1", max_static_frames));
  }
  if (!(same_time_s >= 0.0) || !std::isfinite(same_time_s)) {
    return Status::InvalidArgument(fmt::format("same_time_s = {}: must be >= 0", same_time_s));
  }
  if (threads < 0)
    return Status::InvalidArgument(fmt::format("threads = {}: must be >= 0", threads));
  return Status::Ok();
}

double IngestStageSeconds::Total() const {
  return static_scene + floor + segmentation + registration + masks + finishing;
}

nlohmann::json IngestReport::ToJson() const {
  nlohmann::json cams = nlohmann::json::array();
  for (const CameraIngest& c : cameras) {
    cams.push_back({{"name", c.name},
                    {"static_scene_from", c.static_from_background ? "background" : "frames"},
                    {"object_pixels", c.object_pixels},
                    {"rejected_regions", c.rejected_regions},
                    {"completed_pixels", c.completed_pixels},
                    {"cut_off", c.cut_off}});
  }
  return {{"format", "softid-ingest/1"},
          {"cameras", std::move(cams)},
          {"floor",
           {{"normal", {floor_W.normal_W.x(), floor_W.normal_W.y(), floor_W.normal_W.z()}},
            {"offset_m", floor_W.offset_m},
            {"inliers", floor_C.inliers},
            {"inlier_share", floor_C.inlier_share},
            {"rms_m", floor_C.rms_m},
            {"world_frame_from_floor", world_from_floor}}},
          {"registration",
           {{"overlap", registration.overlap},
            {"rms_m", registration.rms_m},
            {"max_distance_m", registration.max_distance_m},
            {"cameras", registration_cameras},
            {"points", registration_points},
            {"world_from_mesh", PoseJson(X_WS)}}},
          {"time",
           {{"origin_s", time_origin_s},
            {"frames", frame_times_s.size()},
            {"median_interval_s", median_interval_s},
            {"max_gap_s", max_gap_s}}},
          {"seconds",
           {{"static_scene", seconds.static_scene},
            {"floor", seconds.floor},
            {"segmentation", seconds.segmentation},
            {"registration", seconds.registration},
            {"masks", seconds.masks},
            {"finishing", seconds.finishing},
            {"total", seconds.Total()}}}};
}

namespace {

// Stage 2: the floor in camera 0's static scene, and every camera's pose in the world frame
// (given, or built on the floor for a single camera without one).
Status FloorAndWorld(const recording::Recording& rec, const IngestOptions& options,
                     std::vector<CameraView>* views, IngestReport* report) {
  const recording::RecordingCamera& camera0 = rec.cameras[0];
  std::vector<Eigen::Vector3d> points;
  std::vector<float> sigmas;
  StaticScenePoints((*views)[0].scene, (*views)[0].rays, &points, &sigmas);
  // Up: the world's z seen from a posed camera, else image up (OpenCV's y points down).
  const Eigen::Vector3d up_C = camera0.has_world_from_camera
                                   ? Eigen::Vector3d(camera0.camera.X_WC.linear().row(2))
                                   : Eigen::Vector3d(0.0, -1.0, 0.0);
  Result<FloorPlane> floor = FindFloorPlane(points, sigmas, up_C, options.floor);
  if (!floor.ok()) {
    return floor.status().WithContext(fmt::format("ingest: camera \"{}\"", camera0.camera.name));
  }
  report->floor_C = *floor;
  for (int c = 0; c < rec.NumCameras(); ++c) (*views)[c].X_WC = rec.cameras[c].camera.X_WC;
  if (!camera0.has_world_from_camera) {
    (*views)[0].X_WC = WorldFromFloor(*floor);
    report->world_from_floor = true;
  }
  report->floor_W = FloorInWorld(*floor, (*views)[0].X_WC);
  return Status::Ok();
}

// The object's centre in every frame of camera c, world frame (frames without points: none).
std::vector<std::optional<Eigen::Vector3d>> ObjectCentres(const CameraView& view) {
  std::vector<std::optional<Eigen::Vector3d>> centres;
  for (const std::optional<Eigen::Vector3d>& centre_C : view.centres_C) {
    centres.push_back(centre_C ? std::optional<Eigen::Vector3d>(view.X_WC * *centre_C)
                               : std::nullopt);
  }
  return centres;
}

// A recording must show the object released above the floor and moving: one resting on the floor
// at the release was never released (its rest shape is already squashed), and one that never
// moves tells nothing of its material. Movement is judged on each camera's own centres (one
// camera's view of the object shifts its centre), against 1 % of the mesh's size.
Status CheckTheObjectIsReleasedAndMoves(const recording::Recording& rec,
                                        const geometry::TriangleMesh& mesh_S,
                                        const std::vector<CameraView>& views,
                                        const IngestReport& report) {
  const double size_m = mesh_S.Bounds().diagonal().norm();
  const double tolerance_m = 0.01 * size_m;
  const Eigen::Vector3d& up = report.floor_W.normal_W;
  double lowest_m = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& v : mesh_S.vertices) {
    lowest_m = std::min(lowest_m, up.dot(report.X_WS * v) - report.floor_W.offset_m);
  }
  double moved_m = 0.0, rose_m = 0.0;
  for (const CameraView& view : views) {
    const std::vector<std::optional<Eigen::Vector3d>> centres = ObjectCentres(view);
    if (centres.empty() || !centres[0]) continue;
    for (const auto& centre : centres) {
      if (!centre) continue;
      moved_m = std::max(moved_m, (*centre - *centres[0]).norm());
      rose_m = std::max(rose_m, up.dot(*centre - *centres[0]));
    }
  }
  const int frames = static_cast<int>(rec.cameras[0].frames.size());
  if (lowest_m <= tolerance_m && rose_m <= tolerance_m) {
    return Status::FailedPrecondition(fmt::format(
        "ingest: the object never leaves the floor: at the release (frame 0) its lowest point is "
        "{:.1f} mm above the floor and over {} frames its centre never rises more than {:.1f} mm "
        "(a recording must show the object released above the floor)",
        1e3 * lowest_m, frames, 1e3 * rose_m));
  }
  if (moved_m <= tolerance_m) {
    return Status::FailedPrecondition(fmt::format(
        "ingest: the object never moves: over {} frames its centre stays within {:.1f} mm of "
        "where it was in frame 0 (1 % of its size is {:.1f} mm; a recording must show it released "
        "and moving)",
        frames, 1e3 * moved_m, 1e3 * tolerance_m));
  }
  return Status::Ok();
}

// The capture's cameras as the recording declares them (their poses come with Finish).
capture::Capture CaptureHeader(const recording::Recording& rec) {
  capture::Capture capture;
  capture.mesh_file = "object.obj";
  for (int c = 0; c < rec.NumCameras(); ++c) {
    capture::CameraRecording camera;
    camera.camera = rec.cameras[c].camera;
    camera.depth_scale = rec.cameras[c].depth_scale;
    capture.cameras.push_back(camera);
  }
  return capture;
}

// Stage 3 for camera c: the object's pixels in every frame (written once the mesh is posed).
Status SegmentCameraFrames(const recording::Recording& rec, int c, double object_radius_m,
                           const IngestOptions& options, CameraView* view, IngestReport* report,
                           const IngestProgress& progress) {
  if (!report->cameras[c].static_from_background)
    SOFTID_RETURN_IF_ERROR(MarkHiddenPixels(rec, c, report->floor_W, options, view));
  return SegmentCamera(rec, c, object_radius_m, options, view, &report->cameras[c], progress);
}

// Stage 6: the capture folder's mesh and capture.json (the frames are written): one clock, the
// cameras' poses, the floor. ingest.json follows.
Status FinishIngestedCapture(const recording::Recording& rec, const geometry::TriangleMesh& mesh_S,
                             const Timeline& timeline, const std::vector<CameraView>& views,
                             const std::filesystem::path& capture_dir,
                             capture::CaptureWriter* writer, IngestReport* report) {
  report->time_origin_s = timeline.origin_s;
  report->median_interval_s = timeline.median_interval_s;
  report->max_gap_s = timeline.max_gap_s;
  capture::Capture capture = CaptureHeader(rec);
  capture.fps = timeline.median_interval_s > 0.0 ? 1.0 / timeline.median_interval_s : 30.0;
  capture.mass_kg = rec.mass_kg;
  capture.floor = capture::Capture::Floor{report->floor_W.normal_W, report->floor_W.offset_m};
  for (int c = 0; c < rec.NumCameras(); ++c) capture.cameras[c].camera.X_WC = views[c].X_WC;
  for (const TimelineFrame& entry : timeline.frames) {
    capture.frame_times.push_back(entry.time_s);
    report->frame_times_s.push_back(entry.time_s);
  }
  geometry::TriangleMesh mesh_W = mesh_S;
  for (Eigen::Vector3d& v : mesh_W.vertices) v = report->X_WS * v;
  return writer->Finish(capture, mesh_W);
}

}  // namespace

Result<IngestReport> Ingest(const recording::Recording& rec,
                            const std::filesystem::path& capture_dir, const IngestOptions& options,
                            const IngestProgress& progress) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (rec.NumCameras() == 0) return Status::InvalidArgument("ingest: the recording has no camera");
  SOFTID_ASSIGN_OR_RETURN(const geometry::TriangleMesh mesh_S, recording::LoadRecordingMesh(rec));
  IngestReport report;
  StageClock clock;
  std::vector<CameraView> views(rec.NumCameras());
  report.cameras.resize(rec.NumCameras());
  // 1. Each camera's lens and static scene.
  for (int c = 0; c < rec.NumCameras(); ++c) {
    report.cameras[c].name = rec.cameras[c].camera.name;
    Result<capture::PixelRays> rays =
        capture::ComputePixelRays(rec.cameras[c].camera, rec.cameras[c].distortion);
    if (!rays.ok()) {
      return rays.status().WithContext(
          fmt::format("ingest: camera \"{}\"", rec.cameras[c].camera.name));
    }
    views[c].rays = std::move(*rays);
    SOFTID_ASSIGN_OR_RETURN(
        views[c].scene,
        CameraStaticScene(rec, c, options, &report.cameras[c].static_from_background));
    if (progress) progress("static scene", c + 1, rec.NumCameras());
    SOFTID_RETURN_IF_ERROR(CheckNotCancelled(options));
  }
  report.seconds.static_scene = clock.Lap();
  // 2. The floor and the world frame.
  SOFTID_RETURN_IF_ERROR(FloorAndWorld(rec, options, &views, &report));
  report.seconds.floor = clock.Lap();
  // 3. The object's pixels in every frame; the capture's frames on one clock.
  const double object_radius_m = 0.5 * mesh_S.Bounds().diagonal().norm();
  const Timeline timeline = MergeTimeline(rec, options.same_time_s);
  SOFTID_ASSIGN_OR_RETURN(capture::CaptureWriter writer,
                          capture::CaptureWriter::Create(capture_dir, CaptureHeader(rec),
                                                         static_cast<int>(timeline.frames.size())));
  for (int c = 0; c < rec.NumCameras(); ++c) {
    SOFTID_RETURN_IF_ERROR(
        SegmentCameraFrames(rec, c, object_radius_m, options, &views[c], &report, progress));
  }
  SOFTID_RETURN_IF_ERROR(CheckSomeCameraSeesTheWholeObject(rec, report));
  report.seconds.segmentation = clock.Lap();
  // 4. The mesh's pose at the release.
  SOFTID_RETURN_IF_ERROR(PoseMeshAtRelease(rec, mesh_S, options, views, &report));
  if (progress) progress("registration", 1, 1);
  SOFTID_RETURN_IF_ERROR(CheckTheObjectIsReleasedAndMoves(rec, mesh_S, views, report));
  SOFTID_RETURN_IF_ERROR(CheckNotCancelled(options));
  report.seconds.registration = clock.Lap();
  // 5. Every frame's mask completed by the posed mesh, into the capture.
  for (int c = 0; c < rec.NumCameras(); ++c) {
    SOFTID_RETURN_IF_ERROR(WriteCameraFrames(rec, c, mesh_S, report.X_WS, options, timeline,
                                             views[c], &writer, &report.cameras[c], progress));
  }
  report.seconds.masks = clock.Lap();
  // 6. The capture, a picture of what the ingest saw, and last the report with every stage's time.
  SOFTID_RETURN_IF_ERROR(
      FinishIngestedCapture(rec, mesh_S, timeline, views, capture_dir, &writer, &report));
  SOFTID_RETURN_IF_ERROR(
      WriteContactSheet(capture_dir / kContactSheetFileName, rec, report, mesh_S, views[0].rays));
  report.seconds.finishing = clock.Lap();
  SOFTID_RETURN_IF_ERROR(WriteIngestJson(capture_dir / "ingest.json", report));
  return report;
}

}  // namespace softid::ingest
