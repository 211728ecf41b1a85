// What a camera sees when the object is not there: per pixel, the depth of the static scene
// (floor, walls, clutter) and how much that depth scatters from frame to frame (sensor noise).
// Pixels that are closer than the static scene by well more than the noise show something that
// moves: the object.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/capture/depth_image.h"
#include "core/capture/pixel_rays.h"
#include "core/common/status.h"

namespace softid::ingest {

struct StaticScene {
  int width = 0;
  int height = 0;
  // Per pixel (row-major): depth of the static scene along the camera z axis [m]; 0 where the
  // camera never saw anything behind the object (or saw nothing at all).
  std::vector<float> depth_m;
  // Per pixel: robust standard deviation of that depth over the frames that show it [m].
  std::vector<float> sigma_m;
  // Per pixel, or empty: 1 where the depth may be the object itself at rest, never seen behind
  // (MarkHiddenByTheObject). Such pixels join an object region their depths continue, but never
  // make one by themselves.
  std::vector<uint8_t> maybe_object;

  float depth(int col, int row) const { return depth_m[static_cast<size_t>(row) * width + col]; }
  float sigma(int col, int row) const { return sigma_m[static_cast<size_t>(row) * width + col]; }
};

// The median of the scene's nonzero sigmas [m], at least 0.1 mm: the depth noise of a typical
// pixel (0.1 mm when no pixel has a sigma).
double MedianSigma(const StaticScene& scene);

struct StaticSceneOptions {
  // Samples within this distance of a pixel's farthest reading belong to the static scene [m]:
  // larger than the depth noise, smaller than the object's height above what is behind it.
  // The object passes in front of a pixel for some frames; the scene behind it is the farthest
  // consistent reading, so a moving object never becomes background even if it covers a pixel in
  // most frames.
  double cluster_width_m = 0.02;
  // Readings the farthest window needs to count as the scene. One: a pixel where the object
  // rests for most of the recording shows what is behind it only in the frames before it came to
  // rest, sometimes just once (a rarer reading farther away than the scene does not occur: a
  // sensor's flying pixels lie between an object and what is behind it).
  int min_readings = 1;
  // MarkHiddenByTheObject: scene points at most this high above the floor are floor [m].
  double min_height_above_floor_m = 0.01;
  // Threads for the per-pixel work; 0: one per core. Pixels are independent, so the scene does
  // not depend on the count.
  int threads = 0;  // >= 0

  Status Validate() const;
};

// The static scene from `images` of one camera (background frames of the empty scene, or the
// recording's own frames: the object moves, so every pixel shows the scene behind it in some
// frames). Per pixel: the farthest cluster of readings (within cluster_width_m of the farthest
// one), its median as the depth and 1.4826 times its median absolute deviation as sigma, raised to
// the median sigma of the pixels at the same depth (few readings understate the noise).
// InvalidArgument when images is empty or sizes differ, naming the image.
Result<StaticScene> EstimateStaticScene(const std::vector<capture::DepthImage>& images,
                                        const StaticSceneOptions& options = {});

// Without views of the empty scene, pixels the object covers in every frame (it falls onto where
// it was) show only the object: their "static" depth is the object at rest, and the object would
// lose them once it lies still. Marks as maybe_object the pixels of `first_object_pixels` (the
// object in the first frame) whose static point stands higher than min_height_above_floor_m above
// the floor n_C . p = offset_m: resting object, or clutter behind the released object, which the
// foreground tells apart by whether the object's region continues into them.
void MarkHiddenByTheObject(const std::vector<int>& first_object_pixels,
                           const Eigen::Vector3d& floor_normal_C, double floor_offset_m,
                           const capture::PixelRays& rays, const StaticSceneOptions& options,
                           StaticScene* scene);

// The static scene from views of the empty scene (background frames): every reading shows the
// scene, so the sensor's noise at each depth comes from all of them (per 3 % depth bin, the median
// over its pixels of their sample variance, corrected for their reading count), where a few
// readings' own spread says little (three frames read it at half its size). Where four times that
// noise is wider than cluster_width_m (far from the camera), the scene is taken again with that
// window, centred on its median; every pixel's sigma is at least the noise at its depth.
Result<StaticScene> EstimateEmptyScene(const std::vector<capture::DepthImage>& images,
                                       const StaticSceneOptions& options = {});

// The static scene's points in the camera frame [m], unprojected along the lens's rays (same
// size as the scene), with each point's sigma; pixels of unknown depth are left out.
void StaticScenePoints(const StaticScene& scene, const capture::PixelRays& rays,
                       std::vector<Eigen::Vector3d>* points_C, std::vector<float>* sigmas_m);

}  // namespace softid::ingest
