#include "core/diagnosis/localization.h"

#include <cmath>

namespace softid::diagnosis {

std::vector<std::string> Localization::FlaggedPhaseNames() const {
  std::vector<std::string> out;
  for (const PhaseMisfit& p : phases)
    if (p.flagged) out.push_back(ToString(p.phase));
  return out;
}

std::vector<std::string> Localization::FlaggedPatchLabels() const {
  std::vector<std::string> out;
  for (const PatchMisfit& p : patches)
    if (p.flagged) out.push_back("patch " + std::to_string(p.patch) + " (" + p.label + ")");
  return out;
}

Localization Locate(const ResidualMap& map, const std::vector<FrameMotion>& motion, double sigma,
                    double threshold, int min_phase_frames, long long min_patch_points) {
  Localization out;
  out.sigma = sigma;
  out.threshold = threshold;
  const size_t n = map.frames.size();
  double worst = -1.0;
  for (size_t k = 0; k < n; ++k) {
    const double r = map.frames[k].misfit / sigma;
    out.frame_normalised.push_back(r);
    if (r > worst) {
      worst = r;
      out.worst_frame = map.frames[k].frame;
    }
  }
  // Onset: the first frame above threshold that starts a run (at least 2 of it and the next 2).
  for (size_t k = 0; k < n && out.onset_frame < 0; ++k) {
    if (out.frame_normalised[k] <= threshold) continue;
    int above = 0, seen = 0;
    for (size_t j = k; j < std::min(n, k + 3); ++j, ++seen)
      above += out.frame_normalised[j] > threshold;
    if (above >= std::min(2, seen)) out.onset_frame = map.frames[k].frame;
  }
  for (int ph = 0; ph < kNumPhases; ++ph) {
    PhaseMisfit p;
    p.phase = static_cast<Phase>(ph);
    double sum = 0.0;
    for (size_t k = 0; k < n && k < motion.size(); ++k) {
      if (motion[k].phase != p.phase) continue;
      sum += out.frame_normalised[k] * out.frame_normalised[k];
      ++p.frames;
      if (p.first_frame < 0) p.first_frame = map.frames[k].frame;
      p.last_frame = map.frames[k].frame;
    }
    if (p.frames == 0) continue;
    p.normalised = std::sqrt(sum / p.frames);
    p.flagged = p.frames >= min_phase_frames && p.normalised > threshold;
    out.flagged |= p.flagged;
    out.phases.push_back(p);
  }
  auto all = [](int) { return true; };
  for (int q = 0; q < map.patches.size(); ++q) {
    PatchMisfit p;
    p.patch = q;
    p.label = map.patches.labels[q];
    p.centre = map.patches.centres[q];
    p.points = map.PatchPoints(q, all);
    p.normalised = map.PatchMisfit(q, all) / sigma;
    p.flagged = p.points >= min_patch_points && p.normalised > threshold;
    out.flagged |= p.flagged;
    out.patches.push_back(p);
  }
  return out;
}

}  // namespace softid::diagnosis
