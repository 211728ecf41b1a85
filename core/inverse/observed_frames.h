// What the cameras saw, as the cost consumes it: per frame the world points of every camera's
// depth pixels (unprojected through pixel centres with each camera's intrinsics and pose).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"

namespace softid::inverse {

struct ObservedFrame {
  int frame = 0;                        // index in the capture
  double time = 0.0;                    // frame / fps [s]
  bool heldout = false;                 // excluded from the fit, kept for validation
  std::vector<Eigen::Vector3d> points;  // world frame [m], all cameras
};

// Most observed points a fit loads (24 B each: 1.2 GB); a capture whose frames are not
// segmented (every pixel non-zero) reaches it after a few hundred frames.
inline constexpr int64_t kMaxObservedPoints = 50'000'000;

// Loads frames first..last (inclusive; last = -1 means the capture's last frame), none held out.
// InvalidArgument naming "frames.first" / "frames.last" and the value when out of range; errors
// of unreadable frames name the file; InvalidArgument when the frames hold more than
// kMaxObservedPoints points.
Result<std::vector<ObservedFrame>> LoadObservedFrames(const capture::Capture& capture, int first,
                                                      int last);

}  // namespace softid::inverse
