#include "core/ingest/capture_frames.h"

#include <optional>
#include <vector>

#include "core/common/for_each_index.h"
#include "core/ingest/mask_completion.h"

namespace softid::ingest {
namespace {

using capture::DepthImage;

// The object's points drawn into the camera's ideal pinhole image: each point at its nearest
// pixel, the nearest point winning.
DepthImage SplatToPinhole(const std::vector<Eigen::Vector3d>& points_C,
                          const capture::PinholeCamera& camera) {
  DepthImage image = DepthImage::Zeros(camera.width, camera.height);
  for (const Eigen::Vector3d& p : points_C) {
    if (p.z() <= 0.0) continue;
    const int col = static_cast<int>(std::lround(camera.fx * p.x() / p.z() + camera.cx));
    const int row = static_cast<int>(std::lround(camera.fy * p.y() / p.z() + camera.cy));
    if (col < 0 || row < 0 || col >= camera.width || row >= camera.height) continue;
    float& z = image.at(col, row);
    if (z == 0.0f || p.z() < z) z = static_cast<float>(p.z());
  }
  return image;
}

// Per recording frame of camera c, the capture frames that show it.
std::vector<std::vector<int>> CaptureFramesOf(const recording::Recording& rec, int c,
                                              const Timeline& timeline) {
  std::vector<std::vector<int>> out(rec.cameras[c].frames.size());
  for (size_t i = 0; i < timeline.frames.size(); ++i) {
    const int k = timeline.frames[i].frame_of[c];
    if (k >= 0) out[k].push_back(static_cast<int>(i));
  }
  return out;
}

Status CheckNotCancelled(const IngestOptions& options) {
  if (options.cancel != nullptr && options.cancel->load(std::memory_order_relaxed))
    return Status::Cancelled("ingest: cancelled");
  return Status::Ok();
}

// Completes recording frame k's object mask with the posed mesh (mask_completion.h) and records
// what it added (-1 where no pose held) and the mask's new size.
void CompleteMask(const DepthImage& image, int k, MaskCompleter* completer, CameraIngest* report) {
  std::vector<int>& mask = report->object_masks[k];
  const FrameCompletion done = mask.empty() ? FrameCompletion{} : completer->Complete(image, &mask);
  report->completed_pixels.push_back(done.posed ? done.pixels_added : -1);
  report->object_pixels[k] = static_cast<int>(mask.size());
}

// Writes the object's pixels of a recording frame, drawn into the ideal pinhole image, as each
// capture frame that shows it.
Status WriteFrameOfMask(const DepthImage& image, const std::vector<int>& mask,
                        const std::vector<int>& capture_frames, int c, const CameraView& view,
                        const capture::PinholeCamera& camera, capture::CaptureWriter* writer) {
  if (capture_frames.empty()) return Status::Ok();
  std::vector<Eigen::Vector3d> points_C;
  points_C.reserve(mask.size());
  for (const int p : mask) {
    const Eigen::Vector2d& xy = view.rays.xy[p];
    points_C.push_back(image.depth[p] * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
  }
  const DepthImage pinhole = SplatToPinhole(points_C, camera);
  for (const int j : capture_frames) SOFTID_RETURN_IF_ERROR(writer->WriteFrame(c, j, pinhole));
  return Status::Ok();
}

// The capture frames camera c did not record (a dropped frame) are written empty.
Status WriteUnseenFrames(const Timeline& timeline, int c, const capture::PinholeCamera& camera,
                         capture::CaptureWriter* writer) {
  const DepthImage empty = DepthImage::Zeros(camera.width, camera.height);
  for (size_t i = 0; i < timeline.frames.size(); ++i) {
    if (timeline.frames[i].frame_of[c] < 0)
      SOFTID_RETURN_IF_ERROR(writer->WriteFrame(c, static_cast<int>(i), empty));
  }
  return Status::Ok();
}

}  // namespace

Status WriteCameraFrames(const recording::Recording& rec, int c,
                         const geometry::TriangleMesh& mesh_S, const Eigen::Isometry3d& X_WS,
                         const IngestOptions& options, const Timeline& timeline,
                         const CameraView& view, capture::CaptureWriter* writer,
                         CameraIngest* report, const IngestProgress& progress) {
  const recording::RecordingCamera& camera = rec.cameras[c];
  const int n = static_cast<int>(camera.frames.size());
  const std::vector<std::vector<int>> capture_frames = CaptureFramesOf(rec, c, timeline);
  std::optional<MaskCompleter> completer;
  report->completed_pixels.clear();
  if (options.mask_completion.enabled) {
    completer.emplace(mesh_S, X_WS, view, camera.camera, camera.distortion, MedianSigma(view.scene),
                      options.mask_completion);
  }
  // Frames are read side by side a few per worker at a time, completed in order (each pose starts
  // from the last ones), and written side by side again.
  const int workers = options.threads > 0 ? options.threads : CoreCount();
  const int chunk = 2 * workers;
  std::vector<Result<DepthImage>> images(chunk, Status::Internal("unread"));
  std::vector<Status> written(chunk);
  for (int first = 0; first < n; first += chunk) {
    SOFTID_RETURN_IF_ERROR(CheckNotCancelled(options));
    const int count = std::min(chunk, n - first);
    ForEachIndex(count, workers, [&](size_t i) {
      images[i] = recording::LoadRecordingFrame(rec, c, first + static_cast<int>(i));
    });
    for (int i = 0; i < count; ++i) {
      SOFTID_RETURN_IF_ERROR(images[i].status());
      if (completer) CompleteMask(*images[i], first + i, &*completer, report);
    }
    ForEachIndex(count, workers, [&](size_t i) {
      const int k = first + static_cast<int>(i);
      written[i] = WriteFrameOfMask(*images[i], report->object_masks[k], capture_frames[k], c, view,
                                    camera.camera, writer);
    });
    for (int i = 0; i < count; ++i) SOFTID_RETURN_IF_ERROR(written[i]);
    for (int i = 0; i < count; ++i) {
      if (progress) progress("masks", first + i + 1, n);
    }
  }
  return WriteUnseenFrames(timeline, c, camera.camera, writer);
}

}  // namespace softid::ingest
