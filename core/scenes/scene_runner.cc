#include "core/scenes/scene_runner.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>

#include "core/common/json_fields.h"

namespace softid::scenes {

Status RunOptions::Validate() const {
  if (!(fps > 0.0) || !std::isfinite(fps)) return json::Invalid("fps", fps, "must be positive");
  if (substeps_per_frame < 1) {
    return json::Invalid("substeps", substeps_per_frame, "must be at least 1");
  }
  if (duration && (!(*duration > 0.0) || !std::isfinite(*duration))) {
    return json::Invalid("duration", *duration, "must be positive and finite");
  }
  fem::SimulationOptions sim = simulation;
  sim.time_step = 1.0 / (fps * substeps_per_frame);
  return sim.Validate();
}

int RunOptions::NumFrames(const Scene& scene) const {
  return static_cast<int>(std::floor(duration.value_or(scene.duration) * fps + 1e-9)) + 1;
}

Result<RunSummary> RunScene(const Scene& scene, const RunOptions& options,
                            const std::function<void(int, const fem::Simulator&)>& on_frame) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  fem::SimulationOptions sim_options = options.simulation;
  sim_options.time_step = 1.0 / (options.fps * options.substeps_per_frame);
  fem::Simulator sim(scene.mesh, scene.parameters, sim_options, scene.fixed_region);
  RunSummary summary;
  const int num_frames = options.NumFrames(scene);
  const auto start = std::chrono::steady_clock::now();
  on_frame(0, sim);
  summary.num_frames = 1;
  for (int frame = 1; frame < num_frames; ++frame) {
    const RunSummary before = summary;
    const auto frame_start = std::chrono::steady_clock::now();
    for (int s = 0; s < options.substeps_per_frame; ++s) {
      const fem::StepSummary step = sim.Step();
      ++summary.num_steps;
      summary.newton_iterations += step.newton_iterations;
      summary.linear_iterations += step.linear_iterations;
      summary.refactorizations += step.refactorized ? 1 : 0;
      if (step.diverged) {
        summary.diverged = true;
        summary.seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        return summary;
      }
    }
    // Where a run's time goes (impacts cost many times a free-flight frame): -v shows it.
    spdlog::debug(
        "frame {}: {} Newton iterations, {} linear iterations, {} refactorisations, {:.3f} s",
        frame, summary.newton_iterations - before.newton_iterations,
        summary.linear_iterations - before.linear_iterations,
        summary.refactorizations - before.refactorizations,
        std::chrono::duration<double>(std::chrono::steady_clock::now() - frame_start).count());
    on_frame(frame, sim);
    summary.num_frames = frame + 1;
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

Result<RunSummary> RunSceneToEnd(const Scene& scene, const RunOptions& options,
                                 const std::function<void(int, const fem::Simulator&)>& on_frame,
                                 std::string_view frames_noun) {
  Result<RunSummary> run = [&]() -> Result<RunSummary> {
    try {
      return RunScene(scene, options, on_frame);
    } catch (const std::invalid_argument& e) {
      return Status::InvalidArgument(e.what());
    }
  }();
  SOFTID_RETURN_IF_ERROR(run.status());
  if (run->diverged) {
    return Status::FailedPrecondition(
        "the simulation of scene " + scene.name + " diverged after " +
        std::to_string(frames_noun == "steps" ? run->num_steps : run->num_frames) + " " +
        std::string(frames_noun) + "; lower the time step or stiffen the contact");
  }
  return run;
}

}  // namespace softid::scenes
