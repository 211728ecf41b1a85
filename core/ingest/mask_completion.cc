#include "core/ingest/mask_completion.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace softid::ingest {

Status MaskCompletionOptions::Validate() const {
  if (!(agreement_sigmas > 0.0) || !std::isfinite(agreement_sigmas)) {
    return Status::InvalidArgument(
        fmt::format("agreement_sigmas = {}: must be positive", agreement_sigmas));
  }
  if (!(min_overlap > 0.0 && min_overlap <= 1.0)) {
    return Status::InvalidArgument(fmt::format("min_overlap = {}: must be in (0, 1]", min_overlap));
  }
  if (surface_points < 100) {
    return Status::InvalidArgument(
        fmt::format("surface_points = {}: must be >= 100", surface_points));
  }
  if (!(capture_fraction > 0.0) || !std::isfinite(capture_fraction)) {
    return Status::InvalidArgument(
        fmt::format("capture_fraction = {}: must be positive", capture_fraction));
  }
  return Status::Ok();
}

MaskCompleter::MaskCompleter(const geometry::TriangleMesh& mesh_S, const Eigen::Isometry3d& X_WS,
                             const CameraView& view, const capture::PinholeCamera& camera,
                             const capture::DistortionCoefficients& distortion,
                             double noise_sigma_m, const MaskCompletionOptions& options)
    : mesh_S_(mesh_S),
      surface_(mesh_S, options.surface_points),
      view_(view),
      camera_(camera),
      distortion_(distortion),
      noise_sigma_m_(noise_sigma_m),
      capture_m_(options.capture_fraction * mesh_S.Bounds().diagonal().norm()),
      options_(options),
      renderer_(mesh_S),
      last_CS_(view.X_WC.inverse() * X_WS) {
  camera_.X_WC = Eigen::Isometry3d::Identity();  // vertices are projected from the camera frame
}

// Constant velocity: the last step's motion once more (the release pose alone at first).
Eigen::Isometry3d MaskCompleter::PredictedPose_CS() const {
  if (!before_last_CS_) return last_CS_;
  return last_CS_ * (before_last_CS_->inverse() * last_CS_);
}

// The pixels the posed mesh can cover: its vertices' image, one pixel wider on every side.
ImageWindow MaskCompleter::SilhouetteWindow(const std::vector<Eigen::Vector3d>& vertices_C) const {
  for (const Eigen::Vector3d& p_C : vertices_C) {
    if (p_C.z() <= 0.0) return {0, 0, camera_.width - 1, camera_.height - 1};
  }
  double col_lo = camera_.width, row_lo = camera_.height, col_hi = -1.0, row_hi = -1.0;
  for (const Eigen::Vector2d& pixel : capture::ProjectDistorted(camera_, distortion_, vertices_C)) {
    col_lo = std::min(col_lo, pixel.x());
    col_hi = std::max(col_hi, pixel.x());
    row_lo = std::min(row_lo, pixel.y());
    row_hi = std::max(row_hi, pixel.y());
  }
  const auto clamp = [](double v, int hi) {
    return static_cast<int>(std::clamp(v, -1.0, static_cast<double>(hi)));
  };
  return {clamp(std::floor(col_lo) - 1.0, camera_.width),
          clamp(std::floor(row_lo) - 1.0, camera_.height),
          clamp(std::ceil(col_hi) + 1.0, camera_.width),
          clamp(std::ceil(row_hi) + 1.0, camera_.height)};
}

// The pixels with data outside the mask, inside `window`, and as near the mask as the window
// reaches beyond the mask's box on any side (at least 2 pixels): where a silhouette can extend
// the mask. The mask's interior needs no ray.
std::vector<int> MaskCompleter::Candidates(const capture::DepthImage& image,
                                           const std::vector<int>& mask,
                                           const ImageWindow& window) const {
  const int col_lo = std::max(0, window.col_lo), col_hi = std::min(image.width - 1, window.col_hi);
  const int row_lo = std::max(0, window.row_lo), row_hi = std::min(image.height - 1, window.row_hi);
  std::vector<int> out;
  if (col_lo > col_hi || row_lo > row_hi) return out;
  cv::Mat1b outside(row_hi - row_lo + 1, col_hi - col_lo + 1, uint8_t{255});
  int mask_col_lo = image.width, mask_col_hi = -1, mask_row_lo = image.height, mask_row_hi = -1;
  for (const int p : mask) {
    const int row = p / image.width, col = p % image.width;
    mask_col_lo = std::min(mask_col_lo, col);
    mask_col_hi = std::max(mask_col_hi, col);
    mask_row_lo = std::min(mask_row_lo, row);
    mask_row_hi = std::max(mask_row_hi, row);
    if (row >= row_lo && row <= row_hi && col >= col_lo && col <= col_hi)
      outside(row - row_lo, col - col_lo) = 0;
  }
  const int reach = std::max(
      {2, mask_col_lo - col_lo, col_hi - mask_col_hi, mask_row_lo - row_lo, row_hi - mask_row_hi});
  cv::Mat1f distance;
  cv::distanceTransform(outside, distance, cv::DIST_L2, cv::DIST_MASK_3);
  for (int row = row_lo; row <= row_hi; ++row) {
    for (int col = col_lo; col <= col_hi; ++col) {
      const float d = distance(row - row_lo, col - col_lo);
      const int p = row * image.width + col;
      if (d > 0.0f && d <= reach + 0.5f && image.depth[p] > 0.0f) out.push_back(p);
    }
  }
  return out;
}

