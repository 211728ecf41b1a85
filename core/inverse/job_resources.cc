#include "core/inverse/job_resources.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/inverse/grid_refinement.h"
#include "core/inverse/grid_selection.h"
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

// CPU time of one forward plus adjoint step per grid node, at kReferenceNodes, on one core of an
// x86-64-v3 machine; the time grows as nodes^1.25 (sparse factorisation fill-in). Measured with
// `softid-lab bench` (29 ms per forward+adjoint step on 2 cores at 3,100 active cells, about
// 7,300 grid nodes; the exponent from its table of grid sizes), 2026-11-26.
constexpr double kCpuSecondsPerNodeStep = 8e-6;
constexpr double kReferenceNodes = 7300.0;
constexpr double kNodeExponent = 0.25;
// Cost evaluations per optimiser iteration: the line search, and the horizon continuation's
// stages, each of which re-evaluates the cost.
constexpr double kEvaluationsPerIteration = 3.0;
// A diagnosis refits the model with each candidate physics and on held-out frames.
constexpr double kDiagnosisFitFactor = 8.0;

std::string GiB(double bytes) {
  return fmt::format("{:.3g} GiB", bytes / (1ull << 30));
}

std::string Hours(double seconds) {
  return fmt::format("{:.3g} h", seconds / 3600.0);
}

// The config key that most plausibly made the job large, for the message.
std::string MemoryCulprit(const JobConfig& config) {
  if (config.solver.cell_size_m > 0.0)
    return fmt::format("cell_size = {}", config.solver.cell_size_m);
  if (config.solver.substeps != kAutoSubsteps && config.solver.substeps > 64) {
    return fmt::format("substeps = {}", config.solver.substeps);
  }
  if (config.solver.cells == kAutoCells) return std::string("cells = \"auto\"");
  return fmt::format("cells = {}", config.solver.cells);
}

// The key that most plausibly made the job long: many iterations or starts, else the grid.
std::string TimeCulprit(const JobConfig& config) {
  if (config.solver.max_iterations > 200)
    return fmt::format("max_iterations = {}", config.solver.max_iterations);
  if (config.solver.starts > 16) return fmt::format("starts = {}", config.solver.starts);
  return MemoryCulprit(config);
}

// Nodes of a grid of cell size h over a box. In doubles: a tiny cell size must not overflow.
double BoxNodes(const Eigen::Vector3d& size, double h) {
  double nodes = 1.0;
  for (int a = 0; a < 3; ++a) nodes *= std::ceil(size[a] / h) + 1.0;
  return nodes;
}

// "auto" cells: the finest candidate the grid selection may simulate within its node budget, and
// its nodes.
std::pair<int, double> FinestAffordableCandidate(const CaptureExtent& extent) {
  const GridSelectionOptions selection;
  const Eigen::Vector3d size = extent.mesh_bounds.sizes();
  auto nodes = [&](size_t i) {
    return i < extent.candidate_grid_nodes.size() ? extent.candidate_grid_nodes[i]
                                                  : GridNodeEstimate(size, selection.candidates[i]);
  };
  size_t chosen = 0;
  for (size_t i = 1; i < selection.candidates.size() && nodes(i) <= selection.max_grid_nodes; ++i)
    chosen = i;
  return {selection.candidates[chosen], nodes(chosen)};
}

