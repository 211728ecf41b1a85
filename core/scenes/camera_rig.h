// Synthetic camera placement: N pinhole cameras on a ring around a target, all looking at it.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/capture/camera.h"
#include "core/common/status.h"

namespace softid::scenes {

struct CameraRigOptions {
  int count = 1;                // [-], >= 1
  int width = 64;               // [px], >= 1
  int height = 64;              // [px], >= 1
  double field_of_view = 50.0;  // horizontal [deg], in (0, 180)
  double elevation = 25.0;      // above the target's horizontal plane [deg], in (-90, 90)
  double azimuth = -90.0;       // of the first camera, from +x towards +y [deg]
  // Distance from the target [m]; 0 frames a sphere of the scene's view radius with a margin.
  double distance = 0.0;
  Status Validate() const;
};

// Cameras named cam0, cam1, ... spaced evenly in azimuth, up = +z.
std::vector<capture::PinholeCamera> MakeCameraRing(const CameraRigOptions& options,
                                                   const Eigen::Vector3d& target,
                                                   double view_radius);

}  // namespace softid::scenes
