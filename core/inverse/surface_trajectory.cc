#include "core/inverse/surface_trajectory.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/fem/simulator.h"

namespace softid::inverse {

SurfaceRun SimulateSurfaceTrajectory(const geometry::TriangleMesh& rest_mesh,
                                     const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                     const fem::PhysicalParameters& parameters,
                                     fem::SimulationOptions simulation, double fps, int last_frame,
                                     int substeps, const std::atomic<bool>* cancel) {
  auto cancelled = [cancel] {
    return cancel != nullptr && cancel->load(std::memory_order_relaxed);
  };
  const auto begin = std::chrono::steady_clock::now();
  auto stop_clock = [begin](SurfaceRun* run) {
    run->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
  };
  simulation.time_step = 1.0 / (fps * substeps);
  fem::Simulator sim(rest_mesh, parameters, simulation, fixed_region);
  SurfaceRun run;
  run.grid_nodes = sim.hex_mesh().NumNodes();
  SurfaceTrajectory& frames = run.frames;
  frames.reserve(last_frame + 1);
  frames.push_back(sim.SurfacePositions());
  for (int frame = 1; frame <= last_frame; ++frame) {
    for (int s = 0; s < substeps; ++s) {
      const bool diverged = cancelled() || sim.Step().diverged || !sim.state().u.allFinite();
      if (diverged) {
        frames.clear();
        stop_clock(&run);
        return run;
      }
      ++run.steps;
    }
    frames.push_back(sim.SurfacePositions());
  }
  stop_clock(&run);
  return run;
}

TrajectoryDifference CompareTrajectories(const SurfaceTrajectory& a, const SurfaceTrajectory& b,
                                         int vertices) {
  TrajectoryDifference out;
  const size_t frames = std::min(a.size(), b.size());
  for (size_t frame = 0; frame < frames; ++frame) {
    size_t count = std::min(a[frame].size(), b[frame].size());
    if (vertices >= 0) count = std::min(count, static_cast<size_t>(vertices));
    double sum = 0.0;
    for (size_t i = 0; i < count; ++i) sum += (a[frame][i] - b[frame][i]).squaredNorm();
    const double rms = std::sqrt(sum / static_cast<double>(std::max<size_t>(1, count)));
    out.per_frame_m.push_back(rms);
    if (rms > out.difference_m) {
      out.difference_m = rms;
      out.worst_frame = static_cast<int>(frame);
    }
  }
  return out;
}

}  // namespace softid::inverse
