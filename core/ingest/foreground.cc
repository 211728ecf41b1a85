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
  if (!(join_noise_sigmas > 0.0) || !(join_noise_sigmas <= noise_sigmas)) {
    return Status::InvalidArgument(
        fmt::format("join_noise_sigmas = {}: must be in (0, noise_sigmas = {}]", join_noise_sigmas,
                    noise_sigmas));
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
  if (min_enclosing_neighbours < 1 || min_enclosing_neighbours > 8) {
    return Status::InvalidArgument(
        fmt::format("min_enclosing_neighbours = {}: must be in [1, 8]", min_enclosing_neighbours));
  }
  return Status::Ok();
}

namespace {

// Candidate pixels: nearer than the scene, or a little nearer, or of a scene that may be the object
// itself (the last two join a region of nearer pixels but make none alone).
constexpr uint8_t kNearer = 1, kJoinsOnly = 2;

cv::Mat1b ClassifyPixels(const capture::DepthImage& frame, const StaticScene& scene,
                         const ForegroundOptions& options) {
  cv::Mat1b candidates(frame.height, frame.width, uint8_t{0});
  const double join_fraction = options.join_noise_sigmas / options.noise_sigmas;
  for (int row = 0; row < frame.height; ++row) {
    for (int col = 0; col < frame.width; ++col) {
      const float z = frame.at(col, row);
      if (z <= 0.0f) continue;
      const float behind = scene.depth(col, row);
      const double margin =
          std::max(options.min_margin_m, options.noise_sigmas * scene.sigma(col, row));
      if (behind <= 0.0f || behind - z > margin) {
        candidates(row, col) = kNearer;
      } else if (behind - z > join_fraction * margin ||
                 (!scene.maybe_object.empty() && scene.maybe_object[row * frame.width + col])) {
        candidates(row, col) = kJoinsOnly;
      }
    }
  }
  return candidates;
}

// Regions, by hysteresis: 8-connected nearer pixels whose depths join without a jump (a pixel of
// the object and a noisy floor pixel beside its silhouette are neighbours in the image, not in
// space) make a region when there are enough of them; it then grows into the pixels that only join.
// A pixel that only joins never bridges two groups of nearer pixels into one region: far, noisy
// background would otherwise become one. OpenCV's connected components know no depth, hence this
// flood fill. `label` gets each region's index (-1 elsewhere).
std::vector<std::vector<int>> GrowRegions(const capture::DepthImage& frame,
                                          const cv::Mat1b& candidates,
                                          const ForegroundOptions& options,
                                          std::vector<int>* label) {
  constexpr int kUnseen = -1, kDropped = -2;
  label->assign(frame.depth.size(), kUnseen);
  std::vector<std::vector<int>> regions;
  std::vector<int> stack, members;
  // Grows from the pixels on `stack` (labelled `id` already) over the pixels `take` admits,
  // labelling them `id`; they go to `members`.
  const auto grow = [&](int id, auto take) {
    while (!stack.empty()) {
      const int p = stack.back();
      stack.pop_back();
      const int row = p / frame.width, col = p % frame.width;
      const float z = frame.depth[p];
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int r = row + dr, c = col + dc;
          if (r < 0 || c < 0 || r >= frame.height || c >= frame.width) continue;
          const int q = r * frame.width + c;
          if (!take(q, candidates(r, c))) continue;
          if (std::abs(frame.depth[q] - z) > options.max_depth_step * z) continue;
          (*label)[q] = id;
          members.push_back(q);
          stack.push_back(q);
        }
      }
    }
  };
  const uint8_t* kinds = candidates.ptr<uint8_t>(0);  // continuous: made whole by ClassifyPixels
  for (int seed = 0; seed < static_cast<int>(label->size()); ++seed) {
    if (kinds[seed] != kNearer || (*label)[seed] != kUnseen) continue;
    const int id = static_cast<int>(regions.size());
    members.assign(1, seed);
    stack.assign(1, seed);
    (*label)[seed] = id;
    grow(id, [&](int q, uint8_t kind) { return kind == kNearer && (*label)[q] == kUnseen; });
    if (static_cast<int>(members.size()) < options.min_region_pixels) {
      for (const int p : members) (*label)[p] = kDropped;
      continue;
    }
    regions.push_back(members);
  }
  // Each region grows from all its pixels at once (the pixels reached are those a growth from
  // each pixel in turn reaches: reachability does not depend on the order).
  for (int id = 0; id < static_cast<int>(regions.size()); ++id) {
    members.clear();
    stack = regions[id];
    grow(id, [&](int q, uint8_t kind) { return kind == kJoinsOnly && (*label)[q] == kUnseen; });
    regions[id].insert(regions[id].end(), members.begin(), members.end());
  }
  for (int& l : *label) l = std::max(l, -1);
  return regions;
}

