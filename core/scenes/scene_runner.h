// Runs a scene's simulation frame by frame: frame k shows time k / fps, reached after k *
// substeps_per_frame time steps of 1 / (fps * substeps_per_frame). Shared by synth, simulate and
// bench.
#pragma once

#include <functional>
#include <optional>
#include <string_view>

#include "core/common/status.h"
#include "core/fem/simulator.h"
#include "core/scenes/scene.h"

namespace softid::scenes {

struct RunOptions {
  fem::SimulationOptions simulation;  // its time_step is replaced by 1 / (fps * substeps)
  double fps = 60.0;                  // frames per second [1/s], > 0
  int substeps_per_frame = 4;         // [-], >= 1
  std::optional<double> duration;     // [s], > 0; the scene's own when unset
  Status Validate() const;
  int NumFrames(const Scene& scene) const;
};

struct RunSummary {
  int num_frames = 0;  // frames delivered (including frame 0)
  int num_steps = 0;
  int newton_iterations = 0;  // summed
  int linear_iterations = 0;  // summed
  int refactorizations = 0;
  bool diverged = false;  // the run stopped early at a diverged step
  double seconds = 0.0;   // wall time of the stepping [s]
};

// Calls on_frame(frame, simulator) for every frame, starting with frame 0 at rest.
// @throws std::invalid_argument (from the simulator) when the scene's parameters are invalid.
Result<RunSummary> RunScene(const Scene& scene, const RunOptions& options,
                            const std::function<void(int, const fem::Simulator&)>& on_frame);

// RunScene with its failures as statuses, for writers of synthetic data: InvalidArgument for a
// scene the simulator rejects, FailedPrecondition naming the scene and how many `frames_noun`
// ("frames", "steps") ran when the simulation diverges.
Result<RunSummary> RunSceneToEnd(const Scene& scene, const RunOptions& options,
                                 const std::function<void(int, const fem::Simulator&)>& on_frame,
                                 std::string_view frames_noun = "frames");

}  // namespace softid::scenes
