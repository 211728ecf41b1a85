#include "server/capture_extent.h"

#include <algorithm>
#include <system_error>

#include "core/capture/capture.h"
#include "core/recording/recording.h"
#include "server/materialize_capture.h"
#include "server/redact_paths.h"
#include "server/store/resource_id.h"

namespace softid::server {

namespace fs = std::filesystem;

namespace {

// A recording's extent before its ingest: the mesh after mesh_unit, and the most frames of a
// camera (the ingest merges the cameras' frames by time, so a capture frame per recorded one is
// the upper bound for one camera), evenly spaced.
ServiceResult<inverse::CaptureExtent> RecordingExtent(const store::Capture& stored,
                                                      const fs::path& dir) {
  Result<recording::Recording> recording = recording::ReadRecording(dir);
  if (!recording.ok()) {
    return ServiceStatus(
        ServiceCode::kFailedPrecondition,
        "capture " + stored.id + ": " + RedactPath(recording.status().message(), dir));
  }
  Result<geometry::TriangleMesh> mesh = recording::LoadRecordingMesh(*recording);
  if (!mesh.ok()) {
    return ServiceStatus(ServiceCode::kFailedPrecondition,
                         "capture " + stored.id + ": " + RedactPath(mesh.status().message(), dir));
  }
  inverse::CaptureExtent extent;
  extent.mesh_bounds = mesh->Bounds();
  extent.num_cameras = recording->NumCameras();
  for (const recording::RecordingCamera& camera : recording->cameras) {
    extent.num_frames = std::max(extent.num_frames, static_cast<int>(camera.frames.size()));
  }
  return extent;
}

}  // namespace

ServiceResult<inverse::CaptureExtent> ReadCaptureExtent(const store::Capture& stored,
                                                        const store::BlobStore& blobs,
                                                        const fs::path& scratch_root) {
  const fs::path dir = scratch_root / store::NewResourceId("extent-");
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ignored;
      fs::remove_all(dir, ignored);
    }
  } cleanup{dir};
  if (Status laid_out = MaterializeCapture(stored, blobs, dir); !laid_out.ok()) {
    return ServiceStatus(ServiceCode::kInternal,
                         "capture " + stored.id + ": " + RedactPath(laid_out.message(), dir));
  }
  if (stored.format == store::kRecordingFormat) return RecordingExtent(stored, dir);
  Result<capture::Capture> capture =
      capture::ReadCapture(dir, capture::ReadCaptureOptions{.decode_frames = false});
  if (!capture.ok()) {
    // Checked at upload; a capture stored before a rule was added may break a newer one.
    return ServiceStatus(
        ServiceCode::kFailedPrecondition,
        "capture " + stored.id + ": " + RedactPath(capture.status().message(), dir));
  }
  Result<geometry::TriangleMesh> mesh = capture::LoadCaptureMesh(*capture);
  if (!mesh.ok()) {
    return ServiceStatus(ServiceCode::kFailedPrecondition,
                         "capture " + stored.id + ": " + RedactPath(mesh.status().message(), dir));
  }
  inverse::CaptureExtent extent;
  extent.mesh_bounds = mesh->Bounds();
  extent.num_frames = capture->NumFrames();
  extent.num_cameras = capture->NumCameras();
  for (const double t : capture->frame_times) extent.frame_periods.push_back(t * capture->fps);
  return extent;
}

}  // namespace softid::server
