#include "core/diagnosis/noise_floor.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/common/json_fields.h"

namespace softid::diagnosis {

Status NoiseFloorOptions::Validate() const {
  if (!(quantile > 0.0 && quantile < 1.0))
    return json::Invalid("noise_floor.quantile", quantile, "must lie in (0, 1)");
  if (!(frame0_excess_factor > 1.0) || !std::isfinite(frame0_excess_factor))
    return json::Invalid("noise_floor.frame0_excess_factor", frame0_excess_factor, "must be > 1");
  return Status::Ok();
}

Result<NoiseFloor> EstimateNoiseFloor(const ResidualMap& map, const NoiseFloorOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  std::vector<double> misfits;
  NoiseFloor out;
  for (const FrameResiduals& f : map.frames) {
    if (f.phi.empty()) continue;
    misfits.push_back(f.misfit);
    if (f.frame == 0) out.frame0_misfit = f.misfit;
  }
  if (misfits.empty()) {
    return Status::FailedPrecondition("no observed frame has depth points: no noise floor");
  }
  std::sort(misfits.begin(), misfits.end());
  // Linear interpolation between order statistics.
  const double position = options.quantile * (misfits.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(position));
  const size_t hi = std::min(lo + 1, misfits.size() - 1);
  out.quantile_misfit = misfits[lo] + (position - lo) * (misfits[hi] - misfits[lo]);
  if (out.frame0_misfit >= 0.0 && out.frame0_misfit <= out.quantile_misfit) {
    out.sigma = out.frame0_misfit;
    out.method = "frame0";
  } else {
    out.sigma = out.quantile_misfit;
    out.method = "quantile";
  }
  out.frame0_excess = out.frame0_misfit > options.frame0_excess_factor * out.quantile_misfit;
  if (!(out.sigma > 0.0)) {
    return Status::FailedPrecondition("the residual floor is 0: noise-free, perfectly fitted data");
  }
  return out;
}

}  // namespace softid::diagnosis