namespace {

// Of the pixels in `agreeing`, those joined to the mask through others of them (8-neighbours). A
// strip cut off from the object is the rest shape overreaching a squashed body: a torus landing
// shows a row of floor pixels below its near rim, apart from it.
std::vector<int> JoinedToMask(const std::vector<int>& agreeing, const std::vector<int>& mask,
                              int width, int height) {
  constexpr uint8_t kMask = 1, kAgreeing = 2;
  std::vector<uint8_t> state(static_cast<size_t>(width) * height, 0);
  for (const int p : mask) state[p] = kMask;
  for (const int p : agreeing) state[p] = kAgreeing;
  std::vector<int> joined, stack;
  const auto visit_neighbours = [&](int p, auto visit) {
    const int row = p / width, col = p % width;
    for (int r = std::max(0, row - 1); r <= std::min(height - 1, row + 1); ++r) {
      for (int c = std::max(0, col - 1); c <= std::min(width - 1, col + 1); ++c)
        visit(r * width + c);
    }
  };
  for (const int p : agreeing) {
    bool touches = false;
    visit_neighbours(p, [&](int q) { touches = touches || state[q] == kMask; });
    if (touches && state[p] == kAgreeing) {
      state[p] = kMask;
      stack.push_back(p);
    }
  }
  while (!stack.empty()) {
    const int p = stack.back();
    stack.pop_back();
    joined.push_back(p);
    visit_neighbours(p, [&](int q) {
      if (state[q] != kAgreeing) return;
      state[q] = kMask;
      stack.push_back(q);
    });
  }
  return joined;
}

}  // namespace

void MaskCompleter::Pose(const capture::DepthImage& image, const std::vector<int>& pixels,
                         FrameCompletion* out) {
  std::vector<Eigen::Vector3d> points_C;
  points_C.reserve(pixels.size());
  for (const int p : pixels) {
    const Eigen::Vector2d& xy = view_.rays.xy[p];
    points_C.push_back(image.depth[p] * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
  }
  const Result<MeshRegistration> pose =
      TrackMeshPose(surface_, points_C, PredictedPose_CS(), capture_m_, noise_sigma_m_);
  if (!pose.ok()) return;
  out->overlap = pose->overlap;
  if (pose->overlap < options_.min_overlap) return;
  out->posed = true;
  before_last_CS_ = last_CS_;
  last_CS_ = pose->X_CS;
}

std::vector<int> MaskCompleter::AgreeingPixels(const capture::DepthImage& image,
                                               const std::vector<int>& mask) const {
  std::vector<Eigen::Vector3d> vertices_C = mesh_S_.vertices;
  for (Eigen::Vector3d& v : vertices_C) v = last_CS_ * v;
  const std::vector<int> candidates = Candidates(image, mask, SilhouetteWindow(vertices_C));
  const std::vector<float> surface = renderer_.RenderPixels(last_CS_, view_.rays, candidates);
  std::vector<int> agreeing;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const int p = candidates[i];
    if (surface[i] <= 0.0f) continue;
    // The rest shape posed on a body squashed against the floor reaches into it: where its
    // surface lies behind the static scene, the scene is what the pixel shows.
    const float behind = view_.scene.depth_m[p];
    if (behind > 0.0f && surface[i] >= behind) continue;
    const double sigma = std::max<double>(view_.scene.sigma_m[p], noise_sigma_m_);
    if (std::abs(image.depth[p] - surface[i]) > options_.agreement_sigmas * sigma) continue;
    agreeing.push_back(p);
  }
  return agreeing;
}

FrameCompletion MaskCompleter::Complete(const capture::DepthImage& image,
                                        std::vector<int>* pixels) {
  FrameCompletion out;
  Pose(image, *pixels, &out);
  if (!out.posed) return out;
  const std::vector<int> joined =
      JoinedToMask(AgreeingPixels(image, *pixels), *pixels, image.width, image.height);
  pixels->insert(pixels->end(), joined.begin(), joined.end());
  out.pixels_added = static_cast<int>(joined.size());
  std::sort(pixels->begin(), pixels->end());
  return out;
}

}  // namespace softid::ingest
