// Observed depth points over the fitted simulation's surface at a few frames, drawn in two
// orthographic views with the world's up vertical: "front" looks the way the first camera looks
// (levelled), "side" from 90 degrees to its left. Each point is coloured by its residual against
// the noise floor, so a person sees where and when the simulation and the recording part.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::diagnosis {

struct SurfaceSnapshot {
  int frame = 0;                        // capture frame index
  double time_s = 0.0;                  // [s]
  geometry::TriangleMesh surface;       // the simulated surface, world frame [m]
  std::vector<Eigen::Vector3d> points;  // the frame's observed points, world frame [m]
  std::vector<float> phi;               // each point's residual [m] (points.size())
  std::vector<char> matched;            // whether each point matched the surface (points.size())
};

struct SurfaceOverlayView {
  Eigen::Vector3d up_W{0, 0, 1};     // drawn vertical; unit
  Eigen::Vector3d front_W{0, 1, 0};  // the front view's direction of sight; unit, normal to up_W
  double noise_floor_m = 0.0;        // residual colour scale: 3 x this is red; > 0
  std::optional<fem::GroundPlane> ground;  // drawn as a line where it cuts each view
};

// Two rows (front, side), one column per snapshot. InvalidArgument when there is nothing to draw
// or a snapshot's residuals do not match its points; IoError when the file cannot be written.
Status WriteSurfaceOverlay(const std::filesystem::path& path,
                           const std::vector<SurfaceSnapshot>& snapshots,
                           const SurfaceOverlayView& view);

}  // namespace softid::diagnosis
