#include "core/ingest/object_tracking.h"

#include <fmt/format.h>

#include <cmath>

namespace softid::ingest {

Status ObjectTrackingOptions::Validate() const {
  if (!(max_speed_m_per_s > 0.0) || !std::isfinite(max_speed_m_per_s) || !(gate_radii > 0.0) ||
      !std::isfinite(gate_radii)) {
    return Status::InvalidArgument(
        fmt::format("max_speed_m_per_s = {}, gate_radii = {}: must be positive", max_speed_m_per_s,
                    gate_radii));
  }
  return Status::Ok();
}

ObjectTracker::ObjectTracker(double object_radius_m, const ObjectTrackingOptions& options)
    : object_radius_m_(object_radius_m), options_(options) {}

TrackedFrame ObjectTracker::Track(const Foreground& foreground, const Eigen::Isometry3d& X_WC,
                                  double time_s) {
  TrackedFrame out;
  if (foreground.regions.empty()) return out;
  std::vector<const ForegroundRegion*> taken;
  if (!last_centre_W_) {
    taken.push_back(&foreground.regions.front());  // largest first
  } else {
    const double reach = options_.gate_radii * object_radius_m_ +
                         options_.max_speed_m_per_s * std::abs(time_s - last_time_s_);
    for (const ForegroundRegion& region : foreground.regions) {
      if ((X_WC * region.centroid_C - *last_centre_W_).norm() <= reach) taken.push_back(&region);
    }
  }
  out.rejected_regions = static_cast<int>(foreground.regions.size() - taken.size());
  if (taken.empty()) return out;
  double weight = 0.0;
  for (const ForegroundRegion* region : taken) {
    out.pixels.insert(out.pixels.end(), region->pixels.begin(), region->pixels.end());
    out.centre_W += static_cast<double>(region->pixels.size()) * (X_WC * region->centroid_C);
    weight += static_cast<double>(region->pixels.size());
  }
  out.centre_W /= weight;
  out.regions = static_cast<int>(taken.size());
  out.found = true;
  last_centre_W_ = out.centre_W;
  last_time_s_ = time_s;
  return out;
}

}  // namespace softid::ingest
