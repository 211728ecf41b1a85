// What the ingest knows of one camera while it works: its lens, static scene, pose in the world,
// the object's points at the release and its centre in every recording frame (the points of the
// other frames go to the capture as they are found, so a long recording is never held in memory).
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <vector>

#include "core/capture/pixel_rays.h"
#include "core/ingest/static_scene.h"

namespace softid::ingest {

struct CameraView {
  capture::PixelRays rays;
  StaticScene scene;
  Eigen::Isometry3d X_WC = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Vector3d> release_points_C;  // recording frame 0's
  // Per recording frame the mean of the object's points; none where it was not found.
  std::vector<std::optional<Eigen::Vector3d>> centres_C;
};

}  // namespace softid::ingest
