// Stage 4 of the ingest: where the scanned mesh sits at the release. It is registered to the
// object's points in the first frame of every camera that saw the release at camera 0's time
// (mesh_registration.h), then refined on the points inside its posed silhouette that read within
// the registration's distance of it on either side: chosen by where they are in the image and a
// window about the mesh, not by how far in front of the scene they read, so noise does not choose
// them (near the foreground's margin that keeps the readings noise moved towards the camera, which
// pulls the mesh that way: pillow on a ramp at 2 m, vertex RMS 1.36 -> 1.12 mm, 0.63 -> 0.37 deg).
#pragma once

#include <vector>

#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"
#include "core/ingest/camera_view.h"
#include "core/ingest/ingest.h"
#include "core/recording/recording.h"

namespace softid::ingest {

// Fills report->registration, registration_cameras, registration_points and X_WS. The views hold
// every camera's lens, scene, world pose and object points (stages 1 to 3). FailedPrecondition
// naming camera 0's first frame when the mesh's size cannot match the points or no pose
// converges.
Status PoseMeshAtRelease(const recording::Recording& rec, const geometry::TriangleMesh& mesh_S,
                         const IngestOptions& options, const std::vector<CameraView>& views,
                         IngestReport* report);

}  // namespace softid::ingest
