// The depth noise of a capture, measured before any fit. Frame 0 shows the object at its rest
// shape, which the capture's mesh gives exactly: the distances of frame 0's observed points to the
// rest surface are sensor noise (and calibration error), with no physics in them. The robust
// sigma 1.4826 median|d| ignores stray background pixels; it is floored at the depth
// quantisation (depth_scale / sqrt(12)), the noise of a noise-free synthetic capture.
#pragma once

#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"
#include "core/inverse/observed_frames.h"

namespace softid::inverse {

struct RestFrameNoise {
  double sigma_m = 0.0;               // the estimate [m], >= quantisation_sigma_m
  double median_distance_m = 0.0;     // median |d| of frame 0's points [m]
  double quantisation_sigma_m = 0.0;  // the floor [m]
  int points = 0;                     // frame 0's points used
};

// FailedPrecondition when the capture has no observed point in frame 0; errors of unreadable
// frames as LoadObservedFrames.
Result<RestFrameNoise> EstimateRestFrameNoise(const capture::Capture& capture,
                                              const geometry::TriangleMesh& rest_mesh);

// The residual-sigma floor of a capture [m]: the finest depth quantum / sqrt(12).
double DepthQuantisationSigma(const capture::Capture& capture);

}  // namespace softid::inverse
