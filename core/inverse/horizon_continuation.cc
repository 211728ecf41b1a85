#include "core/inverse/horizon_continuation.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/common/check.h"

namespace softid::inverse {

std::vector<int> HorizonStages(const std::vector<ObservedFrame>& frames,
                               const std::vector<double>& frame_costs, double negligible_cost,
                               const HorizonContinuationOptions& options) {
  SOFTID_THROW_UNLESS(frame_costs.size() == frames.size(), "one cost per observed frame");
  SOFTID_THROW_UNLESS(options.departure_factor > 1.0 && options.frames_after_departure >= 1 &&
                          options.growth > 1.0 && options.final_fraction > 0.0 &&
                          options.final_fraction <= 1.0,
                      "HorizonContinuationOptions out of range");
  const int all = static_cast<int>(frames.size());
  // Positions (in `frames`) of the fitted frames.
  std::vector<int> fitted;
  for (int k = 0; k < all; ++k)
    if (!frames[k].heldout) fitted.push_back(k);
  SOFTID_THROW_UNLESS(!fitted.empty(), "every observed frame is held out");
  const int m = static_cast<int>(fitted.size());

  double floor = std::numeric_limits<double>::infinity();
  for (int k : fitted) floor = std::min(floor, frame_costs[k]);
  const double threshold = std::max(options.departure_factor * floor, negligible_cost);
  int departure = -1;  // index into `fitted`
  for (int i = 0; i < m && departure < 0; ++i)
    if (frame_costs[fitted[i]] > threshold) departure = i;
  if (departure < 0) return {all};

  std::vector<int> stages;
  double after = 1 + options.frames_after_departure;  // fitted frames from the departure on
  while (departure + after <= options.final_fraction * m) {
    const int c = departure + static_cast<int>(std::lround(after));
    if (stages.empty() || fitted[c - 1] + 1 > stages.back())
      stages.push_back(fitted[c - 1] + 1);  // the prefix up to the c-th fitted frame
    after *= options.growth;
  }
  stages.push_back(all);
  return stages;
}

}  // namespace softid::inverse
