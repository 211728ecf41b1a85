// What a job will need before it runs: the simulation grid and steps its config implies on a
// given capture, and estimates of its memory and time. A service checks this at the door, so a
// config like {"cells": 300} or {"substeps": 20000} is refused with the field and the limit named
// instead of exhausting the machine hours later.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "core/common/status.h"
#include "core/inverse/job_config.h"

namespace softid::inverse {

// The parts of a capture that size a job.
struct CaptureExtent {
  Eigen::AlignedBox3d mesh_bounds;  // rest mesh [m], non-empty
  int num_frames = 0;               // per camera, >= 1
  int num_cameras = 0;              // >= 1
  // Time of frame k in nominal frame periods (t_k * fps) when the capture has frame_times;
  // empty: evenly spaced (k). Sizes the simulation's steps: dropped frames still cost steps.
  std::vector<double> frame_periods;
  // The nodes of GridSelectionOptions' candidate grids over the mesh (CandidateGridNodes), what
  // "auto" cells may simulate; empty: unknown, each grid counted as its bounding box's nodes.
  std::vector<int> candidate_grid_nodes;
};

struct JobResourceEstimate {
  double cell_size_m = 0.0;  // h [m]
  // Nodes of the grid: the simulated count for "auto" cells with candidate_grid_nodes, else the
  // bounding box's (>= simulated nodes).
  int64_t grid_nodes = 0;
  int64_t steps_per_run = 0;  // simulation steps of one forward run over the fitted frames
  int concurrent_starts = 0;  // starts that run at once
  double memory_bytes = 0.0;  // peak estimate over the concurrent starts [B]
  // Wall time if every start ran all max_iterations (fits usually converge sooner), "auto"
  // substeps counted at 16 per frame (an impact may take up to 4x as many) [s]. With
  // "refine_grid", memory and time include the refit on the finer grid (grid_refinement.h).
  double wall_seconds = 0.0;
};

struct JobResourceLimits {
  // Largest accepted memory estimate of one job [B]; default 4 GiB.
  double max_memory_bytes = 4.0 * (1ull << 30);
  // Largest accepted wall-time estimate of one job [s]; default 24 h.
  double max_wall_seconds = 24.0 * 3600.0;
  // Cores a job gets when its config leaves "threads" at 0; bounds its concurrent starts.
  int cores = 1;

  Status Validate() const;
};

// The estimate for `config` on a capture of `extent`, or InvalidArgument naming the field when the
// config does not fit the capture (frames past its end) or the job exceeds `limits`:
//   frames.last = 100: the capture has 60 frames (0-59)
//   cells = 300: the job would need about 41 GiB of memory (grid 301 x 301 x 108 nodes, 960
//   steps per run); at most 4 GiB is accepted: use fewer cells, substeps or frames
//   max_iterations = 5000: the job could run for about 31 h (...); at most 24 h is accepted
// "auto" substeps count as their largest candidate on that grid (LargestSubstepCandidate), "auto"
// cells as the finest grid candidate within GridSelectionOptions::max_grid_nodes (counted as
// extent.candidate_grid_nodes says, else as the bounding box's nodes).
Result<JobResourceEstimate> EstimateJobResources(const JobConfig& config,
                                                 const CaptureExtent& extent,
                                                 const JobResourceLimits& limits);

}  // namespace softid::inverse
