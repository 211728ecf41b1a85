// Stage 5 of the ingest: each camera's frames read again in order, the object's mask completed by
// the mesh posed at the release and followed from frame to frame (mask_completion.h), and the
// object's pixels written to the capture at their capture frames, each drawn at its nearest pixel
// of the camera's ideal pinhole (never a blend of depths).
#pragma once

#include <Eigen/Geometry>

#include "core/capture/capture_writer.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"
#include "core/ingest/camera_view.h"
#include "core/ingest/ingest.h"
#include "core/ingest/timeline.h"
#include "core/recording/recording.h"

namespace softid::ingest {

// Camera c's frames: report->object_masks (as segmented) are completed in place, object_pixels
// follow them and completed_pixels says what was added; empty images go where the camera has no
// frame at a capture frame's moment. X_WS: the mesh's pose at the release.
Status WriteCameraFrames(const recording::Recording& rec, int c,
                         const geometry::TriangleMesh& mesh_S, const Eigen::Isometry3d& X_WS,
                         const IngestOptions& options, const Timeline& timeline,
                         const CameraView& view, capture::CaptureWriter* writer,
                         CameraIngest* report, const IngestProgress& progress);

}  // namespace softid::ingest
