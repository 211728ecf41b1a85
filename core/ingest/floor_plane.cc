#include "core/ingest/floor_plane.h"

#include <fmt/format.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/utility/Random.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/ingest/openmp_threads.h"

namespace softid::ingest {
namespace {

// Least-squares plane through `points` (the smallest principal axis), normal towards `towards`.
FloorPlane FitPlane(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& towards) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points) scatter += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
  FloorPlane plane;
  plane.normal_C = eigen.eigenvectors().col(0).normalized();
  if (plane.normal_C.dot(towards) < 0.0) plane.normal_C = -plane.normal_C;
  plane.offset_m = plane.normal_C.dot(mean);
  double squares = 0.0;
  for (const Eigen::Vector3d& p : points) squares += std::pow(plane.SignedDistance(p), 2);
  plane.rms_m = std::sqrt(squares / points.size());
  return plane;
}

double MedianOf(std::vector<float> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

// The least-squares plane of `points` again and again on those within 2.5 robust sigmas of it:
// what stands just above the floor (an object's underside, a box's foot, a wall's corner) lies
// within RANSAC's threshold but on one side only, and pulled the plane up and over.
FloorPlane TrimmedPlane(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& up) {
  FloorPlane plane = FitPlane(points, up);
  std::vector<Eigen::Vector3d> kept;
  std::vector<float> distances;
  for (int round = 0; round < 3; ++round) {
    distances.clear();
    for (const Eigen::Vector3d& p : points) distances.push_back(std::abs(plane.SignedDistance(p)));
    const double limit = 2.5 * 1.4826 * MedianOf(distances);
    kept.clear();
    for (const Eigen::Vector3d& p : points) {
      if (std::abs(plane.SignedDistance(p)) <= limit) kept.push_back(p);
    }
    if (kept.size() < 3) break;
    plane = FitPlane(kept, up);
  }
  return plane;
}

// RANSAC (Open3D) finds the plane on at most kRansacPoints of the points, taken evenly, and the
// inliers are then all points within the threshold of it: each RANSAC trial scores every point it
// is given, and a 640 x 480 scene has 10^5 of them (the plane from a share of them is as good).
constexpr size_t kRansacPoints = 20000;

std::vector<size_t> RansacPlaneInliers(const open3d::geometry::PointCloud& cloud, double threshold,
                                       const FloorPlaneOptions& options) {
  const size_t every = (cloud.points_.size() + kRansacPoints - 1) / kRansacPoints;
  if (every <= 1) return std::get<1>(cloud.SegmentPlane(threshold, 3, options.ransac_iterations));
  const auto [model, sample_inliers] =
      cloud.UniformDownSample(every)->SegmentPlane(threshold, 3, options.ransac_iterations);
  std::vector<size_t> inliers;
  if (sample_inliers.size() < 3) return inliers;
  for (size_t i = 0; i < cloud.points_.size(); ++i) {
    if (std::abs(model.head<3>().dot(cloud.points_[i]) + model[3]) < threshold) {
      inliers.push_back(i);
    }
  }
  return inliers;
}

}  // namespace

Status FloorPlaneOptions::Validate() const {
  if (!(noise_multiple > 0.0) || !(min_threshold_m > 0.0) || !std::isfinite(min_threshold_m)) {
    return Status::InvalidArgument(
        fmt::format("noise_multiple = {}, min_threshold_m = {}: must be positive", noise_multiple,
                    min_threshold_m));
  }
  if (max_planes < 1 || !(min_share > 0.0 && min_share < 1.0) ||
      !(max_tilt_deg > 0.0 && max_tilt_deg <= 90.0) || ransac_iterations < 1) {
    return Status::InvalidArgument(fmt::format(
        "max_planes = {}, min_share = {}, max_tilt_deg = {}, ransac_iterations = {}: need >= 1, "
        "(0, 1), (0, 90] and >= 1",
        max_planes, min_share, max_tilt_deg, ransac_iterations));
  }
  return Status::Ok();
}

Result<FloorPlane> FindFloorPlane(const std::vector<Eigen::Vector3d>& points_C,
                                  const std::vector<float>& sigmas_m,
                                  const Eigen::Vector3d& up_hint_C,
                                  const FloorPlaneOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (!sigmas_m.empty() && sigmas_m.size() != points_C.size()) {
    return Status::InvalidArgument("floor plane: one sigma per point, or none");
  }
  if (points_C.size() < 3 || !(up_hint_C.norm() > 0.0)) {
    return Status::NotFound(fmt::format("floor plane: {} static points", points_C.size()));
  }
  const Eigen::Vector3d up = up_hint_C.normalized();
  const double threshold =
      std::max(options.min_threshold_m, options.noise_multiple * MedianOf(sigmas_m));
  const double cos_tilt = std::cos(options.max_tilt_deg * std::numbers::pi / 180.0);
  const size_t min_inliers = static_cast<size_t>(options.min_share * points_C.size());
  const ScopedOpenMPThreads serial(1);
  open3d::utility::random::Seed(static_cast<int>(options.seed));
  open3d::geometry::PointCloud remaining(points_C);
  std::string seen;
  for (int k = 0; k < options.max_planes && remaining.points_.size() >= 3; ++k) {
    const std::vector<size_t> inliers = RansacPlaneInliers(remaining, threshold, options);
    if (inliers.size() < std::max<size_t>(3, min_inliers)) break;
    std::vector<Eigen::Vector3d> plane_points;
    plane_points.reserve(inliers.size());
    for (const size_t i : inliers) plane_points.push_back(remaining.points_[i]);
    FloorPlane plane = TrimmedPlane(plane_points, up);
    const double tilt_cos = plane.normal_C.dot(up);
    seen +=
        fmt::format("{}{} points at {:.0f} deg from up", seen.empty() ? "" : ", ", inliers.size(),
                    std::acos(std::clamp(tilt_cos, -1.0, 1.0)) * 180 / std::numbers::pi);
    if (tilt_cos >= cos_tilt) {
      plane.inliers = static_cast<int>(inliers.size());
      plane.inlier_share = static_cast<double>(inliers.size()) / points_C.size();
      plane.threshold_m = threshold;
      return plane;
    }
    remaining = *remaining.SelectByIndex(inliers, /*invert=*/true);
  }
  return Status::NotFound(fmt::format(
      "no floor: no plane within {} degrees of up holds {:.0f} % of the {} static points (planes "
      "seen: {})",
      options.max_tilt_deg, 100 * options.min_share, points_C.size(),
      seen.empty() ? "none" : seen));
}

}  // namespace softid::ingest
