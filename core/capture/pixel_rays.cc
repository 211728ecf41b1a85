#include "core/capture/pixel_rays.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>

namespace softid::capture {
namespace {

cv::Mat CameraMatrix(const PinholeCamera& camera) {
  return (cv::Mat_<double>(3, 3) << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
}

}  // namespace

Status ValidateDistortion(const DistortionCoefficients& distortion, std::string_view field) {
  const size_t n = distortion.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    return Status::InvalidArgument(
        fmt::format("{} has {} coefficients: OpenCV's model takes 4, 5, 8, 12 or 14", field, n));
  }
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(distortion[i])) {
      return Status::InvalidArgument(
          fmt::format("{}[{}] = {}: must be finite", field, i, distortion[i]));
    }
  }
  return Status::Ok();
}

namespace {

// Coefficients that fold the image (the distortion polynomial turns back inside it, as wrong or
// misordered numbers do) have no inverse there: the iteration stops on a ray that the lens does
// not map to its pixel. Every ray is projected back; a pixel missed by more than a tenth of a
// pixel refuses the coefficients.
Status CheckRaysMapBack(const PinholeCamera& camera, const DistortionCoefficients& distortion,
                        const std::vector<cv::Point2d>& pixels,
                        const std::vector<cv::Point2d>& normalised) {
  std::vector<cv::Point3d> rays;
  rays.reserve(normalised.size());
  for (const cv::Point2d& xy : normalised) rays.emplace_back(xy.x, xy.y, 1.0);
  std::vector<cv::Point2d> back;
  cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), CameraMatrix(camera),
                    cv::Mat(distortion), back);
  size_t worst = 0;
  double worst_px = 0.0;
  for (size_t i = 0; i < back.size(); ++i) {
    const double miss = cv::norm(back[i] - pixels[i]);
    if (!(miss <= worst_px)) {  // NaN counts as worst
      worst = i;
      worst_px = std::isfinite(miss) ? miss : std::numeric_limits<double>::infinity();
    }
  }
  if (worst_px <= 0.1) return Status::Ok();
  return Status::InvalidArgument(fmt::format(
      "distortion = [{}]: the lens model folds the image: the ray found for pixel ({}, {}) maps "
      "back {:.3g} px away (are the coefficients in OpenCV's order k1, k2, p1, p2, k3, and for "
      "this camera's fx, fy, cx, cy?)",
      fmt::join(distortion, ", "), pixels[worst].x, pixels[worst].y, worst_px));
}

}  // namespace

Result<PixelRays> ComputePixelRays(const PinholeCamera& camera,
                                   const DistortionCoefficients& distortion) {
  SOFTID_RETURN_IF_ERROR(camera.Validate());
  SOFTID_RETURN_IF_ERROR(ValidateDistortion(distortion, "distortion"));
  PixelRays rays;
  rays.width = camera.width;
  rays.height = camera.height;
  rays.xy.resize(static_cast<size_t>(camera.width) * camera.height);
  if (distortion.empty()) {
    for (int row = 0; row < camera.height; ++row) {
      for (int col = 0; col < camera.width; ++col) {
        rays.xy[static_cast<size_t>(row) * camera.width + col] =
            camera.RayDirection_C(col, row).head<2>();
      }
    }
    return rays;
  }
  std::vector<cv::Point2d> pixels;
  pixels.reserve(rays.xy.size());
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) pixels.emplace_back(col, row);
  }
  std::vector<cv::Point2d> normalised;
  // The default 5 iterations leave errors of 0.1 pixel near the corners of a wide lens.
  const cv::TermCriteria until(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12);
  cv::undistortPoints(pixels, normalised, CameraMatrix(camera), cv::Mat(distortion), cv::noArray(),
                      cv::noArray(), until);
  for (size_t i = 0; i < normalised.size(); ++i) {
    rays.xy[i] = Eigen::Vector2d(normalised[i].x, normalised[i].y);
  }
  SOFTID_RETURN_IF_ERROR(CheckRaysMapBack(camera, distortion, pixels, normalised));
  return rays;
}

Eigen::Vector2d ProjectDistorted(const PinholeCamera& camera,
                                 const DistortionCoefficients& distortion,
                                 const Eigen::Vector3d& p_C) {
  const std::vector<cv::Point3d> points{{p_C.x(), p_C.y(), p_C.z()}};
  std::vector<cv::Point2d> pixels;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), CameraMatrix(camera),
                    distortion.empty() ? cv::Mat() : cv::Mat(distortion), pixels);
  return {pixels[0].x, pixels[0].y};
}

std::vector<Eigen::Vector2d> ProjectDistorted(const PinholeCamera& camera,
                                              const DistortionCoefficients& distortion,
                                              const std::vector<Eigen::Vector3d>& points_C) {
  std::vector<cv::Point3d> points;
  points.reserve(points_C.size());
  for (const Eigen::Vector3d& p : points_C) points.emplace_back(p.x(), p.y(), p.z());
  std::vector<Eigen::Vector2d> out;
  if (points.empty()) return out;
  std::vector<cv::Point2d> pixels;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), CameraMatrix(camera),
                    distortion.empty() ? cv::Mat() : cv::Mat(distortion), pixels);
  out.reserve(pixels.size());
  for (const cv::Point2d& pixel : pixels) out.emplace_back(pixel.x, pixel.y);
  return out;
}

}  // namespace softid::capture
