#include "core/inverse/job_resources.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/inverse/time_step_selection.h"

namespace softid::inverse {
namespace {

// Memory per grid node and stored step: u, v and a of 3 doubles each (the adjoint pass keeps
// every step's state).
constexpr double kBytesPerNodeStep = 3 * 3 * sizeof(double);
// Memory per grid node of one simulator: 27 neighbour blocks of 3 x 3 doubles in the step
// matrix, its factor (about 4x the matrix with fill-in) and the factor kept for the adjoint,
// plus per-node vectors and the distance-field grid; rounded up.
constexpr double kBytesPerNode = 27 * 9 * sizeof(double) * 10;

std::string GiB(double bytes) {
  return fmt::format("{:.3g} GiB", bytes / (1ull << 30));
}

// The config key that most plausibly made the job large, for the message.
std::string Culprit(const JobConfig& config) {
  if (config.cell_size > 0.0) return fmt::format("cell_size = {}", config.cell_size);
  if (config.substeps != kAutoSubsteps && config.substeps > 64) {
    return fmt::format("substeps = {}", config.substeps);
  }
  return fmt::format("cells = {}", config.cells);
}

}  // namespace

Status JobResourceLimits::Validate() const {
  if (!(max_memory_bytes > 0.0)) {
    return Status::InvalidArgument(
        fmt::format("max_memory_bytes = {}: must be positive", max_memory_bytes));
  }
  if (cores < 1) return Status::InvalidArgument(fmt::format("cores = {}: must be >= 1", cores));
  return Status::Ok();
}

Result<JobResourceEstimate> EstimateJobResources(const JobConfig& config,
                                                 const CaptureExtent& extent,
                                                 const JobResourceLimits& limits) {
  SOFTID_RETURN_IF_ERROR(limits.Validate());
  if (extent.num_frames < 1 || extent.mesh_bounds.isEmpty()) {
    return Status::InvalidArgument("capture: no frames or an empty mesh");
  }
  const int last_frame = extent.num_frames - 1;
  if (config.frames.first > last_frame) {
    return Status::InvalidArgument(
        fmt::format("frames.first = {}: the capture has {} frames (0-{})", config.frames.first,
                    extent.num_frames, last_frame));
  }
  if (config.frames.last > last_frame) {
    return Status::InvalidArgument(fmt::format("frames.last = {}: the capture has {} frames (0-{})",
                                               config.frames.last, extent.num_frames, last_frame));
  }
  const int fitted_last = config.frames.last < 0 ? last_frame : config.frames.last;

  JobResourceEstimate estimate;
  const Eigen::Vector3d size = extent.mesh_bounds.sizes();
  estimate.cell_size_m =
      config.cell_size > 0.0 ? config.cell_size : size.maxCoeff() / std::max(1, config.cells);
  // In doubles: a tiny cell size must not overflow the count.
  double nodes = 1.0;
  for (int a = 0; a < 3; ++a) nodes *= std::ceil(size[a] / estimate.cell_size_m) + 1.0;
  const int substeps =
      config.substeps == kAutoSubsteps ? SubstepSelectionOptions{}.max_substeps : config.substeps;
  const double steps = static_cast<double>(fitted_last) * substeps;
  const int cores = config.threads > 0 ? config.threads : limits.cores;
  estimate.concurrent_starts = std::max(1, std::min(config.starts, cores));
  const double per_start = nodes * (kBytesPerNode + kBytesPerNodeStep * (steps + 1.0));
  // Observed points are bounded where they are loaded (kMaxObservedPoints): a frame's count
  // depends on its content, which a header does not tell.
  estimate.memory_bytes = estimate.concurrent_starts * per_start;
  estimate.grid_nodes = static_cast<int64_t>(std::min(nodes, 9e18));
  estimate.steps_per_run = static_cast<int64_t>(std::min(steps, 9e18));

  if (!(estimate.memory_bytes <= limits.max_memory_bytes)) {
    return Status::InvalidArgument(fmt::format(
        "{}: the job would need about {} of memory (grid of {:.3g} nodes at h = {:.3g} m, {:.3g} "
        "steps per run, {} start(s) at once); at most {} is accepted: use fewer cells, substeps, "
        "frames or threads",
        Culprit(config), GiB(estimate.memory_bytes), nodes, estimate.cell_size_m, steps,
        estimate.concurrent_starts, GiB(limits.max_memory_bytes)));
  }
  return estimate;
}

}  // namespace softid::inverse