// The capture's extent must be non-empty and hold the frames the config selects.
Status CheckCaptureExtent(const JobConfig& config, const CaptureExtent& extent) {
  if (extent.num_frames < 1 || extent.mesh_bounds.isEmpty()) {
    return Status::InvalidArgument("capture: no frames or an empty mesh");
  }
  if (!extent.frame_periods.empty() &&
      extent.frame_periods.size() != static_cast<size_t>(extent.num_frames)) {
    return Status::InvalidArgument("capture: frame_times and frames differ in number");
  }
  for (size_t i = 0; i < extent.candidate_grid_nodes.size(); ++i) {
    if (extent.candidate_grid_nodes[i] < 1) {
      return Status::InvalidArgument(
          fmt::format("capture: candidate_grid_nodes[{}] = {}: must be >= 1", i,
                      extent.candidate_grid_nodes[i]));
    }
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
  return Status::Ok();
}

// The size of one simulation of the job.
struct RunSize {
  double nodes = 0.0;          // of its grid
  double steps = 0.0;          // to the last fitted frame
  double typical_steps = 0.0;  // the same at what "auto" substeps choose for most captures
};

// "auto" substeps take up to 64 per frame only where an impact needs them (a block dropped on a
// floor); smooth motions stop at 4-8, bouncing ones at 16. Memory is bounded by the largest
// candidate, the wall time estimated at this many.
constexpr int kTypicalAutoSubsteps = 16;

// One simulation's grid (the finest "auto" may choose) and steps (the most "auto" may choose);
// sets the estimate's cell size, grid nodes and steps per run.
RunSize EstimateRunSize(const JobConfig& config, const CaptureExtent& extent,
                        JobResourceEstimate* estimate) {
  const int last_frame = extent.num_frames - 1;
  const int fitted_last = config.frames.last < 0 ? last_frame : config.frames.last;
  RunSize run;
  const Eigen::Vector3d size = extent.mesh_bounds.sizes();
  const bool auto_cells = config.solver.cell_size_m <= 0.0 && config.solver.cells == kAutoCells;
  const auto [auto_choice, auto_nodes] = FinestAffordableCandidate(extent);
  const int cells = auto_cells ? auto_choice : config.solver.cells;
  estimate->cell_size_m = config.solver.cell_size_m > 0.0 ? config.solver.cell_size_m
                                                          : size.maxCoeff() / std::max(1, cells);
  run.nodes = auto_cells ? auto_nodes : BoxNodes(size, estimate->cell_size_m);
  const int substeps = config.solver.substeps == kAutoSubsteps
                           ? LargestSubstepCandidate(run.nodes, SubstepSelectionOptions{})
                           : config.solver.substeps;
  const double fitted_periods = extent.frame_periods.empty()
                                    ? static_cast<double>(fitted_last)
                                    : std::ceil(extent.frame_periods.at(fitted_last));
  run.steps = fitted_periods * substeps;
  run.typical_steps = config.solver.substeps == kAutoSubsteps
                          ? fitted_periods * std::min(substeps, kTypicalAutoSubsteps)
                          : run.steps;
  estimate->grid_nodes = static_cast<int64_t>(std::min(run.nodes, 9e18));
  estimate->steps_per_run = static_cast<int64_t>(std::min(run.steps, 9e18));
  return run;
}

// Wall time of the fit (and the diagnosis' refits) on `cores` cores.
double EstimateWallSeconds(const JobConfig& config, const RunSize& run, int cores,
                           int concurrent_starts) {
  const double nodes = run.nodes;
  const double step_cpu_seconds =
      kCpuSecondsPerNodeStep * nodes * std::pow(nodes / kReferenceNodes, kNodeExponent);
  const double evaluations_per_start =
      kEvaluationsPerIteration * (config.solver.max_iterations + 1.0);
  const double start_rounds =
      std::ceil(static_cast<double>(config.solver.starts) / concurrent_starts);
  // Each concurrent start gets cores / concurrent_starts cores (at least one).
  const double cores_per_start = std::max(1.0, static_cast<double>(cores) / concurrent_starts);
  return start_rounds * evaluations_per_start * run.typical_steps * step_cpu_seconds /
         cores_per_start * (config.diagnose ? kDiagnosisFitFactor : 1.0);
}

// "refine_grid": one more start after the fit, on cells 1.5 x smaller (3.4 x the nodes, no more
// than the refinement's budget: GridRefinementOptions::max_grid_nodes), with the cores to itself.
void AddGridRefinement(const JobConfig& config, const RunSize& run, int cores,
                       JobResourceEstimate* estimate) {
  constexpr double kFinerNodesFactor = 1.5 * 1.5 * 1.5;
  RunSize refit = run;
  refit.nodes = std::min(run.nodes * kFinerNodesFactor,
                         static_cast<double>(GridRefinementOptions().max_grid_nodes));
  estimate->memory_bytes =
      std::max(estimate->memory_bytes,
               refit.nodes * (kBytesPerNode + kBytesPerNodeStep * (refit.steps + 1.0)));
  JobConfig one_start = config;
  one_start.solver.starts = 1;
  one_start.diagnose = false;
  estimate->wall_seconds += EstimateWallSeconds(one_start, refit, cores, 1);
}

// InvalidArgument naming the likely culprit when the estimate exceeds a limit.
Status CheckWithinLimits(const JobConfig& config, const JobResourceLimits& limits,
                         const RunSize& run, const JobResourceEstimate& estimate) {
  const double nodes = run.nodes, steps = run.steps;
  if (!(estimate.memory_bytes <= limits.max_memory_bytes)) {
    return Status::InvalidArgument(fmt::format(
        "{}: the job would need about {} of memory (grid of {:.3g} nodes at h = {:.3g} m, {:.3g} "
        "steps per run, {} start(s) at once); at most {} is accepted: use fewer cells, substeps, "
        "frames or threads",
        MemoryCulprit(config), GiB(estimate.memory_bytes), nodes, estimate.cell_size_m, steps,
        estimate.concurrent_starts, GiB(limits.max_memory_bytes)));
  }
  if (!(estimate.wall_seconds <= limits.max_wall_seconds)) {
    return Status::InvalidArgument(fmt::format(
        "{}: the job could run for about {} (grid of {:.3g} nodes, {:.3g} steps per run, {} "
        "start(s) of up to {} iterations{}); at most {} is accepted: use fewer iterations, "
        "starts, cells, substeps or frames",
        TimeCulprit(config), Hours(estimate.wall_seconds), nodes, run.typical_steps,
        config.solver.starts, config.solver.max_iterations,
        config.diagnose ? ", with a diagnosis" : "", Hours(limits.max_wall_seconds)));
  }
  return Status::Ok();
}

}  // namespace

