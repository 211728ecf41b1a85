// The diagnosis' PNG plots, drawn with OpenCV primitives (no plotting library):
//   - the residual per frame (misfit / noise floor) before and after, over the motion phases;
//   - the residual painted on the object as each camera saw it at one frame, before and after;
//   - the cost per iteration of each fit.
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/diagnosis/motion_phases.h"
#include "core/diagnosis/residual_map.h"

namespace softid::diagnosis {

// One named curve of a line plot.
struct Series {
  std::string label;
  std::vector<double> x, y;
};

// @param frames capture frame indices (x axis); before/after misfit / sigma per frame (after may
//   be empty); motion colours the background by phase; threshold is drawn as a dashed line;
//   before_label names the first curve in the legend.
// `as_compared`: when given, the base misfit with the compared time step's own error still in it
// (time_step_error.h), drawn in grey; `before` is then the misfit without it.
Status WriteFrameMisfitPlot(const std::filesystem::path& path, const std::vector<int>& frames,
                            const std::vector<double>& before, const std::vector<double>& after,
                            const std::vector<FrameMotion>& motion, double threshold,
                            const std::string& before_label = "before",
                            const std::vector<double>& as_compared = {});

// Cost per iteration of each series on a log scale [m^2].
Status WriteCostHistoryPlot(const std::filesystem::path& path, const std::vector<Series>& series);

// Panels (rows: `rows`, e.g. before/after; columns: cameras) of frame `k` (index into
// observations.frames): each observed pixel coloured by |phi| / sigma (blue 0 ... red >= 3),
// unmatched points magenta.
// @pre every map in `rows` was built from `observations`.
Status WriteResidualPainting(const std::filesystem::path& path, const capture::Capture& capture,
                             const Observations& observations, int k,
                             const std::vector<std::pair<std::string, const ResidualMap*>>& rows,
                             double sigma);

}  // namespace softid::diagnosis
