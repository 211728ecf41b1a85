#include "core/inverse/time_step_selection.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/inverse/surface_trajectory.h"

namespace softid::inverse {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point begin) {
  return std::chrono::duration<double>(Clock::now() - begin).count();
}

bool Cancelled(const std::atomic<bool>* cancel) {
  return cancel != nullptr && cancel->load(std::memory_order_relaxed);
}

Status CheckSubstepSelectionInputs(const SubstepSelectionOptions& options, double fps,
                                   int last_frame) {
  if (options.min_substeps < 1) {
    return Status::InvalidArgument("min_substeps = " + std::to_string(options.min_substeps) +
                                   ": must be at least 1");
  }
  if (!(options.max_node_steps_per_frame > 0.0)) {
    return Status::InvalidArgument(fmt::format("max_node_steps_per_frame = {}: must be positive",
                                               options.max_node_steps_per_frame));
  }
  if (options.max_substeps < options.min_substeps) {
    return Status::InvalidArgument("max_substeps = " + std::to_string(options.max_substeps) +
                                   ": must be at least min_substeps");
  }
  if (!(options.tolerance_fraction > 0.0)) {
    return Status::InvalidArgument(
        fmt::format("tolerance_fraction = {}: must be positive", options.tolerance_fraction));
  }
  if (!(options.max_seconds >= 0.0) || !std::isfinite(options.max_seconds)) {
    return Status::InvalidArgument(
        fmt::format("max_seconds = {}: must be >= 0", options.max_seconds));
  }
  if (!(fps > 0.0)) return Status::InvalidArgument(fmt::format("fps = {}: must be > 0", fps));
  if (last_frame < 1) {
    return Status::InvalidArgument("last_frame = " + std::to_string(last_frame) +
                                   ": need at least one frame after the first");
  }
  return Status::Ok();
}

// Leading frames whose difference is within tolerance_m or at most 3/4 of `previous`'s there (a
// step error at least halves with the step; a chaotic motion's difference does not shrink).
int LeadingFramesConverging(const std::vector<double>& current, const std::vector<double>& previous,
                            double tolerance_m) {
  const size_t frames = std::min(current.size(), previous.size());
  size_t count = 0;
  while (count < frames &&
         (current[count] <= tolerance_m || current[count] <= 0.75 * previous[count])) {
    ++count;
  }
  return static_cast<int>(count);
}

// The comparison of the surface trajectories at `substeps` (coarse) and twice as many (fine);
// `previous_per_frame_m` holds the previous trial's per-frame differences (empty for the first)
// and receives this one's.
SubstepTrial CompareSubsteps(int substeps, const SurfaceTrajectory& coarse,
                             const SurfaceTrajectory& fine, double tolerance_m,
                             std::vector<double>* previous_per_frame_m) {
  SubstepTrial trial;
  trial.substeps = substeps;
  trial.diverged = coarse.empty() || fine.empty();
  if (trial.diverged) {
    previous_per_frame_m->clear();
    return trial;
  }
  TrajectoryDifference difference = CompareTrajectories(coarse, fine);
  trial.difference_m = difference.difference_m;
  trial.worst_frame = difference.worst_frame;
  trial.frames_within_tolerance = difference.LeadingFramesWithin(tolerance_m);
  trial.frames_converging =
      previous_per_frame_m->empty()
          ? trial.frames_within_tolerance
          : LeadingFramesConverging(difference.per_frame_m, *previous_per_frame_m, tolerance_m);
  trial.per_frame_m = difference.per_frame_m;
  *previous_per_frame_m = std::move(difference.per_frame_m);
  return trial;
}

// Whether the last halving of the step shrank the difference by at least a quarter (true with one
// trial). A step error halves at first order (contact) and falls to a quarter at second, give or
// take: a scanned bunny's landing went 0.99 -> 0.59 mm, slow but converging. A chaotic motion's
// difference stays or grows (16.8 -> 18.2 mm for a rocking block).
bool LastHalvingConverged(const std::vector<SubstepTrial>& trials) {
  if (trials.size() < 2) return true;
  const SubstepTrial& previous = trials[trials.size() - 2];
  const SubstepTrial& last = trials.back();
  if (previous.diverged || last.diverged) return true;  // says nothing about the motion
  return last.difference_m <= 0.75 * previous.difference_m;
}

