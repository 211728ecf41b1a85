// The floor in a camera's view: the largest plane of the static scene whose normal points up
// (within a tilt of an "up" hint), found by RANSAC and refined by least squares over its inliers
// (Open3D). The world frame of a one-camera recording is built on it, and it gives the ground's
// starting value.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/common/status.h"

namespace softid::ingest {

// The plane n . p = offset_m in the camera frame, n a unit vector pointing to the side of the
// camera (up, for a floor seen from above).
struct FloorPlane {
  Eigen::Vector3d normal_C{0, 0, -1};
  double offset_m = 0.0;
  int inliers = 0;            // static points within the threshold
  double inlier_share = 0.0;  // of all points given
  double rms_m = 0.0;         // RMS distance of the inliers to the plane
  double threshold_m = 0.0;   // inlier distance used

  double SignedDistance(const Eigen::Vector3d& p_C) const { return normal_C.dot(p_C) - offset_m; }
};

struct FloorPlaneOptions {
  // Inlier distance: this many times the median depth noise of the points, at least
  // min_threshold_m (a quantised sensor's noise can read as zero) [m].
  double noise_multiple = 3.0;
  double min_threshold_m = 0.003;
  // Planes are peeled off the points largest first, at most this many, each holding at least
  // min_share of the points; the floor is the largest whose normal lies within max_tilt_deg of
  // the up hint (walls are ~90 degrees off).
  int max_planes = 5;
  double min_share = 0.03;
  double max_tilt_deg = 45.0;
  int ransac_iterations = 2000;
  unsigned seed = 1;  // RANSAC draws: the same points give the same plane

  Status Validate() const;
};

// The floor among `points_C` (static-scene points in the camera frame [m]) with per-point noise
// `sigmas_m` (same size, or empty: min_threshold_m), `up_hint_C` a rough up direction in the
// camera frame (e.g. (0, -1, 0) for an upright camera: OpenCV's y points down). NotFound naming
// the planes seen when no plane within the tilt holds min_share of the points.
Result<FloorPlane> FindFloorPlane(const std::vector<Eigen::Vector3d>& points_C,
                                  const std::vector<float>& sigmas_m,
                                  const Eigen::Vector3d& up_hint_C,
                                  const FloorPlaneOptions& options = {});

}  // namespace softid::ingest
