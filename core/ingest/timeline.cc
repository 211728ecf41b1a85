#include "core/ingest/timeline.h"

#include <algorithm>
#include <tuple>

namespace softid::ingest {

Timeline MergeTimeline(const recording::Recording& recording, double same_time_s) {
  Timeline out;
  const int cameras = recording.NumCameras();
  if (cameras == 0 || recording.cameras[0].frames.empty()) return out;
  out.origin_s = recording.cameras[0].frames[0].time_s;
  std::vector<std::tuple<double, int, int>> all;  // time, camera, frame
  for (int c = 0; c < cameras; ++c) {
    const std::vector<recording::RecordingFrame>& frames = recording.cameras[c].frames;
    for (int k = 0; k < static_cast<int>(frames.size()); ++k) {
      const double t = frames[k].time_s - out.origin_s;
      if (t >= 0.0) all.emplace_back(t, c, k);
    }
  }
  std::sort(all.begin(), all.end());
  for (const auto& [t, camera, frame] : all) {
    const bool joins = !out.frames.empty() && t - out.frames.back().time_s <= same_time_s &&
                       out.frames.back().frame_of[camera] < 0;
    if (!joins) out.frames.push_back({t, std::vector<int>(cameras, -1)});
    out.frames.back().frame_of[camera] = frame;
  }
  std::vector<double> intervals;
  for (size_t k = 1; k < out.frames.size(); ++k) {
    intervals.push_back(out.frames[k].time_s - out.frames[k - 1].time_s);
  }
  if (!intervals.empty()) {
    out.max_gap_s = *std::max_element(intervals.begin(), intervals.end());
    std::nth_element(intervals.begin(), intervals.begin() + intervals.size() / 2, intervals.end());
    out.median_interval_s = intervals[intervals.size() / 2];
  }
  return out;
}

}  // namespace softid::ingest