// Doubles the substeps from options.min_substeps until a run and one at twice the substeps agree
// within selection->tolerance_m, or max_substeps is reached; records every trial. Throws
// std::invalid_argument as SimulateSurfaceTrajectory.
Status DoubleSubstepsUntilConverged(const geometry::TriangleMesh& rest_mesh,
                                    const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                    const fem::PhysicalParameters& parameters,
                                    const fem::SimulationOptions& simulation, double fps,
                                    int last_frame, const SubstepSelectionOptions& options,
                                    SubstepSelection* selection) {
  int substeps = options.min_substeps;
  const auto begin = Clock::now();
  SurfaceRun first = SimulateSurfaceTrajectory(rest_mesh, fixed_region, parameters, simulation, fps,
                                               last_frame, substeps, options.cancel);
  if (Cancelled(options.cancel)) return Status::Cancelled("the time-step choice was cancelled");
  SurfaceTrajectory coarse = std::move(first.frames);
  selection->seconds_per_step = first.SecondsPerStep();
  selection->max_substeps = LargestSubstepCandidate(first.grid_nodes, options);
  if (selection->max_substeps < options.max_substeps) {
    spdlog::info(
        "time step: at most {} substeps per frame on this grid ({} nodes; {:.0f} node-steps per "
        "frame bound the fit's memory)",
        selection->max_substeps, first.grid_nodes, options.max_node_steps_per_frame);
  }
  std::vector<double> previous_per_frame_m;
  double last_run_s = first.seconds;
  while (true) {
    if (substeps >= selection->max_substeps) {
      selection->substeps = selection->max_substeps;
      break;
    }
    // A run's time grows with its steps: the next one, at twice the steps, takes twice as long.
    if (options.max_seconds > 0.0 && SecondsSince(begin) + 2.0 * last_run_s > options.max_seconds) {
      selection->substeps = substeps;
      selection->stopped_at_time_limit = true;
      break;
    }
    const int finer = 2 * substeps;  // <= max_substeps: the candidates are doublings
    SurfaceRun fine_run = SimulateSurfaceTrajectory(rest_mesh, fixed_region, parameters, simulation,
                                                    fps, last_frame, finer, options.cancel);
    SurfaceTrajectory fine = std::move(fine_run.frames);
    last_run_s = fine_run.seconds;
    if (Cancelled(options.cancel)) {
      return Status::Cancelled("the time-step choice was cancelled");
    }
    const SubstepTrial trial =
        CompareSubsteps(substeps, coarse, fine, selection->tolerance_m, &previous_per_frame_m);
    selection->trials.push_back(trial);
    spdlog::info(
        "time step: {} vs {} substeps per frame: surface differs by {:.3g} mm at frame {}, within "
        "tolerance on the first {} frames, converging on the first {}{}",
        substeps, finer, 1e3 * trial.difference_m, trial.worst_frame, trial.frames_within_tolerance,
        trial.frames_converging, trial.diverged ? " (a run diverged)" : "");
    if (!trial.diverged && trial.difference_m <= selection->tolerance_m) {
      selection->substeps = substeps;
      selection->within_tolerance = true;
      break;
    }
    substeps = finer;
    coarse = std::move(fine);
    selection->seconds_per_step = fine_run.SecondsPerStep();
  }
  return Status::Ok();
}

}  // namespace

int PredictableLastFrame(const SubstepSelection& selection, int last_frame,
                         int min_converging_contact_frames) {
  // Not selection.converging: that compares the largest difference over every frame, which in
  // chaotic frames rises and falls at random (13.3 then 10.0 mm at 16/32 and 32/64 substeps on a
  // block rocking on a 10-cell grid, 9.1 then 16.7 mm on 16 cells); each frame's own
  // convergence says where the motion stops being predictable.
  // A choice the time limit ended has no evidence of chaos: its last halving is not the finest.
  if (selection.within_tolerance || selection.stopped_at_time_limit || selection.trials.size() < 2)
    return -1;
  const SubstepTrial& last = selection.trials.back();
  if (last.diverged || last.frames_converging > last_frame) return -1;
  if (last.frames_converging < last.frames_within_tolerance + min_converging_contact_frames) {
    return -1;
  }
  return last.frames_converging - 1;
}

