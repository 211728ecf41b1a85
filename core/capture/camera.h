// Pinhole depth cameras with OpenCV axes (x right, y down, z forward) and pixel conventions.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <string_view>

#include "core/common/status.h"

namespace softid::capture {

// An ideal pinhole camera (no lens distortion). Pixel coordinates (u, v) follow OpenCV: the centre
// of the pixel in column `col` and row `row` is at (u, v) = (col, row), so the image covers
// [-0.5, width - 0.5] x [-0.5, height - 0.5].
struct PinholeCamera {
  std::string name;
  int width = 0;    // [pixels]
  int height = 0;   // [pixels]
  double fx = 0.0;  // focal length [pixels]
  double fy = 0.0;  // focal length [pixels]
  double cx = 0.0;  // principal point [pixels]
  double cy = 0.0;  // principal point [pixels]
  // Pose of camera frame C in world W [m]; C has OpenCV axes (x right, y down, z forward).
  Eigen::Isometry3d X_WC = Eigen::Isometry3d::Identity();

  // Direction in C of the ray through pixel coordinates (u, v), scaled so that its z component is
  // 1: ((u - cx) / fx, (v - cy) / fy, 1). A point at depth z along it is z * RayDirection_C(u, v).
  Eigen::Vector3d RayDirection_C(double u, double v) const;

  // Pixel coordinates (u, v) of the world point p_W [m], or nullopt when it is not in front of the
  // camera (z_C <= 0). The result may lie outside the image.
  std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& p_W) const;

  // Depth of p_W along the camera z axis [m] (negative behind the camera).
  double Depth(const Eigen::Vector3d& p_W) const;

  // World point p_W [m] seen at pixel coordinates (u, v) with depth depth_z [m] along the camera z
  // axis (not along the ray).
  Eigen::Vector3d Unproject(double u, double v, double depth_z) const;

  // OK when width, height, fx, fy are positive and finite, (cx, cy) lies inside the image
  // ([-0.5, width - 0.5] x [-0.5, height - 0.5]) and X_WC is rigid (rotation orthonormal with
  // determinant +1 to 1e-6, last row 0 0 0 1, finite translation). Otherwise InvalidArgument
  // naming the field as `<field_prefix><field> = <value>: <reason>`, e.g. "cameras[0].fx = -1: must
  // be positive and finite" for field_prefix "cameras[0].".
  Status Validate(std::string_view field_prefix = "") const;
};

// Tolerance for the orthonormality and determinant of a rigid transform's rotation part.
inline constexpr double kRigidTolerance = 1e-6;

// OK when the 4x4 matrix is a rigid transform (see PinholeCamera::Validate); otherwise
// InvalidArgument "<field> ...: <reason>".
Status ValidateRigidTransform(const Eigen::Matrix4d& X, std::string_view field);

// Pose X_WC of a camera with OpenCV axes at eye_W looking at target_W, with image "up" (-y_C) as
// close to up_W as possible [m]. Throws std::invalid_argument when eye_W == target_W or the view
// direction is parallel to up_W.
Eigen::Isometry3d LookAt(const Eigen::Vector3d& eye_W, const Eigen::Vector3d& target_W,
                         const Eigen::Vector3d& up_W = Eigen::Vector3d::UnitZ());

}  // namespace softid::capture
