#include "core/ingest/foreground.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace softid::ingest {

Status ForegroundOptions::Validate() const {
  if (!(noise_sigmas > 0.0) || !std::isfinite(noise_sigmas)) {
    return Status::InvalidArgument(
        fmt::format("noise_sigmas = {}: must be positive", noise_sigmas));
  }
  if (!(min_margin_m >= 0.0) || !std::isfinite(min_margin_m)) {
    return Status::InvalidArgument(fmt::format("min_margin_m = {}: must be >= 0", min_margin_m));
  }
  if (min_region_pixels < 1) {
    return Status::InvalidArgument(
        fmt::format("min_region_pixels = {}: must be >= 1", min_region_pixels));
  }
  return Status::Ok();
}

Result<Foreground> SegmentForeground(const capture::DepthImage& frame, const StaticScene& scene,
                                     const capture::PixelRays& rays,
                                     const ForegroundOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (frame.width != scene.width || frame.height != scene.height || frame.width != rays.width ||
      frame.height != rays.height) {
    return Status::InvalidArgument(
        fmt::format("foreground: frame {}x{}, static scene {}x{}, rays {}x{}: sizes differ",
                    frame.width, frame.height, scene.width, scene.height, rays.width, rays.height));
  }
  cv::Mat1b candidates(frame.height, frame.width, uint8_t{0});
  for (int row = 0; row < frame.height; ++row) {
    for (int col = 0; col < frame.width; ++col) {
      const float z = frame.at(col, row);
      if (z <= 0.0f) continue;
      const float behind = scene.depth(col, row);
      const double margin =
          std::max(options.min_margin_m, options.noise_sigmas * scene.sigma(col, row));
      if (behind <= 0.0f || behind - z > margin) candidates(row, col) = 1;
    }
  }
  cv::Mat1i labels;
  cv::Mat stats, centroids;
  const int count = cv::connectedComponentsWithStats(candidates, labels, stats, centroids, 8);
  Foreground out;
  out.width = frame.width;
  out.height = frame.height;
  out.mask.assign(static_cast<size_t>(frame.width) * frame.height, 0);
  std::vector<int> region_of_label(count, -1);
  for (int label = 1; label < count; ++label) {
    if (stats.at<int>(label, cv::CC_STAT_AREA) < options.min_region_pixels) continue;
    region_of_label[label] = static_cast<int>(out.regions.size());
    out.regions.emplace_back();
  }
  for (int row = 0; row < frame.height; ++row) {
    for (int col = 0; col < frame.width; ++col) {
      const int region = region_of_label[labels(row, col)];
      if (labels(row, col) == 0 || region < 0) continue;
      const int pixel = row * frame.width + col;
      const Eigen::Vector2d& xy = rays.at(col, row);
      out.regions[region].pixels.push_back(pixel);
      out.regions[region].centroid_C += frame.at(col, row) * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
      out.mask[pixel] = 1;
    }
  }
  for (ForegroundRegion& region : out.regions) region.centroid_C /= region.pixels.size();
  std::sort(out.regions.begin(), out.regions.end(),
            [](const ForegroundRegion& a, const ForegroundRegion& b) {
              return a.pixels.size() > b.pixels.size();
            });
  return out;
}

}  // namespace softid::ingest
