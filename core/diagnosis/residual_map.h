// Where the fitted simulation and the recording disagree: the residual of every observed depth
// point at the fitted parameters, grouped per frame and per surface patch.
//
// A point's residual is phi, the rest-pose signed distance of the material point the simulated
// motion carries onto it (sparse_surface_cost.h): 0 on the simulated surface, in metres. A frame's
// misfit is the RMS-equivalent sqrt(2 C_k) of its cost C_k (mean Tukey loss; = RMS(phi) for
// residuals well inside the truncation), so a misfit is comparable with a depth noise sigma.
// Patches partition the rest surface: k-means (farthest-point seeded, deterministic) of its
// vertices; a matched point belongs to the patch nearest to its rest position X.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/cost/sparse_surface_cost.h"
#include "core/geometry/triangle_mesh.h"
#include "core/inverse/observed_frames.h"

namespace softid::diagnosis {

// Observed frames with, per frame, the index of the first point of each camera (points of camera
// c are [camera_offsets[k][c], camera_offsets[k][c + 1])).
struct Observations {
  std::vector<inverse::ObservedFrame> frames;
  std::vector<std::vector<int>> camera_offsets;
};
// Loads frames first..last (as inverse::LoadObservedFrames, same points in the same order), marks
// held-out frames with `heldout_every` (as JobConfig::IsHeldOut) and records the camera offsets.
Result<Observations> LoadObservations(const capture::Capture& capture, int first, int last,
                                      int heldout_every);

// Surface patches: centres of a k-means partition of rest-surface points.
struct Patches {
  std::vector<Eigen::Vector3d> centres;  // rest pose, world frame [m]
  std::vector<std::string> labels;       // "bottom", "+x top", ... (side of the body centre)
  // Index of the patch nearest to rest position X.
  int Assign(const Eigen::Vector3d& X) const;
  int size() const { return static_cast<int>(centres.size()); }
};
// @param count patches, >= 1 (fewer when the surface has fewer vertices).
// @param up the world "up" (against gravity) for the labels.
Patches MakePatches(const geometry::TriangleMesh& rest_surface, int count,
                    const Eigen::Vector3d& up);

struct FrameResiduals {
  int frame = 0;
  double time = 0.0;  // [s]
  bool heldout = false;
  double cost = 0.0;          // mean Tukey loss C_k [m^2]
  double misfit = 0.0;        // sqrt(2 C_k) [m]
  std::vector<float> phi;     // per point [m] (0 when unmatched)
  std::vector<int> patch;     // per point, -1 when unmatched
  std::vector<char> matched;  // per point
};

struct ResidualMap {
  std::vector<FrameResiduals> frames;
  Patches patches;
  double truncation = 0.0;  // phi_max [m]
  // RMS-equivalent misfit of patch p over the frames for which `use(k)` holds (k indexes frames),
  // matched points only [m]; 0 without points. Unmatched points cannot be placed on a patch.
  template <typename Use>
  double PatchMisfit(int p, Use use) const;
  // Points of patch p over the selected frames.
  template <typename Use>
  long long PatchPoints(int p, Use use) const;
};

// Builds the map from the per-frame matches of TrajectoryObjective::MatchPoints.
// @pre matches.size() == observations.frames.size(), matches[k].size() == points of frame k.
ResidualMap BuildResidualMap(const Observations& observations,
                             const std::vector<std::vector<cost::PointMatch>>& matches,
                             const Patches& patches, double truncation);

// Signed residuals of the fitted (not held-out) frames, per frame, in acquisition order, matched
// points only: the input of ComputeEffectiveSampleSize.
std::vector<std::vector<double>> FittedResiduals(const ResidualMap& map);

template <typename Use>
double ResidualMap::PatchMisfit(int p, Use use) const {
  double sum = 0.0;
  long long n = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    if (!use(static_cast<int>(k))) continue;
    const FrameResiduals& f = frames[k];
    for (size_t i = 0; i < f.phi.size(); ++i) {
      if (f.patch[i] != p) continue;
      const double phi = std::min<double>(std::abs(f.phi[i]), truncation);
      sum += phi * phi;
      ++n;
    }
  }
  return n > 0 ? std::sqrt(sum / n) : 0.0;
}

template <typename Use>
long long ResidualMap::PatchPoints(int p, Use use) const {
  long long n = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    if (!use(static_cast<int>(k))) continue;
    for (int q : frames[k].patch) n += q == p;
  }
  return n;
}

}  // namespace softid::diagnosis