int LargestSubstepCandidate(double grid_nodes, const SubstepSelectionOptions& options) {
  const double affordable = options.max_node_steps_per_frame / std::max(1.0, grid_nodes);
  const double cap = std::min<double>(options.max_substeps, std::floor(affordable));
  int largest = options.min_substeps;
  while (2.0 * largest <= cap) largest *= 2;
  return largest;
}

Result<SubstepSelection> SelectSubsteps(const geometry::TriangleMesh& rest_mesh,
                                        const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                        const fem::PhysicalParameters& parameters,
                                        const fem::SimulationOptions& simulation, double fps,
                                        int last_frame, const SubstepSelectionOptions& options) {
  SOFTID_RETURN_IF_ERROR(CheckSubstepSelectionInputs(options, fps, last_frame));
  SubstepSelection selection;
  selection.tolerance_m = options.tolerance_fraction * rest_mesh.Bounds().sizes().maxCoeff();
  try {
    SOFTID_RETURN_IF_ERROR(DoubleSubstepsUntilConverged(
        rest_mesh, fixed_region, parameters, simulation, fps, last_frame, options, &selection));
  } catch (const std::invalid_argument& error) {
    return Status::InvalidArgument(error.what());
  }
  selection.converging = LastHalvingConverged(selection.trials);
  if (selection.stopped_at_time_limit) {
    spdlog::warn(
        "time step: {} substeps per frame, the finest the time limit ({:.3g} s) let the choice "
        "compare; it was not shown to be within tolerance of half the step",
        selection.substeps, options.max_seconds);
  } else if (!selection.within_tolerance && !selection.converging) {
    const SubstepTrial& previous = selection.trials[selection.trials.size() - 2];
    const SubstepTrial& last = selection.trials.back();
    spdlog::warn(
        "time step: halving the step did not shrink the surface's difference ({:.3g} mm at {} vs "
        "{} substeps per frame, {:.3g} mm at {} vs {}; tolerance {:.3g} mm): from frame {} on no "
        "affordable step predicts the "
        "motion (an undamped body rocking on its corners converges with the step too slowly, and "
        "later turns chaotic; damping settles it); {} substeps taken",
        1e3 * previous.difference_m, previous.substeps, 2 * previous.substeps,
        1e3 * last.difference_m, last.substeps, 2 * last.substeps, 1e3 * selection.tolerance_m,
        last.frames_converging, selection.substeps);
  } else if (!selection.within_tolerance) {
    spdlog::warn(
        "time step: even {} substeps per frame leave the surface {:.3g} mm from a run at half the "
        "step (tolerance {:.3g} mm); the fit may be biased by the time discretisation",
        selection.substeps,
        selection.trials.empty() ? 0.0 : 1e3 * selection.trials.back().difference_m,
        1e3 * selection.tolerance_m);
  }
  return selection;
}

nlohmann::json ToJson(const SubstepSelection& selection) {
  nlohmann::json trials = nlohmann::json::array();
  for (const SubstepTrial& t : selection.trials) {
    trials.push_back({{"substeps", t.substeps},
                      {"difference_m", t.difference_m},
                      {"worst_frame", t.worst_frame},
                      {"frames_within_tolerance", t.frames_within_tolerance},
                      {"frames_converging", t.frames_converging},
                      {"per_frame_m", t.per_frame_m},
                      {"diverged", t.diverged}});
  }
  return {{"substeps", selection.substeps},
          {"max_substeps", selection.max_substeps},
          {"tolerance_m", selection.tolerance_m},
          {"within_tolerance", selection.within_tolerance},
          {"converging", selection.converging},
          {"stopped_at_time_limit", selection.stopped_at_time_limit},
          {"trials", trials}};
}

}  // namespace softid::inverse
