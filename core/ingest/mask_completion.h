// The object's pixels completed by its scanned shape. Where a body meets the floor its lowest
// pixels read within the noise of the floor behind them, and no depth threshold tells them from it
// (a pillow on a ramp 2 m from the cameras: 11 mm of noise, worst mask IoU 0.906 from the depths
// alone). The mesh, posed on the frame's surely-object pixels, shows where the silhouette runs: a
// pixel inside it whose reading agrees with the posed surface within the noise is the object's.
// The mesh keeps its rest shape, so the completion is only as good as the body is rigid between a
// frame's pose and its silhouette; a pixel it adds must still read on the posed surface.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <vector>

#include "core/capture/camera.h"
#include "core/capture/depth_image.h"
#include "core/capture/depth_renderer.h"
#include "core/capture/pixel_rays.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"
#include "core/ingest/camera_view.h"
#include "core/ingest/mesh_registration.h"

namespace softid::ingest {

struct MaskCompletionOptions {
  bool enabled = true;
  // A pixel inside the posed silhouette joins the object when its reading lies within this many
  // noise sigmas of the posed surface [-], > 0. Its own noise is all that separates them, so the
  // window is that of any reading of the surface (3 sigma: 99.7 %).
  double agreement_sigmas = 3.0;
  // A frame's pose is trusted when at least this share of its object points lies within 3 noise
  // sigmas of the posed mesh [-], in (0, 1]; otherwise its mask stays as segmented.
  double min_overlap = 0.8;
  // Samples of the mesh's surface the pose is fitted to [-], >= 100.
  int surface_points = 10000;
  // The first pairing distance of the pose's ICP, as a fraction of the mesh's bounding-box
  // diagonal [-], > 0: the prediction's error (the motion's change from one frame to the next).
  double capture_fraction = 0.07;

  Status Validate() const;
};

// A rectangle of pixels, bounds included (may reach past the image).
struct ImageWindow {
  int col_lo = 0, row_lo = 0, col_hi = -1, row_hi = -1;
};

// What the completion did to one frame.
struct FrameCompletion {
  bool posed = false;    // the mesh's pose was found (else the mask is as segmented)
  int pixels_added = 0;  // pixels the posed mesh added to the mask
  double overlap = 0.0;  // the pose's ICP overlap
};

// Follows the mesh through one camera's frames, in their order, from its pose at the release.
class MaskCompleter {
 public:
  // mesh_S in its own frame (metres), X_WS its pose at the release; the camera's view (lens rays,
  // static scene, pose X_WC), intrinsics and distortion; noise_sigma_m the typical depth noise,
  // for pixels whose static scene has no sigma.
  MaskCompleter(const geometry::TriangleMesh& mesh_S, const Eigen::Isometry3d& X_WS,
                const CameraView& view, const capture::PinholeCamera& camera,
                const capture::DistortionCoefficients& distortion, double noise_sigma_m,
                const MaskCompletionOptions& options);

  // The next frame: `pixels` are its object's pixels as segmented (row-major indices into
  // `image`). Poses the mesh on their points, from the pose the last two frames' motion predicts,
  // and adds the pixels inside its silhouette that read on its surface; `pixels` stay sorted.
  FrameCompletion Complete(const capture::DepthImage& image, std::vector<int>* pixels);

 private:
  Eigen::Isometry3d PredictedPose_CS() const;
  // Poses the mesh on the mask's points; sets out->posed and moves the pose on when it holds.
  void Pose(const capture::DepthImage& image, const std::vector<int>& mask, FrameCompletion* out);
  // Pixels near the mask inside the posed silhouette whose readings lie on the posed surface.
  std::vector<int> AgreeingPixels(const capture::DepthImage& image,
                                  const std::vector<int>& mask) const;
  ImageWindow SilhouetteWindow(const std::vector<Eigen::Vector3d>& vertices_C) const;
  std::vector<int> Candidates(const capture::DepthImage& image, const std::vector<int>& mask,
                              const ImageWindow& window) const;

  geometry::TriangleMesh mesh_S_;
  MeshSurface surface_;
  const CameraView& view_;
  capture::PinholeCamera camera_;
  capture::DistortionCoefficients distortion_;
  double noise_sigma_m_;
  double capture_m_;
  MaskCompletionOptions options_;
  capture::RigidMeshRenderer renderer_;
  Eigen::Isometry3d last_CS_;
  std::optional<Eigen::Isometry3d> before_last_CS_;
};

}  // namespace softid::ingest
