// The world frame of a one-camera recording without a measured camera pose, built on the floor:
// z along the floor's normal (up, gravity -z), the origin on the floor below the camera, x along
// the camera's viewing direction projected onto the floor.
#pragma once

#include <Eigen/Geometry>

#include "core/ingest/floor_plane.h"

namespace softid::ingest {

// X_WC of the camera that saw `floor` (in its own frame).
Eigen::Isometry3d WorldFromFloor(const FloorPlane& floor);

// The floor plane in the world frame: n_W . p_W = offset_W.
struct WorldPlane {
  Eigen::Vector3d normal_W{0, 0, 1};
  double offset_m = 0.0;
};
WorldPlane FloorInWorld(const FloorPlane& floor, const Eigen::Isometry3d& X_WC);

}  // namespace softid::ingest
