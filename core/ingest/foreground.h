// Which pixels of a raw depth frame show the object: those nearer than the static scene by well
// more than its noise, grouped into connected regions so that isolated noise does not count.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/capture/depth_image.h"
#include "core/capture/pixel_rays.h"
#include "core/common/status.h"
#include "core/ingest/static_scene.h"

namespace softid::ingest {

struct ForegroundOptions {
  // A pixel is foreground when it is nearer than the static scene by more than noise_sigmas of
  // that pixel's noise and by more than min_margin_m (sigma from few frames can be tiny).
  double noise_sigmas = 4.0;
  double min_margin_m = 0.004;
  // Hysteresis: a pixel nearer by more than join_noise_sigmas (and the margin scaled alike) joins
  // a region of surely nearer pixels when its depth continues it, but makes none alone. Where the
  // object meets the floor its pixels stand only a little in front of it; a lone noisy floor pixel
  // beside the object is rarely this far out (2.3 % at 2 sigma, and it must touch the object).
  double join_noise_sigmas = 2.0;  // in (0, noise_sigmas]
  // Neighbouring pixels (8-neighbourhood) belong to one region when their depths differ by at most
  // this fraction of the depth: a surface seen at 80 degrees from its normal steps about 2 % per
  // pixel at 140-pixel focal lengths; the gap between an object and the floor behind it is larger.
  double max_depth_step = 0.05;
  // Regions of fewer pixels are noise, not objects.
  int min_region_pixels = 12;
  // A pixel with at least this many of its 8 neighbours in one region, and a depth that continues
  // theirs, joins it whatever its reading (noise took it behind the margin). A pixel beside a
  // straight silhouette has 3 such neighbours, one in a concave corner 5.
  int min_enclosing_neighbours = 6;  // in [1, 8]

  Status Validate() const;
};

// A connected region of foreground pixels.
struct ForegroundRegion {
  std::vector<int> pixels;              // row-major pixel indices
  Eigen::Vector3d centroid_C{0, 0, 0};  // mean of the pixels' points in the camera frame [m]
};

struct Foreground {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> mask;              // 1 = foreground (in a kept region), row-major
  std::vector<ForegroundRegion> regions;  // largest first
};

// The foreground of `frame` against `scene` (same size): pixels with data that are nearer than the
// static scene by the margin above, or that have data where the scene has none; regions with
// fewer than min_region_pixels such pixels are dropped. Pixels the scene marks maybe_object join
// a region when their depths continue it. Points are unprojected along `rays` (the camera's lens).
// InvalidArgument when the sizes differ.
Result<Foreground> SegmentForeground(const capture::DepthImage& frame, const StaticScene& scene,
                                     const capture::PixelRays& rays,
                                     const ForegroundOptions& options = {});

}  // namespace softid::ingest
