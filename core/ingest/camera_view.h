// What the ingest knows of one camera while it works: its lens, static scene, pose in the world
// and the object's points in every recording frame.
#pragma once

#include <Eigen/Geometry>
#include <vector>

#include "core/capture/pixel_rays.h"
#include "core/ingest/static_scene.h"

namespace softid::ingest {

struct CameraView {
  capture::PixelRays rays;
  StaticScene scene;
  Eigen::Isometry3d X_WC = Eigen::Isometry3d::Identity();
  std::vector<std::vector<Eigen::Vector3d>> object_points_C;  // per recording frame
};

}  // namespace softid::ingest
