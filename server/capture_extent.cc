#include "server/capture_extent.h"

#include <system_error>

#include "core/capture/capture.h"
#include "server/materialize_capture.h"
#include "server/redact_paths.h"
#include "server/store/resource_id.h"

namespace softid::server {

namespace fs = std::filesystem;

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
