// One clock for all cameras: every camera's frames sorted by device time, frames of different
// cameras taken at the same moment merged into one capture frame, times counted from the first
// frame of the first camera (the release). Capture frames then show one or more cameras; a camera
// without a frame at that moment contributes no points.
#pragma once

#include <vector>

#include "core/recording/recording.h"

namespace softid::ingest {

struct TimelineFrame {
  double time_s = 0.0;        // after the release [s], >= 0, strictly increasing
  std::vector<int> frame_of;  // per camera: its recording frame shown here, or -1
};

struct Timeline {
  double origin_s = 0.0;  // device-clock time of t = 0: camera 0's first frame
  std::vector<TimelineFrame> frames;
  double median_interval_s = 0.0;  // between consecutive capture frames (0 with one frame)
  double max_gap_s = 0.0;          // longest interval: dropped frames show here
};

// Frames earlier than camera 0's first are left out (the object was not released yet). Frames of
// different cameras within same_time_s of each other are merged (a camera keeps at most one
// frame per capture frame).
Timeline MergeTimeline(const recording::Recording& recording, double same_time_s);

}  // namespace softid::ingest