// The rows and columns the regions' pixels span (empty: lo > hi). Only pixels beside a region
// can join one, and the object covers a small part of a frame: the whole 640 x 480 image, scanned
// for them, cost more than the rest of the segmentation.
struct PixelBox {
  int row_lo = 0, row_hi = -1, col_lo = 0, col_hi = -1;
};

PixelBox RegionsBox(const std::vector<std::vector<int>>& regions, int width, int height) {
  PixelBox box{height, -1, width, -1};
  for (const std::vector<int>& members : regions) {
    for (const int p : members) {
      const int row = p / width, col = p % width;
      box.row_lo = std::min(box.row_lo, row);
      box.row_hi = std::max(box.row_hi, row);
      box.col_lo = std::min(box.col_lo, col);
      box.col_hi = std::max(box.col_hi, col);
    }
  }
  return box;
}

// A pixel with data that is not foreground but whose neighbours mostly are, of one region, and
// whose depth continues theirs, is that region's surface under a noisy reading: it joins. Decided
// on the regions as grown, so that the filling never spreads; a hole through the object (a torus's)
// is wider than one pixel and stays open. Only the labels change: the caller lists each region's
// pixels from them.
void FillEnclosedPixels(const capture::DepthImage& frame, const ForegroundOptions& options,
                        const PixelBox& box, std::vector<int>* label) {
  std::vector<std::pair<int, int>> joins;  // pixel, region
  for (int row = std::max(1, box.row_lo - 1); row <= std::min(frame.height - 2, box.row_hi + 1);
       ++row) {
    for (int col = std::max(1, box.col_lo - 1); col <= std::min(frame.width - 2, box.col_hi + 1);
         ++col) {
      const int p = row * frame.width + col;
      const float z = frame.depth[p];
      if ((*label)[p] >= 0 || z <= 0.0f) continue;
      int region = -1, count = 0;
      bool one_region = true;
      double depth_sum = 0.0;
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int q = p + dr * frame.width + dc;
          if (q == p || (*label)[q] < 0) continue;
          one_region = one_region && (region < 0 || (*label)[q] == region);
          region = (*label)[q];
          ++count;
          depth_sum += frame.depth[q];
        }
      }
      if (!one_region || count < options.min_enclosing_neighbours) continue;
      if (std::abs(z - depth_sum / count) > options.max_depth_step * z) continue;
      joins.emplace_back(p, region);
    }
  }
  for (const auto& [p, region] : joins) (*label)[p] = region;
}

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
  const cv::Mat1b candidates = ClassifyPixels(frame, scene, options);
  std::vector<int> label;
  std::vector<std::vector<int>> pixels = GrowRegions(frame, candidates, options, &label);
  const PixelBox box = RegionsBox(pixels, frame.width, frame.height);
  FillEnclosedPixels(frame, options, box, &label);
  // Each region's pixels in row-major order, from its labels: those filled in lie at most one
  // pixel outside the box.
  for (std::vector<int>& members : pixels) members.clear();
  for (int row = std::max(0, box.row_lo - 1); row <= std::min(frame.height - 1, box.row_hi + 1);
       ++row) {
    for (int col = std::max(0, box.col_lo - 1); col <= std::min(frame.width - 1, box.col_hi + 1);
         ++col) {
      const int p = row * frame.width + col;
      if (label[p] >= 0) pixels[label[p]].push_back(p);
    }
  }
  Foreground out;
  out.width = frame.width;
  out.height = frame.height;
  out.mask.assign(frame.depth.size(), 0);
  for (std::vector<int>& members : pixels) {
    ForegroundRegion region;
    region.pixels = std::move(members);
    for (const int p : region.pixels) {
      const Eigen::Vector2d& xy = rays.xy[p];
      region.centroid_C += frame.depth[p] * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
      out.mask[p] = 1;
    }
    region.centroid_C /= static_cast<double>(region.pixels.size());
    out.regions.push_back(std::move(region));
  }
  std::sort(out.regions.begin(), out.regions.end(),
            [](const ForegroundRegion& a, const ForegroundRegion& b) {
              return a.pixels.size() > b.pixels.size();
            });
  return out;
}

}  // namespace softid::ingest
