// Where and when the fitted model misses the recording: misfits per motion phase and per surface
// patch, normalised by the noise floor, the frame where the misfit begins and the worst frame.
#pragma once

#include <string>
#include <vector>

#include "core/diagnosis/motion_phases.h"
#include "core/diagnosis/residual_map.h"

namespace softid::diagnosis {

struct PhaseMisfit {
  Phase phase = Phase::kFlight;
  int frames = 0;
  int first_frame = -1, last_frame = -1;  // capture frame indices
  double normalised = 0.0;                // RMS over its frames of misfit / sigma [-]
  bool flagged = false;
};

struct PatchMisfit {
  int patch = 0;
  std::string label;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // rest pose [m]
  long long points = 0;
  double normalised = 0.0;  // RMS residual of its points over all frames / sigma [-]
  bool flagged = false;
};

struct Localization {
  double sigma = 0.0;                    // noise floor [m]
  double threshold = 0.0;                // flag above threshold x sigma [-]
  std::vector<double> frame_normalised;  // per observed frame: misfit / sigma [-]
  std::vector<PhaseMisfit> phases;       // phases that occur, in kPhase order
  std::vector<PatchMisfit> patches;
  int onset_frame = -1;  // capture index of the first frame of a run above threshold; -1: none
  int worst_frame = -1;  // capture index of the largest misfit
  bool flagged = false;  // any phase or patch flagged
  std::vector<std::string> FlaggedPhaseNames() const;
  std::vector<std::string> FlaggedPatchLabels() const;  // "patch 3 (+x bottom)"
};

// @param motion per observed frame (aligned with map.frames).
// @param min_phase_frames a phase is flagged only over at least this many frames (one frame is
//   an anecdote: a single impact frame's contact discretisation).
// @param min_patch_points likewise for patches.
Localization Locate(const ResidualMap& map, const std::vector<FrameMotion>& motion, double sigma,
                    double threshold, int min_phase_frames = 2, long long min_patch_points = 50);

}  // namespace softid::diagnosis
