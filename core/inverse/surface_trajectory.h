// The simulated surface over a capture's frames, and how far two such trajectories lie apart: the
// measure behind the choice of the time step (time_step_selection.h) and of the grid
// (grid_selection.h), which both compare a run with a finer one.
#pragma once

#include <Eigen/Geometry>
#include <atomic>
#include <optional>
#include <vector>

#include "core/fem/physical_parameters.h"
#include "core/fem/simulation_options.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::inverse {

// Surface vertex positions [m] of every frame 0..last_frame.
using SurfaceTrajectory = std::vector<std::vector<Eigen::Vector3d>>;

struct SurfaceRun {
  SurfaceTrajectory frames;  // empty when the run diverged or was cancelled
  int grid_nodes = 0;        // of the simulation's hexahedral mesh
  int steps = 0;             // time steps run
  double seconds = 0.0;      // wall time of the run, setup included [s]

  // Wall time per time step [s] (0 before a step): what a fit's evaluation on this grid scales.
  double SecondsPerStep() const { return steps > 0 ? seconds / steps : 0.0; }
};

// Simulates frames 0..last_frame at `substeps` steps per frame (simulation.time_step is replaced
// by 1 / (fps substeps)). Throws std::invalid_argument for parameters or options fem::Simulator
// rejects.
SurfaceRun SimulateSurfaceTrajectory(const geometry::TriangleMesh& rest_mesh,
                                     const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                     const fem::PhysicalParameters& parameters,
                                     fem::SimulationOptions simulation, double fps, int last_frame,
                                     int substeps, const std::atomic<bool>* cancel);

struct TrajectoryDifference {
  double difference_m = 0.0;        // max over frames of the RMS distance over surface vertices [m]
  int worst_frame = 0;              // where that maximum is
  std::vector<double> per_frame_m;  // the RMS distance of each frame [m]

  // The number of leading frames whose distance is at most tolerance_m [m].
  int LeadingFramesWithin(double tolerance_m) const {
    int count = 0;
    while (count < static_cast<int>(per_frame_m.size()) && per_frame_m[count] <= tolerance_m)
      ++count;
    return count;
  }
};

// Compares the first `vertices` vertices of each frame (-1: all; both trajectories must then have
// the same vertices). Runs on different grids share only the rest mesh's own vertices, which come
// first: the simulator appends the points of its grid-dependent subdivision after them.
TrajectoryDifference CompareTrajectories(const SurfaceTrajectory& a, const SurfaceTrajectory& b,
                                         int vertices = -1);

}  // namespace softid::inverse
