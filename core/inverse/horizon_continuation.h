// Continuation over the horizon: which prefixes of the observed frames a start fits, in order,
// before it fits them all.
//
// Over a whole bouncing or vibrating sequence the cost of a wrong stiffness has local minima
// wherever a later rebound comes back in phase with the recording (torus-drop, E only: minima
// at 1.4x, 2.5x and 3.2x of the truth, so 6 of 20 starts spread over [0.1x, 10x] stopped there).
// Over the first frames after the simulation departs from the recording (the first impact) the
// cost is monotone on each side of the truth. So a start fits first up to shortly after the
// departure, then a prefix twice as long, and so on: each stage starts inside the basin of the
// next one.
#pragma once

#include <vector>

#include "core/inverse/observed_frames.h"

namespace softid::inverse {

struct HorizonContinuationOptions {
  // A fitted frame departs when its cost exceeds this many times the smallest fitted frame cost
  // (the floor of a matching frame: noise and discretisation) [-], > 1. At 2 the first impact of
  // a torus started at 1.7x its stiffness departs (3x the floor); at 4 it did not, and the single
  // stage fell into the local minimum of the rebound.
  double departure_factor = 2.0;
  // The first stage fits the departing frame and this many fitted frames after it [-], >= 1: the
  // first impact of a drop at 30-60 fps spans a few frames.
  int frames_after_departure = 2;
  // Each stage fits this many times as many frames after the departure as the previous one [-],
  // > 1.
  double growth = 2.0;
  // A stage that would hold more than this fraction of the fitted frames is replaced by the
  // final one (every frame) [-], in (0, 1].
  double final_fraction = 0.8;
};

// Active-frame counts (prefix lengths of `frames`, see TrajectoryObjective::SetActiveFrames), in
// increasing order; the last is frames.size(). With d fitted frames before the departure and
// w = frames_after_departure, stage j holds d + (w + 1) growth^j fitted frames. Only the last
// stage when no fitted frame departs, or when the first stage would already hold most frames.
// @param frame_costs per frame of `frames`, at the start's values [m^2].
// @param negligible_cost frame costs at or below this never depart [m^2], >= 0 (a noise-free
//        capture's matching frames cost ~0).
// @pre frame_costs.size() == frames.size(); at least one frame is fitted.
std::vector<int> HorizonStages(const std::vector<ObservedFrame>& frames,
                               const std::vector<double>& frame_costs, double negligible_cost,
                               const HorizonContinuationOptions& options = {});

}  // namespace softid::inverse
