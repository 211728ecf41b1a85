#include "core/inverse/rest_frame_noise.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/geometry/mesh_distance.h"

namespace softid::inverse {

double DepthQuantisationSigma(const capture::Capture& capture) {
  double quantum = std::numeric_limits<double>::infinity();
  for (const capture::CameraRecording& camera : capture.cameras) {
    quantum = std::min(quantum, camera.depth_scale);
  }
  return std::isfinite(quantum) ? quantum / std::sqrt(12.0) : 0.0;
}

Result<RestFrameNoise> EstimateRestFrameNoise(const capture::Capture& capture,
                                              const geometry::TriangleMesh& rest_mesh) {
  SOFTID_ASSIGN_OR_RETURN(std::vector<ObservedFrame> frames, LoadObservedFrames(capture, 0, 0));
  if (frames.empty() || frames[0].points.empty()) {
    return Status::FailedPrecondition("frame 0 has no observed point: cannot measure depth noise");
  }
  SOFTID_ASSIGN_OR_RETURN(geometry::MeshDistance distance,
                          geometry::MeshDistance::Create(rest_mesh));
  std::vector<double> d;
  d.reserve(frames[0].points.size());
  for (const Eigen::Vector3d& p : frames[0].points) d.push_back(distance.Distance(p));
  const auto middle = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), middle, d.end());
  RestFrameNoise out;
  out.points = static_cast<int>(d.size());
  out.median_distance_m = *middle;
  out.quantisation_sigma_m = DepthQuantisationSigma(capture);
  // 1.4826 median|d| is sigma for Gaussian d: consistent, and robust to a minority of outliers.
  out.sigma_m = std::max(1.4826 * out.median_distance_m, out.quantisation_sigma_m);
  return out;
}

}  // namespace softid::inverse
