#include "core/scenes/camera_rig.h"

#include <cmath>
#include <numbers>

#include "core/common/json_fields.h"

namespace softid::scenes {

Status CameraRigOptions::Validate() const {
  using json::Invalid;
  if (count < 1) return Invalid("cameras", count, "must be at least 1");
  if (width < 1) return Invalid("width", width, "must be at least 1");
  if (height < 1) return Invalid("height", height, "must be at least 1");
  if (!(field_of_view > 0.0 && field_of_view < 180.0)) {
    return Invalid("field_of_view", field_of_view, "must lie in (0, 180) degrees");
  }
  if (!(elevation > -90.0 && elevation < 90.0)) {
    return Invalid("elevation", elevation, "must lie in (-90, 90) degrees");
  }
  if (!std::isfinite(azimuth)) return Invalid("azimuth", azimuth, "must be finite");
  if (!(distance >= 0.0) || !std::isfinite(distance)) {
    return Invalid("distance", distance, "must be non-negative and finite");
  }
  return Status::Ok();
}

std::vector<capture::PinholeCamera> MakeCameraRing(const CameraRigOptions& options,
                                                   const Eigen::Vector3d& target,
                                                   double view_radius) {
  constexpr double kDegree = std::numbers::pi / 180.0;
  const double half_fov = 0.5 * options.field_of_view * kDegree;
  const double fx = 0.5 * options.width / std::tan(half_fov);
  // Fit the view sphere into the narrower image side, with 10 % margin.
  const double narrow_half_fov = std::atan(0.5 * std::min(options.width, options.height) / fx);
  const double distance =
      options.distance > 0.0 ? options.distance : 1.1 * view_radius / std::sin(narrow_half_fov);
  std::vector<capture::PinholeCamera> cameras;
  for (int i = 0; i < options.count; ++i) {
    const double azimuth = (options.azimuth + 360.0 * i / options.count) * kDegree;
    const double elevation = options.elevation * kDegree;
    const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth),
                                    std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
    capture::PinholeCamera camera;
    camera.name = "cam" + std::to_string(i);
    camera.width = options.width;
    camera.height = options.height;
    camera.fx = fx;
    camera.fy = fx;
    camera.cx = 0.5 * (options.width - 1);
    camera.cy = 0.5 * (options.height - 1);
    camera.X_WC = capture::LookAt(target + distance * direction, target, Eigen::Vector3d::UnitZ());
    cameras.push_back(camera);
  }
  return cameras;
}

}  // namespace softid::scenes