Status JobResourceLimits::Validate() const {
  if (!(max_memory_bytes > 0.0)) {
    return Status::InvalidArgument(
        fmt::format("max_memory_bytes = {}: must be positive", max_memory_bytes));
  }
  if (!(max_wall_seconds > 0.0)) {
    return Status::InvalidArgument(
        fmt::format("max_wall_seconds = {}: must be positive", max_wall_seconds));
  }
  if (cores < 1) return Status::InvalidArgument(fmt::format("cores = {}: must be >= 1", cores));
  return Status::Ok();
}

Result<JobResourceEstimate> EstimateJobResources(const JobConfig& config,
                                                 const CaptureExtent& extent,
                                                 const JobResourceLimits& limits) {
  SOFTID_RETURN_IF_ERROR(limits.Validate());
  SOFTID_RETURN_IF_ERROR(CheckCaptureExtent(config, extent));
  JobResourceEstimate estimate;
  const RunSize run = EstimateRunSize(config, extent, &estimate);
  const int cores = config.solver.threads > 0 ? config.solver.threads : limits.cores;
  estimate.concurrent_starts = std::max(1, std::min(config.solver.starts, cores));
  const double per_start = run.nodes * (kBytesPerNode + kBytesPerNodeStep * (run.steps + 1.0));
  // Observed points are bounded where they are loaded (kMaxObservedPoints): a frame's count
  // depends on its content, which a header does not tell.
  estimate.memory_bytes = estimate.concurrent_starts * per_start;
  estimate.wall_seconds = EstimateWallSeconds(config, run, cores, estimate.concurrent_starts);
  if (config.refine_grid) AddGridRefinement(config, run, cores, &estimate);
  SOFTID_RETURN_IF_ERROR(CheckWithinLimits(config, limits, run, estimate));
  return estimate;
}

}  // namespace softid::inverse
