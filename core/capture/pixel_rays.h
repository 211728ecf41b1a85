// Rays of a real depth camera's pixels: OpenCV's lens distortion model inverted once per camera,
// so that depth pixels are unprojected along their true rays instead of being resampled onto an
// ideal pinhole grid (resampling would blend depths across object edges).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/capture/camera.h"
#include "core/common/status.h"

namespace softid::capture {

// Distortion coefficients in OpenCV's order (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx,
// ty]]]]): 0, 4, 5, 8, 12 or 14 numbers, finite. Empty: an ideal pinhole.
using DistortionCoefficients = std::vector<double>;

// OK for 0, 4, 5, 8, 12 or 14 finite coefficients; otherwise InvalidArgument naming `field`.
Status ValidateDistortion(const DistortionCoefficients& distortion, std::string_view field);

// Per pixel (row-major, width * height), the normalised coordinates (x, y) of the ray through the
// centre of that pixel in the distorted image: the ray's direction in the camera frame is (x, y,
// 1), and a pixel of depth z (along the camera z axis) shows the point z * (x, y, 1).
struct PixelRays {
  int width = 0;
  int height = 0;
  std::vector<Eigen::Vector2d> xy;

  const Eigen::Vector2d& at(int col, int row) const {
    return xy[static_cast<size_t>(row) * width + col];
  }
};

// The rays of `camera`'s pixels through a lens with `distortion` (OpenCV's model, inverted
// iteratively to 1e-12 in normalised coordinates). Without distortion, the pinhole's rays.
// InvalidArgument for invalid distortion coefficients.
Result<PixelRays> ComputePixelRays(const PinholeCamera& camera,
                                   const DistortionCoefficients& distortion);

// Where the camera-frame point p_C (z > 0) appears in the distorted image [pixels] (OpenCV's
// projectPoints): the forward model that ComputePixelRays inverts.
Eigen::Vector2d ProjectDistorted(const PinholeCamera& camera,
                                 const DistortionCoefficients& distortion,
                                 const Eigen::Vector3d& p_C);

// The same for many points at once (one call of OpenCV's projectPoints).
std::vector<Eigen::Vector2d> ProjectDistorted(const PinholeCamera& camera,
                                              const DistortionCoefficients& distortion,
                                              const std::vector<Eigen::Vector3d>& points_C);

}  // namespace softid::capture
