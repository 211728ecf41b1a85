#include "core/inverse/observed_frames.h"

#include "core/common/json_fields.h"

namespace softid::inverse {

Result<std::vector<ObservedFrame>> LoadObservedFrames(const capture::Capture& capture, int first,
                                                      int last) {
  const int num_frames = capture.NumFrames();
  if (last < 0) last = num_frames - 1;
  if (first < 0 || first >= num_frames) {
    return json::Invalid("frames.first", first,
                         "must lie in [0, " + std::to_string(num_frames - 1) +
                             "] (the capture has " + std::to_string(num_frames) + " frames)");
  }
  if (last < first || last >= num_frames) {
    return json::Invalid("frames.last", last,
                         "must lie in [frames.first, " + std::to_string(num_frames - 1) + "]");
  }
  std::vector<ObservedFrame> frames;
  frames.reserve(last - first + 1);
  int64_t total_points = 0;
  for (int k = first; k <= last; ++k) {
    ObservedFrame frame;
    frame.frame = k;
    frame.time = capture.FrameTime(k);
    for (int c = 0; c < capture.NumCameras(); ++c) {
      SOFTID_ASSIGN_OR_RETURN(capture::DepthImage image, capture::LoadFrame(capture, c, k));
      const std::vector<Eigen::Vector3d> points =
          capture::DepthToWorldPoints(image, capture.cameras[c].camera);
      total_points += static_cast<int64_t>(points.size());
      if (total_points > kMaxObservedPoints) {
        return Status::InvalidArgument(
            "frames: more than " + std::to_string(kMaxObservedPoints) +
            " observed points up to frame " + std::to_string(k) +
            " (only the object's pixels should be non-zero): fit fewer frames");
      }
      frame.points.insert(frame.points.end(), points.begin(), points.end());
    }
    frames.push_back(std::move(frame));
  }
  return frames;
}

}  // namespace softid::inverse
