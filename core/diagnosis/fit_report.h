// The pictures that come with every fit's result (softid-lab fit, service jobs): how each start's
// cost fell, how far every frame's residual lies above the noise floor, and the observed points
// over the fitted simulation's surface at a few frames. Written as PNGs into one folder; the
// server stores the folder with the job and serves its files (DownloadArtifact).
#pragma once

#include <atomic>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/diagnosis/motion_phases.h"
#include "core/diagnosis/noise_floor.h"
#include "core/inverse/fit.h"
#include "core/inverse/job_config.h"

namespace softid::diagnosis {

struct FitReportOptions {
  // Frames drawn over the simulated surface: the worst-fitting frame and others spread over the
  // motion [-], in [1, 8].
  int snapshots = 3;
  // The dashed line of the per-frame plot, in noise floors [-], > 0 (the diagnosis' threshold).
  double misfit_threshold = 1.5;
  NoiseFloorOptions noise_floor;
  MotionPhaseOptions phases;
  // Checked during the residuals' simulation: set, the report stops with Cancelled. Null: never.
  const std::atomic<bool>* cancel = nullptr;

  Status Validate() const;
};

// The files the report wrote, relative to its folder, in order.
struct FitReport {
  std::vector<std::string> files;
  double noise_floor_m = 0.0;        // the residuals' noise floor (noise_floor.h) [m]
  std::vector<int> snapshot_frames;  // capture frames drawn over the simulated surface
  double seconds = 0.0;
};

// Writes into `dir` (created; files of the same names replaced):
//   cost_per_iteration.png   every start's cost per iteration over every fitted frame
//   residual_per_frame.png   each frame's misfit / noise floor over the motion phases
//   surface_overlay.png      observed points over the simulated surface, front and side
// at the best start's final parameters, on the grid and time step the fit used. Errors as
// Diagnose's for the capture; FailedPrecondition when the fit has no successful start or the
// simulation diverges; IoError when a file cannot be written.
Result<FitReport> WriteFitReport(const capture::Capture& capture, const inverse::JobConfig& config,
                                 const inverse::FitResult& fit, const std::filesystem::path& dir,
                                 const FitReportOptions& options = {});

nlohmann::json ToJson(const FitReport& report);

}  // namespace softid::diagnosis
