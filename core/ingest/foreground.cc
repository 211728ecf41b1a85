#include "core/ingest/foreground.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>

namespace softid::ingest {

Status ForegroundOptions::Validate() const {
  if (!(noise_sigmas > 0.0) || !std::isfinite(noise_sigmas)) {
    return Status::InvalidArgument(
        fmt::format("noise_sigmas = {}: must be positive", noise_sigmas));
  }
  if (!(min_margin_m >= 0.0) || !std::isfinite(min_margin_m)) {
    return Status::InvalidArgument(fmt::format("min_margin_m = {}: must be >= 0", min_margin_m));
  }
  if (!(max_depth_step > 0.0) || !std::isfinite(max_depth_step)) {
    return Status::InvalidArgument(
        fmt::format("max_depth_step = {}: must be positive", max_depth_step));
  }
  if (min_region_pixels < 1) {
    return Status::InvalidArgument(
        fmt::format("min_region_pixels = {}: must be >= 1", min_region_pixels));
  }
  return Status::Ok();
}

namespace {

// Candidate pixels: nearer than the scene, or of a scene that may be the object itself (they join
// a region of nearer pixels but make none alone).
constexpr uint8_t kNearer = 1, kJoinsOnly = 2;

}  // namespace

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
      if (behind <= 0.0f || behind - z > margin) {
        candidates(row, col) = kNearer;
      } else if (!scene.maybe_object.empty() && scene.maybe_object[row * frame.width + col]) {
        candidates(row, col) = kJoinsOnly;
      }
    }
  }
  // Regions: 8-connected candidates whose depths join without a jump (a pixel of the object and a
  // noisy floor pixel beside its silhouette are neighbours in the image, not in space). OpenCV's
  // connected components know no depth, hence this flood fill.
  Foreground out;
  out.width = frame.width;
  out.height = frame.height;
  out.mask.assign(static_cast<size_t>(frame.width) * frame.height, 0);
  std::vector<int> label(out.mask.size(), -1), stack, members;
  for (int seed = 0; seed < static_cast<int>(label.size()); ++seed) {
    if (!candidates(seed / frame.width, seed % frame.width) || label[seed] >= 0) continue;
    members.clear();
    int nearer = 0;
    stack.assign(1, seed);
    label[seed] = seed;
    while (!stack.empty()) {
      const int p = stack.back();
      stack.pop_back();
      members.push_back(p);
      const int row = p / frame.width, col = p % frame.width;
      nearer += candidates(row, col) == kNearer ? 1 : 0;
      const float z = frame.depth[p];
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int r = row + dr, c = col + dc;
          if (r < 0 || c < 0 || r >= frame.height || c >= frame.width) continue;
          const int q = r * frame.width + c;
          if (label[q] >= 0 || !candidates(r, c)) continue;
          if (std::abs(frame.depth[q] - z) > options.max_depth_step * z) continue;
          label[q] = seed;
          stack.push_back(q);
        }
      }
    }
    if (nearer < options.min_region_pixels) continue;
    ForegroundRegion region;
    region.pixels = members;
    std::sort(region.pixels.begin(), region.pixels.end());
    for (const int p : region.pixels) {
      const Eigen::Vector2d& xy = rays.xy[p];
      region.centroid_C += frame.depth[p] * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
      out.mask[p] = 1;
    }
    out.regions.push_back(std::move(region));
  }
  for (ForegroundRegion& region : out.regions) region.centroid_C /= region.pixels.size();
  std::sort(out.regions.begin(), out.regions.end(),
            [](const ForegroundRegion& a, const ForegroundRegion& b) {
              return a.pixels.size() > b.pixels.size();
            });
  return out;
}

}  // namespace softid::ingest
