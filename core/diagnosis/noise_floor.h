// The noise floor of the depth residuals: the misfit a frame shows when the model is right, so
// that residuals can be said to be "at the noise level" or k times above it.
//
// Frame 0 is the one frame with no physics in it: the rest pose at t = 0 is given, so its misfit
// is sensor noise plus the fit grid's interpolation of the rest shape, never a wrong parameter.
// A single frame is a noisy estimate and a mis-posed camera (or a time offset) would inflate it,
// so the floor is
//   sigma = min(misfit of frame 0, q-quantile of the misfits of all frames)
// (a frame 0 worse than a quarter of the moving frames has something other than noise in it). Any
// capture without frame 0 uses the quantile alone. The frame-0 excess is reported, as a hint of a
// calibration nuisance (camera pose, time offset), never as physics.
#pragma once

#include <string>

#include "core/common/status.h"
#include "core/diagnosis/residual_map.h"

namespace softid::diagnosis {

struct NoiseFloorOptions {
  // Quantile of the per-frame misfits taken as the floor when frame 0 is absent or worse [-], in
  // (0, 1). 0.25: the effects of interest (impact, sliding, drag) spoil most frames but rarely the
  // best quarter.
  double quantile = 0.25;
  // Frame 0 counts as "worse than the floor" (calibration hint) above this factor [-], > 1.
  double frame0_excess_factor = 1.5;
  Status Validate() const;
};

struct NoiseFloor {
  double sigma = 0.0;            // the floor [m], > 0 for a usable map
  double frame0_misfit = -1.0;   // [m]; -1 when frame 0 is not observed
  double quantile_misfit = 0.0;  // [m]
  bool frame0_excess = false;    // frame 0 misfit > frame0_excess_factor x quantile_misfit
  std::string method;            // "frame0" or "quantile"
};

// FailedPrecondition when the map has no frame with points.
Result<NoiseFloor> EstimateNoiseFloor(const ResidualMap& map,
                                      const NoiseFloorOptions& options = {});

}  // namespace softid::diagnosis
